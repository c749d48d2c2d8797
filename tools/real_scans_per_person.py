#!/usr/bin/env python3
"""Each real-scan pedestrian's best score under several detect outputs, side by side.

For every pedestrian of real-scans/gt within 25 m holding at least 5 points: the highest score of
a detection whose bird's-eye centre lies within 0.5 m (not eval's greedy one-to-one matching, so a
count here can differ from eval's by a person where two people stand close). A diagnosis of which
people flip between outputs (weights, or turns of the input: docs/results/real_scans_turns/),
never a figure to decide on.

    python3 tools/real_scans_per_person.py LABEL=OUT ...   # OUT as tools/score_real_scans.sh wrote it

A star marks a score at or above AT_SCORE (the environment's, default 0.5).
"""
import glob, math, os, sys

gt_root = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'real-scans', 'gt')
cols=[a.split('=',1) for a in sys.argv[1:]]
at=float(os.environ.get('AT_SCORE','0.5'))
def read(f):
    out=[]
    for l in open(f):
        t=l.split()
        if not t or t[0].lower()!='pedestrian': continue
        out.append(dict(n=int(t[3]),x=float(t[12]),z=float(t[14]),s=float(t[16])))
    return out
rows=[]
for src in sorted(os.listdir(gt_root)):
    for f in sorted(glob.glob(f'{gt_root}/{src}/*.txt')):
        fr=os.path.basename(f)
        for g in read(f):
            r=math.hypot(g['x'],g['z'])
            if g['n']<5 or r>25: continue
            best=[]
            for lab,root in cols:
                d=read(f'{root}/det/{src}/{fr}')
                sc=[x['s'] for x in d if math.hypot(x['x']-g['x'],x['z']-g['z'])<=0.5]
                best.append(max(sc) if sc else 0.0)
            rows.append((src,fr[:10],r,g['n'],best))
print('source       frame       range points  '+'  '.join(f'{l:>7}' for l,_ in cols))
for src,fr,r,n,b in rows:
    print(f'{src:12} {fr:10} {r:5.1f} {n:6d}  '+'  '.join(('*' if s>=at else ' ')+f'{s:6.2f}' for s in b))
print(f'found at {at}:', [sum(1 for row in rows if row[4][i]>=at) for i in range(len(cols))])
