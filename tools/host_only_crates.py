#!/usr/bin/env python3
"""Which dependencies run only at compile time, and at what opt-level they are built.

The workspace's `[profile.dev.package."*"]` outranks `build-override`, so proc macros and the
crates only they and build scripts use are optimised like the runtime's crates unless
Cargo.toml names them (its `[profile.dev.package]` list). A unit is compile-time only when no
path from the build's roots reaches it without passing through a proc macro or a build script.
Lists every such package with the opt-levels its units get; with a cargo timings page
(`--timings`), also the seconds each took, largest first.

    cargo +nightly build -p train --bins --unit-graph -Z unstable-options > main.json
    python3 tools/host_only_crates.py main.json [target/cargo-timings/cargo-timing.html]
"""
import json, re, sys
from collections import defaultdict

graph = json.load(open(sys.argv[1]))
units = graph['units']

def package(u):
    # `…#name@version` for registry and git packages, `path+file:///…/name#version` for the workspace's
    m = re.search(r'#([\w-]+)@', u['pkg_id'])
    return m.group(1) if m else u['pkg_id'].split('#')[0].rstrip('/').rsplit('/', 1)[-1]

def compile_time(u):
    kinds = u['target']['kind']
    return 'proc-macro' in kinds or 'custom-build' in kinds

runtime, stack = set(), list(graph['roots'])
while stack:
    i = stack.pop()
    if i in runtime or compile_time(units[i]):
        continue
    runtime.add(i)
    stack += [d['index'] for d in units[i]['dependencies']]
runtime_packages = {package(units[i]) for i in runtime}

levels = defaultdict(set)
for u in units:
    if u['mode'] == 'build' and package(u) not in runtime_packages:
        levels[package(u)].add(str(u['profile']['opt_level']))

seconds = defaultdict(float)
if len(sys.argv) > 2:
    page = open(sys.argv[2]).read()
    for unit in json.loads(re.search(r'const UNIT_DATA = (\[.*?\]);\n', page, re.S).group(1)):
        if unit['name'] in levels and 'build script' not in unit['target']:
            seconds[unit['name']] += unit['duration']

print(f'{len(levels)} packages run only at compile time')
for name in sorted(levels, key=lambda n: (-seconds[n], n)):
    flag = '' if levels[name] == {'0'} else '   <- optimised'
    time = f'{seconds[name]:7.1f} s  ' if seconds else ''
    print(f'{time}{name}  opt-level {",".join(sorted(levels[name]))}{flag}')
