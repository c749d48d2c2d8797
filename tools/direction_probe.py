#!/usr/bin/env python3
"""How much of a person's facing direction is in the LiDAR points, given the box (docs/recipe.md §14).

    python3 tools/direction_probe.py data/sim-bench-v1 [--cell 0.2 0.1] [--l2 0.01] [--voxel 0.2]

A detector that has found a person and the axis of their heading still has to tell front from
back. This probe asks how well that can be done from the points alone, with everything else
given: for every labelled person (at least 10 points, within 25 m, as the protocol counts them)
the points inside the box (grown by 5 cm) are put in a frame whose x runs along the heading's
axis, signed to point at the sensor, y to its left and z up from the box's floor. The question
is then binary: does the person face the sensor's side (+x) or away from it? A logistic
regression on the points' occupancy histogram in that frame (cells of the given size, share of
the person's points per cell) is fitted on the `sim-train-*` sequences and scored on the
`sim-val-*` ones, scenes it never saw. Its validation accuracy is a lower bound on what the points
hold about the direction at that resolution; 50 % means nothing a linear read of the occupancy
finds. `--voxel S` first replaces the points by the centres of the occupied voxels of a
world-aligned grid of S metres: what a sparse network's occupancy shows, before any point
feature. `--detections DIR` also scores it in the frames of a detector's matched boxes (their
axis and place, not the labels'), matched by BEV distance (0.5 m) to counted people, with the
detector's own heading scored on the same pairs: what a second stage on those boxes would tell.
Two baselines come with it: the majority class, and the accuracy of "faces the side of the box
centre with more of the points" (a rule of thumb that is given the box). numpy only.
"""
import argparse
import glob
import json
import math
import os

import numpy as np

PCD_DTYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4",
              ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4"}


def read_pcd(path):
    """x, y, z of a binary PCD file (the writer's format)."""
    with open(path, "rb") as f:
        header = {}
        while True:
            line = f.readline().decode("ascii").strip()
            if not line or line.startswith("#"):
                continue
            key, *vals = line.split()
            header[key] = vals
            if key == "DATA":
                break
        if header["DATA"][0] != "binary":
            raise SystemExit(f"{path}: DATA {header['DATA'][0]} (only binary is read here)")
        fields = [(n, PCD_DTYPES[(t, int(s))]) for n, t, s in zip(header["FIELDS"], header["TYPE"], header["SIZE"])]
        n = int(header["POINTS"][0])
        data = np.frombuffer(f.read(), dtype=np.dtype(fields), count=n)
    return np.stack([data["x"], data["y"], data["z"]], axis=1).astype(np.float64)


def read_calibration(root):
    """Sensor → base transforms, `Rz(rotation[2]) · (p − translation)` (JRDB's convention)."""
    out, cur, key = {}, None, None
    for line in open(os.path.join(root, "calibration", "defaults.yaml")):
        s = line.strip()
        if s.startswith("lidar_upper_to_rgb") or s.startswith("lidar_lower_to_rgb"):
            cur = "upper" if "upper" in s else "lower"
            out[cur] = {}
        elif cur and (s.startswith("rotation:") or s.startswith("translation:")):
            key, vals = s.split(":", 1)
            out[cur][key] = [float(v) for v in vals.strip(" []").split(",")]
    return out


def to_base(p, cal):
    q = p - np.array(cal["translation"])
    c, s = math.cos(cal["rotation"][2]), math.sin(cal["rotation"][2])
    return np.stack([c * q[:, 0] - s * q[:, 1], s * q[:, 0] + c * q[:, 1], q[:, 2]], axis=1)


def canonical(pts, b, heading, margin):
    """The points in box `b` (grown by `margin`) in the frame along b's axis, +x towards the
    sensor: as they are, and centred on their centroid; and whether `heading` points along +x.
    None when fewer than 3 points are inside."""
    c, s = math.cos(b["rot_z"]), math.sin(b["rot_z"])
    d = pts - np.array([b["cx"], b["cy"], b["cz"] - b["h"] / 2])
    x, y = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    inside = (np.abs(x) <= b["l"] / 2 + margin) & (np.abs(y) <= b["w"] / 2 + margin) \
        & (d[:, 2] >= -margin) & (d[:, 2] <= b["h"] + margin)
    if inside.sum() < 3:
        return None
    # The axis points at the sensor's side when the sensor (the origin) lies ahead along it.
    sign = 1.0 if (c * -b["cx"] + s * -b["cy"]) > 0 else -1.0
    faces = sign * (math.cos(heading) * c + math.sin(heading) * s) > 0
    q = np.stack([sign * x[inside], sign * y[inside], d[inside, 2]], axis=1)
    # The box's centre is not given to a detector, and where it sits on the body says which way
    # the body faces (the feet reach forward): centre x and y on the points.
    return q, q - np.r_[q[:, :2].mean(0), 0.0], faces


def match(dets, gts, min_score=0.3, radius=0.5):
    """(detection, label) pairs: best score first, each to the nearest unmatched label in BEV."""
    taken, out = [False] * len(gts), []
    for d in sorted(dets, key=lambda d: -d["score"]):
        if d["score"] < min_score:
            break
        near = [(math.hypot(d["box"]["cx"] - g["cx"], d["box"]["cy"] - g["cy"]), i) for i, g in enumerate(gts) if not taken[i]]
        near = [t for t in near if t[0] < radius]
        if near:
            i = min(near)[1]
            taken[i] = True
            out.append((d["box"], gts[i]))
    return out


def people(root, split, cal, voxel=None, detections=None, max_range=25.0, min_points=10):
    """(points in the sensor-signed axis frame, the same centred on their centroid, range, faces
    the sensor?) for every counted person; with `detections` (a folder of `infer`'s per-sequence
    JSON), in the frame of the detection matched to each person instead, with the detector's own
    heading's error (degrees) after them."""
    for lf in sorted(glob.glob(os.path.join(root, "labels", "labels_3d", f"sim-{split}-*.json"))):
        seq = os.path.basename(lf)[:-5]
        labels = json.load(open(lf))["labels"]
        dets = json.load(open(os.path.join(detections, seq + ".json")))["detections"] if detections else None
        for frame, ls in sorted(labels.items()):
            boxes = [l["box"] for l in ls if l["label_id"].startswith("pedestrian")
                     and l["attributes"]["num_points"] >= min_points
                     and math.hypot(l["box"]["cx"], l["box"]["cy"]) <= max_range]
            if not boxes:
                continue
            pts = np.concatenate([to_base(read_pcd(os.path.join(root, "pointclouds", f"{s}_velodyne", seq, frame)), cal[s])
                                  for s in ("upper", "lower")])
            if voxel:
                # What a network on a world-aligned grid sees: which voxels are occupied, each
                # standing at its centre, whatever the points inside.
                pts = (np.unique(np.floor(pts / voxel), axis=0) + 0.5) * voxel
            # The box grown by 5 cm, or by half a voxel for voxel centres.
            margin = max(0.05, (voxel or 0) / 2)
            if dets is None:
                for b in boxes:
                    t = canonical(pts, b, b["rot_z"], margin)
                    if t:
                        yield t[0], t[1], math.hypot(b["cx"], b["cy"]), t[2]
                continue
            for d, g in match(dets.get(frame[:-4], []), boxes):
                t = canonical(pts, d, g["rot_z"], margin)
                if t:
                    err = abs((d["rot_z"] - g["rot_z"] + math.pi) % (2 * math.pi) - math.pi)
                    yield t[0], t[1], math.hypot(g["cx"], g["cy"]), t[2], math.degrees(err)


def histogram(p, cell, half=0.6, height=2.0):
    nx, nz = int(round(2 * half / cell)), int(round(height / cell))
    ix = np.clip(((p[:, 0] + half) / cell).astype(int), 0, nx - 1)
    iy = np.clip(((p[:, 1] + half) / cell).astype(int), 0, nx - 1)
    iz = np.clip((p[:, 2] / cell).astype(int), 0, nz - 1)
    h = np.bincount((ix * nx + iy) * nz + iz, minlength=nx * nx * nz).astype(np.float64)
    return h / len(p)


def fit_logistic(x, y, l2, iters=50):
    """L2-regularised logistic regression by damped Newton steps on standardised features."""
    mu, sd = x.mean(0), x.std(0) + 1e-6
    z = np.hstack([(x - mu) / sd, np.ones((len(x), 1))])
    reg = np.r_[np.ones(z.shape[1] - 1), 0.0] * l2

    def objective(w):
        m = z @ w
        return np.mean(np.logaddexp(0, m) - y * m) + 0.5 * np.sum(reg * w * w)

    w = np.zeros(z.shape[1])
    f = objective(w)
    for _ in range(iters):
        p = 0.5 * (1 + np.tanh(0.5 * (z @ w)))
        g = z.T @ (p - y) / len(y) + reg * w
        hess = (z * (p * (1 - p))[:, None]).T @ z / len(y) + np.diag(reg + 1e-9)
        step, t = np.linalg.solve(hess, g), 1.0
        while objective(w - t * step) > f and t > 1e-4:
            t *= 0.5
        w, f_old = w - t * step, f
        f = objective(w)
        if f_old - f < 1e-9:
            break
    return lambda xs: (np.hstack([(xs - mu) / sd, np.ones((len(xs), 1))]) @ w) > 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("root")
    ap.add_argument("--cell", type=float, nargs="+", default=[0.2, 0.1])
    ap.add_argument("--l2", type=float, default=1e-2, help="ridge weight on the standardised features")
    ap.add_argument("--detections", help="also score the facing in the frames of these detections (infer's detections/val/json)")
    ap.add_argument("--voxel", type=float, help="replace the points by the centres of the occupied world-aligned voxels of this size (m)")
    args = ap.parse_args()
    cal = read_calibration(args.root)
    data = {split: list(people(args.root, split, cal, args.voxel)) for split in ("train", "val")}
    det = list(people(args.root, "val", cal, args.voxel, args.detections)) if args.detections else None
    if det == []:
        raise SystemExit(f"{args.detections}: no detection scoring ≥ 0.3 lies within 0.5 m of a counted person")
    ytr = np.array([t[3] for t in data["train"]], dtype=float)
    yva = np.array([t[3] for t in data["val"]], dtype=float)
    print(f"{len(ytr)} training people, {len(yva)} validation people; facing the sensor: "
          f"{ytr.mean():.1%} / {yva.mean():.1%}")
    majority = max(yva.mean(), 1 - yva.mean())
    more_ahead = np.array([(t[0][:, 0] > 0).mean() > 0.5 for t in data["val"]])
    rng = np.array([t[2] for t in data["val"]])
    bands = [(0, 10), (10, 20), (20, 25.01)]
    print(f"majority class: {majority:.1%}; 'faces the side of the box centre with more of its points': {(more_ahead == yva).mean():.1%}")
    for centre, k in (("the points' centroid", 1), ("the box's centre (given)", 0)):
        for cell in args.cell:
            xtr = np.stack([histogram(t[k], cell) for t in data["train"]])
            xva = np.stack([histogram(t[k], cell) for t in data["val"]])
            keep = xtr.std(0) > 0
            predict = fit_logistic(xtr[:, keep], ytr, args.l2)
            acc_tr = (predict(xtr[:, keep]) == ytr).mean()
            right = predict(xva[:, keep]) == yva
            by_band = " / ".join(f"{right[(rng >= a) & (rng < b)].mean():.1%}" for a, b in bands)
            print(f"centred on {centre}, cell {cell:.2f} m ({keep.sum()} cells used): "
                  f"training {acc_tr:.1%}, validation {right.mean():.1%} (0–10 / 10–20 / 20–25 m: {by_band})")
            if k == 1 and det:
                xd = np.stack([histogram(t[1], cell) for t in det])
                yd = np.array([t[3] for t in det])
                own = np.mean([t[4] < 90 for t in det])
                print(f"  in the frames of {len(det)} matched detections (score ≥ 0.3): {(predict(xd[:, keep]) == yd).mean():.1%} "
                      f"told right (the detector's own heading: {own:.1%} within 90°)")


if __name__ == "__main__":
    main()
