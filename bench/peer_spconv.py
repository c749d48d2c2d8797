#!/usr/bin/env python3
"""Peer side of pmunet's side-by-side benchmark: spconv 2.3.8 on the CPU, float32.

    python bench/peer_spconv.py SCENE.npy [--threads 2] [--runs 10] [--warmup 2]
                                [--parts gemm,convs,crosscheck,minkunet]
                                [--mink-runs 3] [--mink-warmup 1] [--json OUT.json]

SCENE.npy holds int32 voxel coordinates, N x 4 (batch, x, y, z) or N x 3.

Every figure is wall-clock time (time.perf_counter) of `--runs` timed calls after `--warmup`
untimed ones; median and min are reported in ms.  The figures mirror what pmunet's
`sparse-conv-bench` and `model-bench` time:

  gemm        torch.matmul of two 2048 x 2048 float32 matrices (the BLAS ceiling), GFLOP/s.
  convs       the submanifold 3x3x3 kernel map (spconv's indice pairs) of the scene;
              SubMConv3d k3 at C = 32, 64, 128 (C_in = C_out, no bias): forward on a cached map
              (no grad), and forward + backward (grads of features and weight);
              SparseConv3d k2 s2 at C = 64, forward + backward with its map built inside the timed
              call; SparseInverseConv3d k2 at C = 64 (the down conv's map, reused), forward + backward.
  crosscheck  SubMConv3d C = 32 at the current thread count against a pure-torch
              gather - matmul - scatter on the same (spconv) kernel map and weights: rows whose
              largest absolute difference exceeds 1e-3.  spconv 2.3.8's CPU kernels race at > 1
              thread, so some rows come out wrong.
  minkunet    MinkUNet at paper width (SPVNAS / Person-MinkUNet layout, 31-channel linear head):
              inference forward of one frame (eval mode, no grad) and one training step at batch 2
              (the scene as samples 0 and 1; forward, mean of squares of the head output, backward,
              Adam).  Each runs in a fresh subprocess, so the peak RSS (ru_maxrss) reported with it
              is that of a process that did only that.  Every kernel map is rebuilt on every call,
              as in a real forward pass.

spconv 2.3.8's CPU backward calls torch.cuda.current_stream(), which fails with a CUDA torch wheel
on a machine without a GPU driver; `get_current_stream` is replaced by a function returning 0
(the stream is not used by CPU kernels).
"""
import argparse
import json
import os
import subprocess
import sys
import time

PARTS = ("gemm", "convs", "crosscheck", "minkunet")
VOXEL_SIZE = (0.05, 0.05, 0.1)  # metres; pmunet's scene::VOXEL_SIZE (features = voxel centres)
MINK_CHANNELS = (32, 32, 64, 128, 256, 256, 128, 96, 96)
HEAD_CHANNELS = 31  # 2 * 12 rotation bins + 7


def parse_args():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scene", help="voxel coordinates, int .npy, N x 4 (batch, x, y, z) or N x 3")
    ap.add_argument("--threads", type=int, default=2, help="torch / OpenMP threads (default 2)")
    ap.add_argument("--runs", type=int, default=10, help="timed runs per figure (default 10)")
    ap.add_argument("--warmup", type=int, default=2, help="untimed warm-up runs (default 2)")
    ap.add_argument("--parts", default=",".join(PARTS),
                    help=f"comma-separated subset of {','.join(PARTS)} (default: all)")
    ap.add_argument("--mink-runs", type=int, default=3, help="timed runs of each MinkUNet figure (default 3)")
    ap.add_argument("--mink-warmup", type=int, default=1, help="warm-up runs of each MinkUNet figure (default 1)")
    ap.add_argument("--json", metavar="OUT", default=None, help="also write the result JSON here")
    ap.add_argument("--mink-part", choices=("infer", "train"), default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    unknown = set(p for p in args.parts.split(",") if p) - set(PARTS)
    if unknown:
        ap.error(f"unknown --parts {sorted(unknown)}; choose from {PARTS}")
    if args.runs < 1 or args.mink_runs < 1 or args.threads < 1:
        ap.error("--runs, --mink-runs and --threads must be at least 1")
    return args


ARGS = parse_args()
# Thread counts must be fixed before torch (and its OpenMP / MKL runtimes) load.
for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = str(ARGS.threads)

import numpy as np  # noqa: E402
import torch  # noqa: E402

torch.set_num_threads(ARGS.threads)

import spconv  # noqa: E402
import spconv.pytorch as spc  # noqa: E402
from spconv.core import ConvAlgo  # noqa: E402
from spconv.pytorch import cppcore as _sp_cppcore  # noqa: E402
from spconv.pytorch import ops as _sp_ops  # noqa: E402

if not torch.cuda.is_available():
    # Workaround, see the module docstring.  `ops` imported the function by name, so patch both.
    def _no_stream():
        return 0

    for _mod in (_sp_cppcore, _sp_ops):
        _mod.get_current_stream = _no_stream
    try:
        from spconv.pytorch import hash as _sp_hash  # noqa: E402

        _sp_hash.get_current_stream = _no_stream
    except ImportError:
        pass


def say(*parts):
    print("[peer]", *parts, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------------------
# timing
# ------------------------------------------------------------------------------------------------
def measure(fn, runs, warmup, before=None):
    """Times fn(); before() runs untimed ahead of every call (e.g. to clear gradients)."""
    times = []
    for i in range(warmup + runs):
        if before is not None:
            before()
        start = time.perf_counter()
        fn()
        elapsed = (time.perf_counter() - start) * 1e3
        if i >= warmup:
            times.append(elapsed)
    return {"median_ms": float(np.median(times)), "min_ms": float(np.min(times)), "runs": runs,
            "times_ms": [round(t, 4) for t in times]}


def with_gflops(rec, flop):
    rec["gflop"] = flop / 1e9
    rec["gflops_median"] = flop / rec["median_ms"] / 1e6
    rec["gflops_best"] = flop / rec["min_ms"] / 1e6
    return rec


# ------------------------------------------------------------------------------------------------
# scene
# ------------------------------------------------------------------------------------------------
class Scene:
    """The scene as spconv wants it: non-negative int32 indices and a spatial shape.

    The coordinates are shifted by a multiple of 16, so the voxels that share a cell at each of
    four stride-2 levels are the same ones as under pmunet's floor division of the raw
    coordinates (a shift by an odd minimum would pair different voxels at the coarse levels)."""

    def __init__(self, path):
        raw = np.load(path)
        if raw.ndim != 2 or raw.shape[1] not in (3, 4):
            raise SystemExit(f"{path}: expected an N x 4 or N x 3 array, got shape {raw.shape}")
        raw = raw.astype(np.int64)
        if raw.shape[1] == 3:
            raw = np.concatenate([np.zeros((raw.shape[0], 1), np.int64), raw], 1)
        self.raw = raw
        shift = (raw[:, 1:].min(0) // 16) * 16
        xyz = raw[:, 1:] - shift
        self.shape = [int(s) for s in ((xyz.max(0) + 1 + 15) // 16 * 16)]
        self.indices = torch.from_numpy(np.concatenate([raw[:, :1], xyz], 1).astype(np.int32))
        self.batch_size = int(raw[:, 0].max()) + 1
        self.n = int(raw.shape[0])

    def tensor(self, feats, indices=None, batch_size=None):
        return spc.SparseConvTensor(feats, self.indices if indices is None else indices, self.shape,
                                    self.batch_size if batch_size is None else batch_size)

    def subm_pairs(self):
        return _sp_ops.get_indice_pairs(self.indices, self.batch_size, self.shape, ConvAlgo.Native,
                                        [3, 3, 3], [1, 1, 1], [1, 1, 1], [1, 1, 1], [0, 0, 0], True, False)


# ------------------------------------------------------------------------------------------------
# pure-torch reference of SubMConv3d on spconv's own kernel map
# ------------------------------------------------------------------------------------------------
def full_pair_lists(indice_pairs, indice_pair_num, n):
    """spconv's native submanifold map stores, for each offset k < 13, the (input, output) pairs of
    offset k only; offset 26 - k is the same list with the roles swapped, and the centre (13) is
    the identity.  Returns the 27 (input rows, output rows) lists of the full map."""
    kv = indice_pairs.shape[1]
    centre = kv // 2
    stored = [int(m) for m in indice_pair_num]
    empty = (torch.empty(0, dtype=torch.long), torch.empty(0, dtype=torch.long))
    lists = [empty] * kv
    for k in range(kv):
        if stored[k]:
            lists[k] = (indice_pairs[0, k, :stored[k]].long(), indice_pairs[1, k, :stored[k]].long())
    for k in range(centre):
        mirror = kv - 1 - k
        if stored[k] and not stored[mirror]:
            lists[mirror] = (lists[k][1], lists[k][0])
    if not stored[centre]:
        ident = torch.arange(n)
        lists[centre] = (ident, ident)
    return lists


def gather_matmul_scatter(feats, weights, lists, n_out):
    """out[o] += feats[i] @ weights[k] over every pair (i, o) of offset k."""
    out = feats.new_zeros(n_out, weights.shape[-1])
    for k, (rows_in, rows_out) in enumerate(lists):
        if rows_in.numel():
            out.index_add_(0, rows_out, feats.index_select(0, rows_in) @ weights[k])
    return out


def krsc_to_kio(weight):
    """spconv's KRSC weight [C_out, kx, ky, kz, C_in] as [27, C_in, C_out]."""
    c_out, c_in = weight.shape[0], weight.shape[-1]
    return weight.detach().permute(1, 2, 3, 4, 0).reshape(-1, c_in, c_out).contiguous()


# ------------------------------------------------------------------------------------------------
# parts
# ------------------------------------------------------------------------------------------------
def bench_gemm(runs, warmup):
    n = 2048
    g = torch.Generator().manual_seed(7)
    a = torch.randn(n, n, generator=g)
    b = torch.randn(n, n, generator=g)
    rec = with_gflops(measure(lambda: torch.matmul(a, b), runs, warmup), 2.0 * n ** 3)
    rec["size"] = n
    say(f"sgemm {n}^3: {rec['median_ms']:.1f} ms, {rec['gflops_median']:.1f} GFLOP/s")
    return rec


def bench_convs(scene, runs, warmup):
    res = {}
    n = scene.n
    g = torch.Generator().manual_seed(0)

    _, ip, ipn = scene.subm_pairs()
    # stored half of the non-centre offsets, mirrored, plus the centre
    pairs = 2 * int(ipn.sum()) + n
    res["subm_pairs"] = pairs
    res["subm_map"] = measure(scene.subm_pairs, runs, warmup)
    say(f"subm k3 map: {pairs} pairs, {res['subm_map']['median_ms']:.2f} ms")

    res["subm"] = {}
    for c in (32, 64, 128):
        flop = 2.0 * pairs * c * c
        x = torch.empty(n, c).uniform_(-1.0, 1.0, generator=g)
        grad_out = torch.empty(n, c).uniform_(-1.0, 1.0, generator=g)
        conv = spc.SubMConv3d(c, c, 3, bias=False, indice_key="bench_subm")
        with torch.no_grad():
            first = conv(scene.tensor(x))  # builds the map once and carries it in indice_dict
        cached = first.replace_feature(x)

        def forward():
            with torch.no_grad():
                conv(cached)

        fwd = with_gflops(measure(forward, runs, warmup), flop)

        xg = x.clone().requires_grad_(True)
        cached_g = first.replace_feature(xg)

        def clear():
            xg.grad = None
            conv.weight.grad = None

        def forward_backward():
            conv(cached_g).features.backward(grad_out)

        fwd_bwd = with_gflops(measure(forward_backward, runs, warmup, before=clear), 3.0 * flop)
        res["subm"][str(c)] = {"fwd": fwd, "fwd_bwd": fwd_bwd}
        say(f"subm k3 C{c}: fwd {fwd['median_ms']:.2f} ms, fwd+bwd {fwd_bwd['median_ms']:.2f} ms")

    c = 64
    x = torch.empty(n, c).uniform_(-1.0, 1.0, generator=g).requires_grad_(True)
    down = spc.SparseConv3d(c, c, 2, stride=2, bias=False, indice_key="bench_down")
    up = spc.SparseInverseConv3d(c, c, 2, bias=False, indice_key="bench_down")
    with torch.no_grad():
        coarse = down(scene.tensor(x.detach()))
    n_coarse = int(coarse.features.shape[0])
    down_pairs = n  # k2 s2: every input voxel lies in exactly one output cell
    grad_coarse = torch.empty(n_coarse, c).uniform_(-1.0, 1.0, generator=g)

    def clear_down():
        x.grad = None
        down.weight.grad = None

    def down_forward_backward():
        # a fresh tensor has no indice_dict, so the k2 s2 map is built inside the timed call
        down(scene.tensor(x)).features.backward(grad_coarse)

    res["down_k2s2_c64_fwd_bwd_incl_map"] = with_gflops(
        measure(down_forward_backward, runs, warmup, before=clear_down), 3.0 * 2.0 * down_pairs * c * c)
    res["down_k2s2_coarse_voxels"] = n_coarse

    xc = torch.empty(n_coarse, c).uniform_(-1.0, 1.0, generator=g).requires_grad_(True)
    coarse_g = coarse.replace_feature(xc)
    grad_fine = torch.empty(n, c).uniform_(-1.0, 1.0, generator=g)

    def clear_up():
        xc.grad = None
        up.weight.grad = None

    def up_forward_backward():
        up(coarse_g).features.backward(grad_fine)

    res["up_k2_c64_fwd_bwd"] = with_gflops(
        measure(up_forward_backward, runs, warmup, before=clear_up), 3.0 * 2.0 * down_pairs * c * c)
    say(f"down k2s2 C64 fwd+bwd (map incl.) {res['down_k2s2_c64_fwd_bwd_incl_map']['median_ms']:.2f} ms, "
        f"up k2 C64 fwd+bwd {res['up_k2_c64_fwd_bwd']['median_ms']:.2f} ms ({n_coarse} coarse voxels)")
    return res


def crosscheck(scene, repeats=3, threshold=1e-3):
    c = 32
    g = torch.Generator().manual_seed(1)
    x = torch.empty(scene.n, c).uniform_(-1.0, 1.0, generator=g)
    conv = spc.SubMConv3d(c, c, 3, bias=False)
    with torch.no_grad():
        conv.weight.copy_(torch.randn(conv.weight.shape, generator=g) / (27 * c) ** 0.5)
    _, ip, ipn = scene.subm_pairs()
    lists = full_pair_lists(ip, ipn, scene.n)
    with torch.no_grad():
        reference = gather_matmul_scatter(x, krsc_to_kio(conv.weight), lists, scene.n)
    runs = []
    for _ in range(repeats):
        with torch.no_grad():
            out = conv(scene.tensor(x)).features
        err = (out - reference).abs().max(1).values
        runs.append({"rows_wrong": int((err > threshold).sum()), "max_abs_err": float(err.max())})
    res = {
        "channels": c,
        "threads": torch.get_num_threads(),
        "threshold": threshold,
        "rows": scene.n,
        "reference_pairs": int(sum(l[0].numel() for l in lists)),
        "reference_max_abs": float(reference.abs().max()),
        "repeats": runs,
        "rows_wrong_max": max(r["rows_wrong"] for r in runs),
        "max_abs_err": max(r["max_abs_err"] for r in runs),
    }
    say(f"crosscheck SubMConv3d C{c} at {res['threads']} threads: rows wrong per repeat "
        f"{[r['rows_wrong'] for r in runs]} (max abs err {res['max_abs_err']:.3g}, "
        f"|ref| max {res['reference_max_abs']:.3g})")
    return res


# ------------------------------------------------------------------------------------------------
# MinkUNet (SPVNAS / Person-MinkUNet layout) in spconv
# ------------------------------------------------------------------------------------------------
class BatchNormReLU(spc.SparseModule):  # SparseModule: SparseSequential hands it the tensor
    def __init__(self, c, relu=True):
        super().__init__()
        self.bn = torch.nn.BatchNorm1d(c)
        self.relu = relu

    def forward(self, x):
        f = self.bn(x.features)
        return x.replace_feature(torch.relu(f) if self.relu else f)


class Residual(spc.SparseModule):
    """conv3-BN-ReLU-conv3-BN, plus the input (through a 1x1 conv + BN when C changes), ReLU."""

    def __init__(self, c_in, c_out, key):
        super().__init__()
        self.conv1 = spc.SubMConv3d(c_in, c_out, 3, bias=False, indice_key=key)
        self.norm1 = BatchNormReLU(c_out)
        self.conv2 = spc.SubMConv3d(c_out, c_out, 3, bias=False, indice_key=key)
        self.norm2 = BatchNormReLU(c_out, relu=False)
        if c_in != c_out:
            self.short = spc.SubMConv3d(c_in, c_out, 1, bias=False)
            self.short_norm = BatchNormReLU(c_out, relu=False)
        else:
            self.short = None

    def forward(self, x):
        y = self.norm2(self.conv2(self.norm1(self.conv1(x))))
        s = x.features if self.short is None else self.short_norm(self.short(x)).features
        return y.replace_feature(torch.relu(y.features + s))


class MinkUNet(torch.nn.Module):
    def __init__(self, c_in=3, head=HEAD_CHANNELS, cs=MINK_CHANNELS):
        super().__init__()
        self.stem = spc.SparseSequential(
            spc.SubMConv3d(c_in, cs[0], 3, bias=False, indice_key="lvl0"), BatchNormReLU(cs[0]),
            spc.SubMConv3d(cs[0], cs[0], 3, bias=False, indice_key="lvl0"), BatchNormReLU(cs[0]))
        self.down = torch.nn.ModuleList()
        for i in range(1, 5):
            self.down.append(spc.SparseSequential(
                spc.SparseConv3d(cs[i - 1], cs[i - 1], 2, stride=2, bias=False, indice_key=f"down{i}"),
                BatchNormReLU(cs[i - 1]),
                Residual(cs[i - 1], cs[i], f"lvl{i}"),
                Residual(cs[i], cs[i], f"lvl{i}")))
        self.up_conv = torch.nn.ModuleList()
        self.up_blocks = torch.nn.ModuleList()
        for j in range(4):
            prev, out, skip = cs[4 + j], cs[5 + j], cs[3 - j]
            level = 4 - j  # the inverse conv undoes down{level}
            self.up_conv.append(spc.SparseSequential(
                spc.SparseInverseConv3d(prev, out, 2, bias=False, indice_key=f"down{level}"),
                BatchNormReLU(out)))
            self.up_blocks.append(spc.SparseSequential(
                Residual(out + skip, out, f"lvl{level - 1}"), Residual(out, out, f"lvl{level - 1}")))
        self.head = torch.nn.Linear(cs[-1], head)

    def forward(self, x):
        levels = [self.stem(x)]
        for stage in self.down:
            levels.append(stage(levels[-1]))
        y = levels[-1]
        for j, (conv, blocks) in enumerate(zip(self.up_conv, self.up_blocks)):
            y = conv(y)
            y = y.replace_feature(torch.cat([y.features, levels[3 - j].features], 1))  # [up, skip]
            y = blocks(y)
        return self.head(y.features), [int(l.features.shape[0]) for l in levels]


def mink_input(scene, batch):
    idx = torch.cat([scene.indices.clone() for _ in range(batch)], 0)
    raw = np.concatenate([scene.raw for _ in range(batch)], 0)
    for b in range(batch):
        idx[b * scene.n:(b + 1) * scene.n, 0] = b
    # features = voxel centres in metres, as pmunet's model bench feeds them
    feats = torch.from_numpy(((raw[:, 1:] + 0.5) * np.array(VOXEL_SIZE)).astype(np.float32))
    return idx, feats


def rss_mib(kind):
    import resource

    if kind == "peak":
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmRSS:"):
                return float(line.split()[1]) / 1024.0
    return 0.0


def mink_part(scene, part, runs, warmup):
    """Runs in its own process (see --mink-part)."""
    torch.manual_seed(0)
    model = MinkUNet()
    res = {"params": sum(p.numel() for p in model.parameters()), "rss_before_mib": rss_mib("now")}
    if part == "infer":
        idx, feats = mink_input(scene, 1)
        model.eval()

        def step():
            with torch.no_grad():
                return model(scene.tensor(feats, idx, 1))

        _, res["voxels_per_level"] = step()
        res["infer_b1"] = measure(step, runs, warmup)
    else:
        idx, feats = mink_input(scene, 2)
        model.train()
        opt = torch.optim.Adam(model.parameters(), lr=1e-3)

        def step():
            opt.zero_grad(set_to_none=True)
            out, _ = model(scene.tensor(feats, idx, 2))
            out.square().mean().backward()
            opt.step()

        res["train_b2"] = measure(step, runs, warmup)
        res["voxels"] = int(idx.shape[0])
    res["peak_rss_mib"] = rss_mib("peak")
    return res


def bench_minkunet(runs, warmup):
    res = {}
    for part in ("infer", "train"):
        cmd = [sys.executable, os.path.abspath(__file__), ARGS.scene, "--threads", str(ARGS.threads),
               "--runs", str(runs), "--warmup", str(warmup), "--mink-part", part]
        say("MinkUNet", part, "in a fresh process ...")
        start = time.time()
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, text=True)
        lines = [l for l in proc.stdout.splitlines() if l.startswith("{")]
        if proc.returncode != 0 or not lines:
            res[part] = {"error": f"exit status {proc.returncode}", "stdout_tail": proc.stdout[-2000:]}
            say("MinkUNet", part, "FAILED:", res[part]["error"])
            continue
        res[part] = json.loads(lines[-1])
        res[part]["wall_s"] = time.time() - start
        fig = res[part].get("infer_b1") or res[part].get("train_b2")
        say(f"MinkUNet {part}: {res[part]['params']} params, median {fig['median_ms']:.0f} ms, "
            f"peak RSS {res[part]['peak_rss_mib']:.0f} MiB")
    params = {res[p]["params"] for p in res if "params" in res[p]}
    res["params"] = params.pop() if len(params) == 1 else None
    return res


def environment():
    import platform

    cpu = "?"
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(l.split(":", 1)[1].strip() for l in fh if l.startswith("model name"))
    except (OSError, StopIteration):
        pass
    try:
        import cumm

        cumm_version = cumm.__version__
    except ImportError:
        cumm_version = None
    return {
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "spconv": spconv.__version__,
        "cumm": cumm_version,
        "numpy": np.__version__,
        "cpu": cpu,
        "nproc": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        # The kernels ATen dispatched to (ATEN_CPU_CAPABILITY caps them): "AVX512", "AVX2", ...
        "torch_cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "isa_env": {k: os.environ[k] for k in ("ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS", "ONEDNN_MAX_CPU_ISA") if k in os.environ},
        "cuda_available": torch.cuda.is_available(),
    }


def main():
    scene = Scene(ARGS.scene)
    if ARGS.mink_part:
        print(json.dumps(mink_part(scene, ARGS.mink_part, ARGS.runs, ARGS.warmup)), flush=True)
        return
    parts = [p for p in ARGS.parts.split(",") if p]
    out = {
        "tool": "spconv",
        "env": environment(),
        "scene": {"path": os.path.abspath(ARGS.scene), "voxels": scene.n, "spatial_shape": scene.shape},
        "threads": ARGS.threads,
        "runs": ARGS.runs,
        "warmup": ARGS.warmup,
        "parts": parts,
    }
    say(f"spconv {spconv.__version__}, torch {torch.__version__}, {ARGS.threads} threads, "
        f"{scene.n} voxels, parts {parts}")
    if "gemm" in parts:
        out["gemm"] = bench_gemm(ARGS.runs, ARGS.warmup)
    if "convs" in parts:
        out["convs"] = bench_convs(scene, ARGS.runs, ARGS.warmup)
    if "crosscheck" in parts:
        out["crosscheck"] = crosscheck(scene)
    if "minkunet" in parts:
        out["minkunet"] = bench_minkunet(ARGS.mink_runs, ARGS.mink_warmup)
        out["minkunet"]["runs"] = ARGS.mink_runs
        out["minkunet"]["warmup"] = ARGS.mink_warmup
    text = json.dumps(out, indent=1)
    if ARGS.json:
        with open(ARGS.json, "w") as fh:
            fh.write(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
