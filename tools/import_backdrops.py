#!/usr/bin/env python3
"""Real backdrops for training: real scans, their people taken out, each in its sensor's frame.

Writes OUT/<name>.npy (N x 3 float32) and OUT/backdrops.csv (file, sensor, source) for
`[data.simulate] backdrops = "OUT"` / `data-jrdb synth --backdrops OUT`, from checkouts of:

  --aimotive DIR   aimotive/aimotive-dataset-loader (its 50-keyframe sample: a motorway at night
                   seen by a Hesai Pandar64; every road user labelled, none a person). LAZ body-
                   frame points are moved into the LiDAR's frame with calibration.json's
                   M_LIDAR_M `RT_sensor_from_body`. Needs `pip install 'laspy[lazrs]'`.
  --kitti DIR      a KITTI object folder with training/{velodyne,label_2,calib} (e.g.
                   kuixu/kitti_object_vis's data/object: three frames, HDL-64E). Points within
                   0.3 m of a Pedestrian, Person_sitting or Cyclist box are removed; KITTI labels
                   only the front camera's view, so a person elsewhere would stay (none seen).

  --labelled DIR   a folder of fetched repositories (`fetch`'s /work/.mirror, bare git dirs named
                   owner+name) holding per-point labelled scans (LABELLED below: SemanticKITTI
                   sample frames, HDL-64E; RELLIS-3D frames, a first-generation Ouster OS1-64 at
                   2048 columns on an off-road robot). Every point of a person class (SemanticKITTI
                   30-32 and their moving 253-255; RELLIS 17), any point within 0.3 m of one, and
                   no-return (0, 0, 0) points are removed; RELLIS's robot's own returns (within
                   2.5 m) too. Needs scipy.
  --pjlab MIRROR   a fetched PJLab-ADG/SensorsCalibration (Apache-2.0): nine roof-LiDAR scans
                   of Shanghai streets and car parks from its calibration data (PJLAB below; a
                   Hesai Pandar64, -25 to +15 degrees). Not labelled: people are taken out by the
                   shipped detector (`target/debug/train detect`, the frame found from the
                   ground), every box scoring >= 0.2 grown by 0.3 m, its points removed; people it
                   misses stay in, and what is removed depends on the weights shipped when it
                   runs (data/backdrops-v3 of 2026-12-07: the soup of git 4be6007). Needs
                   python-lzf (the scans are LZF-compressed PCDs; this reader of x, y, z is the
                   tool's own, the project's PCD reader being Rust's `data_jrdb::cloud`).
  --balance        list each place's scans so every place gets an equal share of the sequences
                   (the simulator takes backdrops.csv's rows in turn): without it the 50 motorway
                   frames would be most of them.

Never use the scans `real-scans/` scores on: they are the yardstick.
    python3 tools/import_backdrops.py OUT --aimotive A --kitti K [--labelled /work/.mirror --pjlab /work/.mirror --balance]
"""
import argparse
import glob
import json
import os
import subprocess

import numpy as np


def commit(d):
    try:
        return subprocess.run(["git", "-C", d, "rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    except Exception:
        p = os.path.join(d, "COMMIT")
        return open(p).read().strip() if os.path.exists(p) else "unknown"


def aimotive(root, out, rows):
    import laspy

    seqs = sorted(glob.glob(os.path.join(root, "data", "*", "*", "*")))
    for seq in seqs:
        calib = json.load(open(os.path.join(seq, "sensor", "calibration", "calibration.json")))
        t = np.array(calib["M_LIDAR_M"]["RT_sensor_from_body"])
        for f in sorted(glob.glob(os.path.join(seq, "dynamic", "raw-revolutions", "*.laz"))):
            las = laspy.read(f)
            body = np.stack([las.x, las.y, las.z], 1)
            pts = body @ t[:3, :3].T + t[:3, 3]
            for g in glob.glob(os.path.join(seq, "dynamic", "box", "3d_body", os.path.basename(f)[:-4] + ".json")):
                kinds = {o["ObjectType"] for o in json.load(open(g))["CapturedObjects"]}
                if kinds & {"PEDESTRIAN", "PERSON", "BICYCLE", "MOTORCYCLE", "CYCLIST"}:
                    raise SystemExit(f"{g}: has people ({kinds}); this importer does not remove them")
            name = "aimotive-" + os.path.basename(f)[:-4]
            np.save(os.path.join(out, name + ".npy"), pts.astype(np.float32))
            rows.append((name + ".npy", "pandar64", f"aimotive-dataset-loader@{commit(root)[:12]}:{os.path.relpath(f, root)}"))


def kitti_calib(path):
    c = {}
    for line in open(path):
        if ":" in line:
            k, v = line.split(":", 1)
            c[k] = np.array([float(x) for x in v.split()])
    r0 = c["R0_rect"].reshape(3, 3)
    tr = c["Tr_velo_to_cam"].reshape(3, 4)
    return r0, tr


def kitti(root, out, rows, margin=0.3):
    base = os.path.join(root, "training")
    for f in sorted(glob.glob(os.path.join(base, "velodyne", "*.bin"))):
        stem = os.path.basename(f)[:-4]
        pts = np.fromfile(f, dtype=np.float32).reshape(-1, 4)[:, :3]
        r0, tr = kitti_calib(os.path.join(base, "calib", stem + ".txt"))
        rect = (pts @ tr[:, :3].T + tr[:, 3]) @ r0.T
        keep = np.ones(len(pts), bool)
        removed = 0
        for line in open(os.path.join(base, "label_2", stem + ".txt")):
            v = line.split()
            if v[0] not in ("Pedestrian", "Person_sitting", "Cyclist"):
                continue
            h, w, l, x, y, z, ry = map(float, v[8:15])
            d = rect - np.array([x, y - h / 2, z])
            c, s = np.cos(ry), np.sin(ry)
            lx, lz = c * d[:, 0] - s * d[:, 2], s * d[:, 0] + c * d[:, 2]
            inside = (abs(lx) < l / 2 + margin) & (abs(d[:, 1]) < h / 2 + margin) & (abs(lz) < w / 2 + margin)
            removed += int((inside & keep).sum())
            keep &= ~inside
        name = "kitti-" + stem
        np.save(os.path.join(out, name + ".npy"), pts[keep].astype(np.float32))
        rows.append((name + ".npy", "hdl64e", f"kitti_object_vis@{commit(root)[:12]}:{os.path.relpath(f, root)} ({removed} people's points removed)"))


# (repository, commit, [(scan, labels)], scheme, sensor, place). Licences: KITTI CC BY-NC-SA 3.0,
# SemanticKITTI labels CC BY-NC-SA 4.0, RELLIS-3D CC BY-NC-SA 3.0 (non-commercial).
LABELLED = [
    ("makeOneBugEveryday+SemanticKITTI-visualizer", "13fe63a8697827943d336659081f3a6df62df61b",
     [(f"src/example/pcd/00000{i}.bin", f"src/example/label/00000{i}.label") for i in range(3)], "semantickitti", "hdl64e", "semantickitti-00"),
    ("mit-han-lab+spvnas", "5c53224ca685844eb27caedf22817a89233ac0ce", [("assets/000000.bin", "assets/000000.label")], "semantickitti", "hdl64e", "semantickitti-spvnas"),
    ("keonhee-han+semantickitti_KI_DT", "869fc6d1fa0ce3c61f6c26ba26d5f4aa06b42c12", [("baselines/test/000964.bin", "baselines/test/000964.label")], "semantickitti", "hdl64e", "semantickitti-07"),
    ("unmannedlab+RELLIS-3D", "c17a118fcaed1559f03cc32cc3a91dedc557f8b8", [("utils/example/000104.bin", "utils/example/000104.label")], "rellis", "os1-64-gen1", "rellis-00000"),
    ("rsasaki0109+CloudAnalyzer", "da3399446a262d50f139e488a8e4981da22c7d48",
     [("demo_assets/public/rellis3d-frame-000001/os1_cloud_node_kitti_bin/000001.bin", "demo_assets/public/rellis3d-frame-000001/os1_cloud_node_semantickitti_label_id/000001.label")],
     "rellis", "os1-64-gen1", "rellis-00000"),
]
PERSON = {"semantickitti": {30, 31, 32, 253, 254, 255}, "rellis": {17}}
SELF_RANGE = {"semantickitti": 0.0, "rellis": 2.5}


def git_show(mirror, commit_, path):
    git_dir = mirror if os.path.isdir(os.path.join(mirror, "objects")) else os.path.join(mirror, "repo")
    return subprocess.run(["git", "--git-dir", git_dir, "show", f"{commit_}:{path}"], capture_output=True, check=True).stdout


def labelled(mirrors, out, rows, margin=0.3):
    from scipy.spatial import cKDTree

    for repo, commit_, files, scheme, sensor, place in LABELLED:
        mirror = os.path.join(mirrors, repo)
        if not os.path.exists(mirror):
            raise SystemExit(f"{mirror}: missing (fetch github:{repo.replace('+', '/')} first)")
        for scan, label in files:
            p = np.frombuffer(git_show(mirror, commit_, scan), np.float32).reshape(-1, 4)[:, :3]
            sem = np.frombuffer(git_show(mirror, commit_, label), np.uint32) & 0xFFFF
            if len(p) != len(sem):
                raise SystemExit(f"{repo}:{scan}: {len(p)} points but {len(sem)} labels")
            person = np.isin(sem, list(PERSON[scheme]))
            keep = (np.abs(p).sum(1) > 0) & (np.linalg.norm(p, axis=1) >= SELF_RANGE[scheme]) & ~person
            if person.any():
                d, _ = cKDTree(p[person]).query(p[keep], distance_upper_bound=margin)
                keep[np.nonzero(keep)[0][np.isfinite(d)]] = False
            name = f"{place}-{os.path.basename(scan)[:-4]}"
            np.save(os.path.join(out, name + ".npy"), p[keep].astype(np.float32))
            rows.append((name + ".npy", sensor, f"{repo.replace('+', '/')}@{commit_[:12]}:{scan} ({int(person.sum())} person-class points removed)"))


# (repository, commit, scans). Each scan shows another street, crossing or car park.
PJLAB = ("PJLab-ADG+SensorsCalibration", "7fe8d46caac040cbcd89cc65e79e5519df01bcd4", [
    "lidar2lidar/auto_calib/data/0001/top.pcd",
    "lidar2lidar/auto_calib/data/0002/top-2022-02-15-17-36-04-449.pcd",
    "lidar2lidar/auto_calib/data/0003/top-2022-02-15-17-45-07-750.pcd",
    "lidar2lidar/manual_calib/data/p64.pcd",
    "lidar2camera/auto_calib_v2.0/data/ours/1/calib.pcd",
    "lidar2camera/auto_calib_v2.0/data/ours/2/calib.pcd",
    "lidar2camera/auto_calib_v2.0/data/ours/3/calib.pcd",
    "lidar2camera/manual_calib/data/0.pcd",
    "radar2lidar/manual_calib/data/lidar.pcd",
])


def read_pcd(blob, what):
    """x, y, z of a PCD's points (ascii, binary or binary_compressed; fields of COUNT 1 or more)."""
    end = blob.index(b"DATA")
    body = blob.index(b"\n", end) + 1
    head = {l.split()[0]: l.split()[1:] for l in blob[:body].decode("ascii", "replace").splitlines() if l.strip() and not l.startswith("#")}
    n, fields = int(head["POINTS"][0]), head["FIELDS"]
    sizes, types = [int(v) for v in head["SIZE"]], head["TYPE"]
    counts = [int(v) for v in head.get("COUNT", ["1"] * len(fields))]
    kind = head["DATA"][0]
    if not all(k in fields for k in "xyz"):
        raise SystemExit(f"{what}: no x, y, z fields ({fields})")
    dtype = [np.dtype({"F": "f", "U": "u", "I": "i"}[t] + str(s)) for s, t in zip(sizes, types)]
    if kind == "ascii":
        rows = np.array([l.split() for l in blob[body:].decode().splitlines() if l.strip()], dtype=np.float64)
        first = np.cumsum([0] + counts)
        return np.stack([rows[:, first[fields.index(k)]] for k in "xyz"], 1).astype(np.float32)
    if kind == "binary":
        rec = np.dtype([(f"f{i}", d, (c,)) for i, (d, c) in enumerate(zip(dtype, counts)) if c > 0])
        a = np.frombuffer(blob[body:body + n * rec.itemsize], rec)
        return np.stack([a[f"f{fields.index(k)}"][:, 0] for k in "xyz"], 1).astype(np.float32)
    if kind == "binary_compressed":
        import lzf
        import struct

        packed, unpacked = struct.unpack("<II", blob[body:body + 8])
        raw = lzf.decompress(blob[body + 8:body + 8 + packed], unpacked)
        cols, off = {}, 0
        for name, d, c in zip(fields, dtype, counts):
            cols[name] = np.frombuffer(raw[off:off + n * d.itemsize * c], d).reshape(n, c)
            off += n * d.itemsize * c
        return np.stack([cols[k][:, 0] for k in "xyz"], 1).astype(np.float32)
    raise SystemExit(f"{what}: DATA {kind} not read")


def pjlab(mirrors, out, rows, threshold=0.2, margin=0.3, train="target/debug/train"):
    import json
    import tempfile

    repo, commit_, scans = PJLAB
    mirror = os.path.join(mirrors, repo)
    if not os.path.exists(mirror):
        raise SystemExit(f"{mirror}: missing (fetch github:{repo.replace('+', '/')} first)")
    with tempfile.TemporaryDirectory() as tmp:
        names = []
        for i, scan in enumerate(scans):
            p = read_pcd(git_show(mirror, commit_, scan), f"{repo}:{scan}")
            p = p[np.isfinite(p).all(1) & (np.abs(p).sum(1) > 0)]
            name = f"pjlab-{i:02d}"
            np.save(os.path.join(tmp, name + ".npy"), p)
            names.append((name, scan, p))
        subprocess.run([train, "detect", tmp, "--score-threshold", str(threshold), "--out", os.path.join(tmp, "det")], check=True, stdout=subprocess.DEVNULL)
        for name, scan, p in names:
            boxes = json.load(open(os.path.join(tmp, "det", "json", name + ".json")))["detections"]
            keep = np.ones(len(p), bool)
            for b in boxes:
                d = p[:, :2] - np.array([b["x"], b["y"]])
                c, s_ = np.cos(b["yaw"]), np.sin(b["yaw"])
                along, across = c * d[:, 0] + s_ * d[:, 1], -s_ * d[:, 0] + c * d[:, 1]
                inside = (abs(along) < b["l"] / 2 + margin) & (abs(across) < b["w"] / 2 + margin) & (abs(p[:, 2] - b["z"]) < b["h"] / 2 + margin)
                keep &= ~inside
            np.save(os.path.join(out, name + ".npy"), p[keep])
            rows.append((name + ".npy", "pandar64", f"{repo.replace('+', '/')}@{commit_[:12]}:{scan} (unlabelled; {len(boxes)} boxes scoring >= {threshold} removed, {int((~keep).sum())} points)"))


def place(row):
    """The place a backdrop shows: a KITTI object frame and a PJLab scan are their own; a sequence's frames share one."""
    name = row[0]
    if name.startswith("aimotive-"):
        return "aimotive"
    if name.startswith(("kitti-", "pjlab-")):
        return name
    return name.rsplit("-", 1)[0]


def balanced(rows):
    """Each place's scans repeated so the places weigh alike, interleaved place by place."""
    places = {}
    for r in rows:
        places.setdefault(place(r), []).append(r)
    most = max(len(v) for v in places.values())
    lists = [[v[i % len(v)] for i in range(most)] for v in places.values()]
    return [l[i] for i in range(most) for l in lists]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--aimotive")
    ap.add_argument("--kitti")
    ap.add_argument("--labelled", metavar="MIRRORS")
    ap.add_argument("--pjlab", metavar="MIRRORS")
    ap.add_argument("--train", default="target/debug/train", help="the train binary --pjlab detects with")
    ap.add_argument("--balance", action="store_true")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows = []
    if a.aimotive:
        aimotive(a.aimotive, a.out, rows)
    if a.kitti:
        kitti(a.kitti, a.out, rows)
    if a.labelled:
        labelled(a.labelled, a.out, rows)
    if a.pjlab:
        pjlab(a.pjlab, a.out, rows, train=a.train)
    if not rows:
        raise SystemExit("nothing to import: give --aimotive, --kitti, --labelled and/or --pjlab")
    if a.balance:
        rows = balanced(rows)
    with open(os.path.join(a.out, "backdrops.csv"), "w") as f:
        f.write("file,sensor,source\n")
        for r in rows:
            f.write(",".join(r) + "\n")
    print(f"wrote {len(rows)} backdrops to {a.out}")


if __name__ == "__main__":
    main()
