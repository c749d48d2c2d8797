#!/usr/bin/env python3
"""Which dependencies run only at compile time (or only through given packages), and at what
opt-level they are built.

The workspace's `[profile.dev.package."*"]` outranks `build-override`, so proc macros and the
crates only they and build scripts use are optimised like the runtime's crates unless
Cargo.toml names them (its `[profile.dev.package]` list). A unit is compile-time only when no
path from the build's roots reaches it without passing through a proc macro or a build script.
Lists every such package with the opt-levels its units get; with a cargo timings page
(`--timings`), also the seconds each took, largest first.

With `--through P,Q,…` it lists instead the runtime packages that every path from the roots
reaches through P or Q: code that runs only when they do, such as turso's dependencies (the
autotune cache's database), which `Cargo.toml` builds at opt-level 0 for that reason.

    cargo +nightly build -p train --bins --unit-graph -Z unstable-options > main.json
    python3 tools/host_only_crates.py main.json [target/cargo-timings/cargo-timing.html]
    python3 tools/host_only_crates.py main.json [timings.html] --through turso,turso_core,turso_sdk_kit,turso_sync_engine,turso_sync_sdk_kit,turso_parser
"""
import argparse, json, re
from collections import defaultdict

cli = argparse.ArgumentParser()
cli.add_argument('graph')
cli.add_argument('timings', nargs='?')
cli.add_argument('--through', default='', help='comma-separated package names')
args = cli.parse_args()
graph = json.load(open(args.graph))
units = graph['units']

def package(u):
    # `…#name@version` for registry and git packages, `path+file:///…/name#version` for the workspace's
    m = re.search(r'#([\w-]+)@', u['pkg_id'])
    return m.group(1) if m else u['pkg_id'].split('#')[0].rstrip('/').rsplit('/', 1)[-1]

def compile_time(u):
    kinds = u['target']['kind']
    return 'proc-macro' in kinds or 'custom-build' in kinds

def runtime_packages(cut=frozenset()):
    """The packages the roots reach without passing a compile-time unit or a package in `cut`."""
    seen, stack = set(), list(graph['roots'])
    while stack:
        i = stack.pop()
        if i in seen or compile_time(units[i]) or package(units[i]) in cut:
            continue
        seen.add(i)
        stack += [d['index'] for d in units[i]['dependencies']]
    return {package(units[i]) for i in seen}

runtime = runtime_packages()
through = frozenset(filter(None, args.through.split(',')))
if through:
    selected = runtime - runtime_packages(through) - through
    title = f'runtime packages reached only through {", ".join(sorted(through))}'
else:
    selected = {package(u) for u in units} - runtime
    title = 'packages run only at compile time'

levels = defaultdict(set)
for u in units:
    if u['mode'] == 'build' and package(u) in selected:
        levels[package(u)].add(str(u['profile']['opt_level']))

seconds = defaultdict(float)
if args.timings:
    page = open(args.timings).read()
    for unit in json.loads(re.search(r'const UNIT_DATA = (\[.*?\]);\n', page, re.S).group(1)):
        if unit['name'] in levels and 'build script' not in unit['target']:
            seconds[unit['name']] += unit['duration']

print(f'{len(levels)} {title}')
for name in sorted(levels, key=lambda n: (-seconds[n], n)):
    flag = '' if levels[name] == {'0'} else '   <- optimised'
    time = f'{seconds[name]:7.1f} s  ' if seconds else ''
    print(f'{time}{name}  opt-level {",".join(sorted(levels[name]))}{flag}')
