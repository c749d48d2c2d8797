#!/usr/bin/env python3
"""Which dependency builds a cargo invocation needs beyond a reference one (crates/workspace-hack).

Cargo unifies dependency features per invocation, so `cargo run -p eval` after
`cargo run -p train` may build serde, syn or Burn again with other features. Each invocation's
unit graph (nightly cargo prints it without building anything) names every compiled unit with its
features, profile and dependencies; a unit of the second graph that the reference graph lacks is
a rebuild. Listed are the first such units (all of whose own dependencies the reference has),
with how they differ.

    ug() { cargo +nightly "$@" --unit-graph -Z unstable-options; }
    ug build -p train --bins > main.json; ug build -p eval > eval.json; ug test --workspace --no-run > test.json
    python3 tools/unit_graph_diff.py main.json eval.json test.json
"""
import json,hashlib,sys
def load(p):
    g=json.load(open(p))['units']
    keys={}; desc={}
    def key(i):
        if i in keys: return keys[i]
        u=g[i]
        deps=sorted(key(d['index']) for d in u['dependencies'])
        prof={k:v for k,v in u['profile'].items() if k!='name'}
        base=(u['pkg_id'], u['target']['name'], tuple(u['target']['kind']), u['mode'], tuple(sorted(u['features'])), json.dumps(prof,sort_keys=True), u.get('platform'))
        h=hashlib.sha1((repr(base)+repr(deps)).encode()).hexdigest()
        keys[i]=h; desc[h]=(base,deps); return h
    for i in range(len(g)): key(i)
    return desc
ws=load(sys.argv[1])
def name(d,h): b=d[h][0]; return f"{b[0]}:{b[1]}:{b[3]}:{','.join(b[4])}"
for p in sys.argv[2:]:
    ev=load(p)
    # only dependency units matter: the workspace's own crates (path+file ids) always rebuild
    miss=[k for k,(b,d) in ev.items() if k not in ws and 'path+file' not in b[0]]
    print(p, len(ev), 'units;', len(miss), 'dependency units not in the reference build')
    for k in miss:
        base,deps=ev[k]
        if all(d in ws for d in deps):
            e=set(name(ev,d) for d in deps)
            print('   ', base[0], base[1], base[3], list(base[4]))
            for kk,(b2,d2) in ws.items():
                if b2[:4]==base[:4]:
                    w=set(name(ws,d) for d in d2)
                    print('      ref features', list(b2[4]), 'deps only here:', e-w, 'only there:', w-e)
