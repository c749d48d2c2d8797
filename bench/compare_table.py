#!/usr/bin/env python3
"""Builds the side-by-side markdown table of one `bench/compare_spconv.sh` results folder.

    python3 bench/compare_table.py RESULTS_DIR

Reads (whichever are there) from RESULTS_DIR:
  spconv.json                        bench/peer_spconv.py --json
  pmunet_conv_<backend>.json         cargo run -p bench --bin sparse-conv-bench -- ... --json
  pmunet_model_<backend>_b1.json     cargo run -p bench --bin model-bench -- ... --batch 1 --json
  pmunet_model_<backend>_b2.json     cargo run -p bench --bin model-bench -- ... --batch 2 --json
  <name>.rc                          exit status of each step (absent: the step was not run)
  <name>.log                         its stderr
  meta.txt                           key=value lines written by compare_spconv.sh
or, after `--rounds N`, the same files in RESULTS_DIR/round1 ... roundN/ (meta.txt stays at the
top): then each figure is its median over the rounds and each ratio the median of the rounds' own
ratios, with their range; prints the table (plus a few context lines and notes) and writes it to RESULTS_DIR/table.md.
Standard library only.
"""
import json
import os
import sys

BACKENDS = ("flex", "ndarray")
TIME_TARGET = 1.5  # the speed target: pmunet time <= spconv time / 1.5
MEM_TARGET = 1.0  # and pmunet peak memory <= spconv's
# The fixed "pmunet must reach" figures (1.5x spconv medians measured in 2026-11 on a
# slower machine of this kind; MiB for memory): by row label, median rows only.
ISSUE_FIGURES = {
    "subm k3 kernel-map build": 12.7,
    "subm k3 C32 fwd": 4.5, "subm k3 C32 fwd+bwd": 11.9,
    "subm k3 C64 fwd": 9.3, "subm k3 C64 fwd+bwd": 26.6,
    "subm k3 C128 fwd": 33.5, "subm k3 C128 fwd+bwd": 86.1,
    "down k2s2 C64 fwd+bwd (map incl.)": 18.1,
    "up k2 C64 fwd+bwd": 15.7,
    "MinkUNet inference, 1 frame": 730.0,
    "MinkUNet training step, batch 2": 3200.0,
    "peak memory (RSS) of the training step, batch 2": 2760.0,
}


class Missing:
    """Why a cell has no number: 'skipped' (step not run), 'failed' (step ran, no JSON), 'n/a'
    (the step's JSON has no such field)."""

    def __init__(self, why):
        self.why = why

    def __str__(self):
        return self.why


def load(folder, name):
    """The last JSON object printed to RESULTS_DIR/name.json, or a Missing."""
    rc_path = os.path.join(folder, name + ".rc")
    path = os.path.join(folder, name + ".json")
    if not os.path.exists(rc_path) and not os.path.exists(path):
        return Missing("skipped")
    rc = None
    if os.path.exists(rc_path):
        with open(rc_path) as fh:
            text = fh.read().strip()
        rc = int(text) if text.lstrip("-").isdigit() else None
    try:
        with open(path) as fh:
            text = fh.read()
    except OSError:
        return Missing("failed")
    if rc not in (None, 0):
        return Missing("failed")
    # The peer writes one indented document; the Rust benches print one object on a line.
    try:
        return json.loads(text)
    except ValueError:
        pass
    for line in reversed(text.splitlines()):
        line = line.strip()
        if line.startswith("{"):
            try:
                return json.loads(line)
            except ValueError:
                continue
    return Missing("failed")


def get(doc, *path):
    """doc[path[0]][path[1]]...; a list step is a (key, value) pair selecting the matching item."""
    if isinstance(doc, Missing):
        return doc
    cur = doc
    for step in path:
        if isinstance(step, tuple):
            key, want = step
            found = [item for item in cur if isinstance(item, dict) and item.get(key) == want] if isinstance(cur, list) else []
            if not found:
                return Missing("n/a")
            cur = found[0]
        elif isinstance(cur, dict) and step in cur:
            cur = cur[step]
        else:
            return Missing("n/a")
    if cur is None:
        return Missing("n/a")
    return cur


def read_meta(folder):
    meta = {}
    path = os.path.join(folder, "meta.txt")
    if os.path.exists(path):
        with open(path) as fh:
            for line in fh:
                if "=" in line:
                    k, v = line.rstrip("\n").split("=", 1)
                    meta[k.strip()] = v.strip()
    return meta


def num(v, unit):
    if isinstance(v, Missing):
        return str(v)
    if unit == "MiB":
        return f"{v:,.0f}"
    if unit == "GFLOP/s":
        return f"{v:.1f}"
    return f"{v:,.2f}" if v < 100 else f"{v:,.1f}"


def median(values):
    values = sorted(values)
    n = len(values)
    return values[n // 2] if n % 2 else (values[n // 2 - 1] + values[n // 2]) / 2


def round_folders(folder):
    """The folders of the rounds of a `--rounds` run, in order, else [folder]."""
    rounds = []
    while os.path.isdir(os.path.join(folder, f"round{len(rounds) + 1}")):
        rounds.append(os.path.join(folder, f"round{len(rounds) + 1}"))
    return rounds or [folder]


class Round:
    """The documents one round's steps wrote."""

    def __init__(self, folder):
        self.folder = folder
        self.peer = load(folder, "spconv")
        self.conv = {b: load(folder, f"pmunet_conv_{b}") for b in BACKENDS}
        self.model1 = {b: load(folder, f"pmunet_model_{b}_b1") for b in BACKENDS}
        self.model2 = {b: load(folder, f"pmunet_model_{b}_b2") for b in BACKENDS}

    def part(self, name):
        """The peer's document where it ran part `name`, else why not."""
        if isinstance(self.peer, Missing):
            return self.peer
        return self.peer if name in self.peer.get("parts", [name]) else Missing("skipped")

    def rows(self):
        """(label, unit, kind, spconv value, {backend: pmunet value}); kind: time | mem | rate."""
        part, conv, model1, model2 = self.part, self.conv, self.model1, self.model2
        rows = [("subm k3 kernel-map build", "ms", "time", get(part("convs"), "convs", "subm_map", "median_ms"),
                 {b: get(conv[b], "map_ms") for b in BACKENDS})]
        for c in (32, 64, 128):
            for key, label, field in (("fwd", "fwd", "fwd_ms"), ("fwd_bwd", "fwd+bwd", "fwd_bwd_ms")):
                rows.append((f"subm k3 C{c} {label}", "ms", "time", get(part("convs"), "convs", "subm", str(c), key, "median_ms"),
                             {b: get(conv[b], "results", ("c_in", c), field) for b in BACKENDS}))
        # The same convs by the fastest run on each side: steadier than medians on a shared VM (other
        # load only adds time); pmunet builds before the minima were printed show n/a.
        for c in (32, 64, 128):
            for key, label, field in (("fwd", "fwd", "fwd_min_ms"), ("fwd_bwd", "fwd+bwd", "fwd_bwd_min_ms")):
                rows.append((f"subm k3 C{c} {label}, fastest run", "ms", "time", get(part("convs"), "convs", "subm", str(c), key, "min_ms"),
                             {b: get(conv[b], "results", ("c_in", c), field) for b in BACKENDS}))
        rows.append(("down k2s2 C64 fwd+bwd (map incl.)", "ms", "time",
                     get(part("convs"), "convs", "down_k2s2_c64_fwd_bwd_incl_map", "median_ms"),
                     {b: get(conv[b], "strided", ("channels", 64), "down_fwd_bwd_ms") for b in BACKENDS}))
        rows.append(("up k2 C64 fwd+bwd", "ms", "time", get(part("convs"), "convs", "up_k2_c64_fwd_bwd", "median_ms"),
                     {b: get(conv[b], "strided", ("channels", 64), "up_fwd_bwd_ms") for b in BACKENDS}))
        rows.append(("MinkUNet inference, 1 frame", "ms", "time", get(part("minkunet"), "minkunet", "infer", "infer_b1", "median_ms"),
                     {b: get(model1[b], "forward_ms") for b in BACKENDS}))
        rows.append(("MinkUNet training step, batch 2", "ms", "time",
                     get(part("minkunet"), "minkunet", "train", "train_b2", "median_ms"),
                     {b: get(model2[b], "train_step_ms") for b in BACKENDS}))
        rows.append(("peak memory (RSS) of the training step, batch 2", "MiB", "mem",
                     get(part("minkunet"), "minkunet", "train", "peak_rss_mib"),
                     {b: get(model2[b], "peak_train_mib") for b in BACKENDS}))
        # sparse-conv-bench's `sgemm` object ({size, ms, gflops}: the GEMM its kernels call) where it
        # prints one; older builds print none (n/a).
        rows.append(("SGEMM ceiling, 2048³ matmul", "GFLOP/s", "rate", get(part("gemm"), "gemm", "gflops_median"),
                     {b: get(conv[b], "sgemm", "gflops") for b in BACKENDS}))
        return rows


def combined(values):
    """The median of the values that are numbers, else the first value's reason."""
    numbers = [v for v in values if not isinstance(v, Missing)]
    return median(numbers) if numbers else values[0]


def ceiling_notes(rounds):
    """What the live target asks of pmunet's conv kernels, round by round: spconv's own rate on
    each subm conv and the target's multiple of it as a share of pmunet's SGEMM ceiling measured in
    the same round, beside pmunet's own rate as a share of that ceiling. Near 100 %, the target asks
    pmunet's sparse conv to run as fast as a large dense SGEMM on the same cores: the round's ratio
    then says how fast spconv ran more than how fast pmunet could."""

    def pct(value, ceiling):
        ok = not any(isinstance(v, Missing) or not v for v in (value, ceiling))
        return f"{100 * value / ceiling:.0f}" if ok else "n/a"

    lines = []
    for c in (32, 64, 128):
        # Both sides' GFLOP/s over their medians: 2·pairs·C² per forward, three times that per
        # forward+backward.
        for key, label, field in (("fwd", "fwd", "fwd_gflops"), ("fwd_bwd", "fwd+bwd", "fwd_bwd_gflops")):
            rates, shares, own = [], [], []
            for r in rounds:
                peer = get(r.part("convs"), "convs", "subm", str(c), key, "gflops_median")
                rates.append("n/a" if isinstance(peer, Missing) else f"{peer:.0f}")
                target = peer if isinstance(peer, Missing) else TIME_TARGET * peer
                ceilings = [get(r.conv[b], "sgemm", "gflops") for b in BACKENDS]
                shares.append(" / ".join(pct(target, ceiling) for ceiling in ceilings))
                own.append(" / ".join(pct(get(r.conv[b], "results", ("c_in", c), field), ceiling) for b, ceiling in zip(BACKENDS, ceilings)))
            if any(v != "n/a" for v in rates):
                lines.append(f"| C{c} {label} | {', '.join(rates)} | {', '.join(shares)} | {', '.join(own)} |")
    if not lines:
        return []
    head = (f"What the live {TIME_TARGET}x asks of pmunet's kernels, round by round: spconv's rate on each subm conv "
            "(2·pairs·C² per forward, three times that per forward+backward, over spconv's median) and "
            f"{TIME_TARGET}x that rate as a % of pmunet's own SGEMM ceiling in the same round (flex / ndarray). "
            "Near 100 %, a round's target asks pmunet's sparse conv to run as fast as a large dense SGEMM. "
            "The last column is pmunet's own median in the same unit.\n\n"
            f"  | conv | spconv GFLOP/s by round | {TIME_TARGET}x spconv, % of pmunet's SGEMM ceiling, by round | pmunet, % of its SGEMM ceiling, by round |\n"
            "  |---|---|---|---|\n")
    return [head + "\n".join("  " + l for l in lines)]


def main():
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    folder = sys.argv[1]
    meta = read_meta(folder)
    rounds = [Round(f) for f in round_folders(folder)]
    first = rounds[0]
    peer, conv, model1, model2, part = first.peer, first.conv, first.model1, first.model2, first.part
    threads = meta.get("threads") or str(get(peer, "threads"))
    per_round = [r.rows() for r in rounds]

    def ratio(kind, s, p):
        if isinstance(s, Missing) or isinstance(p, Missing) or not p:
            return None
        return s / p

    def met(kind, r):
        if r is None or kind == "rate":
            return "—"
        return "yes" if r >= (TIME_TARGET if kind == "time" else MEM_TARGET) else "no"

    def met_figure(label, v):
        figure = ISSUE_FIGURES.get(label)
        if figure is None or isinstance(v, Missing):
            return "—"
        return "yes" if v <= figure else "no"

    def ratio_cell(values):
        """The median ratio, with the range over the rounds when there are several."""
        values = [v for v in values if v is not None]
        if not values:
            return None, "—"
        m = median(values)
        if len(rounds) == 1:
            return m, f"{m:.2f}"
        return m, f"{m:.2f} ({min(values):.2f}–{max(values):.2f})"

    lines = []
    header = ["figure", "spconv 2.3.8", "pmunet flex", "pmunet ndarray", "spconv/flex", "spconv/ndarray",
              "live target", "met (flex / ndarray)", "fixed figure", "met (flex / ndarray)"]
    lines.append("| " + " | ".join(header) + " |")
    lines.append("|" + "---|" * len(header))
    rows = []
    for i, (label, unit, kind, _, _) in enumerate(per_round[0]):
        s = combined([r[i][3] for r in per_round])
        p = {b: combined([r[i][4][b] for r in per_round]) for b in BACKENDS}
        rows.append((label, unit, kind, s, p))
        cells_ratios = {b: ratio_cell([ratio(kind, r[i][3], r[i][4][b]) for r in per_round]) for b in BACKENDS}
        ratios = {b: cells_ratios[b][0] for b in BACKENDS}
        target = {"time": f"spconv/pmunet ≥ {TIME_TARGET}", "mem": "pmunet ≤ spconv", "rate": "—"}[kind]
        cells = [f"{label} ({unit})", num(s, unit)] + [num(p[b], unit) for b in BACKENDS]
        cells += [cells_ratios[b][1] for b in BACKENDS]
        cells += [target, " / ".join(met(kind, ratios[b]) for b in BACKENDS) if kind != "rate" else "—"]
        figure = ISSUE_FIGURES.get(label)
        cells += [f"≤ {num(figure, unit)}" if figure is not None else "—",
                  " / ".join(met_figure(label, p[b]) for b in BACKENDS) if figure is not None else "—"]
        lines.append("| " + " | ".join(cells) + " |")

    checks = [c for c in (get(r.part("crosscheck"), "crosscheck") for r in rounds) if not isinstance(c, Missing)]
    if not checks:
        cc_cell = str(get(part("crosscheck"), "crosscheck"))
        cc_threads = threads
    else:
        per = ", ".join(str(r["rows_wrong"]) for cc in checks for r in cc["repeats"])
        cc_cell = (f"{max(cc['rows_wrong_max'] for cc in checks):,} of {checks[0]['rows']:,} rows (repeats: {per}; max abs err "
                   f"{max(cc['max_abs_err'] for cc in checks):.3g})")
        cc_threads = checks[0]["threads"]
    lines.append(f"| spconv SubMConv3d C32 rows wrong (> 1e-3) at {cc_threads} threads, vs torch gather–matmul–scatter "
                 f"| {cc_cell} | n/a | n/a | — | — | 0 rows | — | — | — |")
    table = "\n".join(lines)

    # context and notes
    ctx = []
    scene = meta.get("scene") or get(peer, "scene", "path")
    ctx.append(f"Scene {scene}; {threads} threads; "
               + (f"{len(rounds)} interleaved rounds (figures: median over the rounds; ratios: median of the rounds' ratios, "
                  "with their range); " if len(rounds) > 1 else "")
               + f"convs: median of {meta.get('runs', get(peer, 'runs'))} runs after "
               f"{meta.get('warmup', get(peer, 'warmup'))} warm-ups; "
               + ("MinkUNet skipped; " if meta.get("quick") == "1" else
                  f"MinkUNet: median of {meta.get('model_runs', '?')} after {meta.get('model_warmup', '?')} warm-ups; ")
               + f"{meta.get('date', '')} on "
               f"{get(peer, 'env', 'cpu')} ({get(peer, 'env', 'nproc')} CPUs).")
    kernels = "; ".join(f"pmunet {b}: {get(conv[b], 'cpu_kernels')}" for b in BACKENDS)
    ctx.append(f"CPU flags: {meta.get('cpu_flags', '?').strip()}; instruction sets: "
               + ("capped at AVX2 + FMA on both sides (--isa avx2); " if meta.get("isa") == "avx2" else "each side's widest; ")
               + f"torch's kernels: {get(peer, 'env', 'torch_cpu_capability')}; {kernels}.")
    if meta.get("quick") == "1":
        ctx.append("QUICK RUN (--quick): few runs, MinkUNet skipped — a test of the scripts, not a measurement.")
    notes = []
    warn = []
    pv = get(peer, "scene", "voxels")
    pp = get(part("convs"), "convs", "subm_pairs")
    for b in BACKENDS:
        for name, doc in ((f"sparse-conv-bench {b}", conv[b]), (f"model-bench {b} b1", model1[b]),
                          (f"model-bench {b} b2", model2[b])):
            t = get(doc, "threads")
            if not isinstance(t, Missing) and str(t) != str(threads):
                warn.append(f"{name} ran on {t} threads, not {threads}.")
        gs = get(conv[b], "sgemm", "size")
        if not isinstance(gs, Missing) and gs != 2048:
            warn.append(f"pmunet {b}'s SGEMM ceiling is a {gs}³ product, spconv's 2048³.")
        cv, cp = get(conv[b], "voxels"), get(conv[b], "pairs")
        if not isinstance(cv, Missing) and not isinstance(pv, Missing) and cv != pv:
            warn.append(f"voxel count differs: spconv {pv}, pmunet {b} {cv}.")
        if not isinstance(cp, Missing) and not isinstance(pp, Missing) and cp != pp:
            warn.append(f"subm k3 pairs differ: spconv {pp}, pmunet {b} {cp}.")
    if not isinstance(pv, Missing):
        notes.append(f"{pv:,} voxels, subm k3 map {pp:,} pairs (spconv)" +
                     "".join(f"; pmunet {b}: {get(conv[b], 'voxels')} voxels, {get(conv[b], 'pairs')} pairs"
                             for b in BACKENDS if not isinstance(conv[b], Missing)) + ".")
    sp_params = get(part("minkunet"), "minkunet", "params")
    pm_params = {b: get(model2[b], "parameters") for b in BACKENDS}
    if not isinstance(sp_params, Missing) or any(not isinstance(v, Missing) for v in pm_params.values()):
        notes.append("MinkUNet parameters: spconv " + str(sp_params) +
                     "".join(f", pmunet {b} {pm_params[b]}" for b in BACKENDS) + ".")
    notes += [
        "Times are medians in ms, except the 'fastest run' rows (minimum of the same runs on both sides). "
        "Ratio = spconv / pmunet: above 1 pmunet is faster (or, for memory, smaller).",
        f"Live target ({TIME_TARGET}x, against spconv measured in this run): pmunet time ≤ spconv time / {TIME_TARGET} "
        f"(ratio ≥ {TIME_TARGET}); pmunet peak memory ≤ spconv's (ratio ≥ 1). Fixed figure: what pmunet must reach, "
        "1.5x spconv's medians measured in 2026-11 on a slower machine of this kind, against pmunet's median.",
        "spconv 'fwd' rows reuse a cached kernel map, as pmunet's do; 'down' builds its map inside the timed call; "
        "'up' reuses the down map. MinkUNet rebuilds every map on every call on both sides.",
        "MinkUNet: spconv's inference is a batch-1 process (eval, no grad) and its training step a batch-2 process "
        "(loss = mean of squared head outputs, Adam); pmunet's inference figure is model-bench --batch 1 "
        "--only infer forward_ms, its training step and peak are model-bench --batch 2 --only train train_step_ms / peak_train_mib "
        "(pmunet's loss is the detector loss on a frame without boxes). Peak RSS is each process's own "
        "(spconv: ru_maxrss of the training subprocess, which includes ~0.47 GiB from importing torch and building the model, rss_before_mib in spconv.json; "
        "pmunet: VmHWM of the batch-2 training process, which runs nothing else).",
        "SGEMM (higher is better, no target): spconv's cell is torch.matmul (MKL) of 2048³ at the same "
        "thread count; pmunet's is sparse-conv-bench's `sgemm.gflops` (the GEMM its kernels call), n/a where "
        "the build prints none.",
        "spconv 2.3.8's CPU SubMConv3d races at > 1 thread: the last row counts wrong output rows in 3 repeats per run "
        "(it varies from call to call and can be 0), so spconv's multi-thread conv timings come from an "
        "implementation that can return wrong rows.",
    ]
    # What 1.5x spconv's training step would ask of pmunet's convolutions: the step's conv work
    # (model-bench's conv_gflop) in the time left after everything that is not a conv kernel.
    # (With rounds, every figure is its median over the rounds.)
    sp_step = combined([get(r.part("minkunet"), "minkunet", "train", "train_b2", "median_ms") for r in rounds])
    # The best SGEMM any side measured in this run: the VM's noise lowers single readings, and
    # a 2048³ SGEMM at this thread count is as close to the cores' peak as software gets.
    measured = [v for r in rounds
                for v in [get(r.part("gemm"), "gemm", "gflops_median")] + [get(r.conv[b], "sgemm", "gflops") for b in BACKENDS]
                if not isinstance(v, Missing)]
    best = max(measured) if measured else None
    for b in BACKENDS:
        k, step = get(model2[b], "train_kernels"), combined([get(r.model2[b], "train_step_ms") for r in rounds])
        ceiling = combined([get(r.conv[b], "sgemm", "gflops") for r in rounds])
        if any(isinstance(v, Missing) for v in (k, step, ceiling, sp_step)) or not k.get("conv_gflop"):
            continue
        conv_ms = combined([sum(get(r.model2[b], "train_kernels", key) for key in ("conv_forward_ms", "conv_input_grad_ms", "conv_weight_grad_ms"))
                            for r in rounds if not isinstance(get(r.model2[b], "train_kernels"), Missing)])
        # The rest of the step against the mean step of the same runs the kernel times are
        # means of (older model-bench JSON has only the median).
        mean_step = combined([get(r.model2[b], "train_step_mean_ms") for r in rounds])
        whole = step if isinstance(mean_step, Missing) else mean_step
        other_ms, target_ms = whole - conv_ms, sp_step / TIME_TARGET
        line = (f"pmunet {b}'s training step: {k['conv_gflop']:.0f} GFLOP of convolution in {conv_ms:,.0f} ms "
                f"({k['conv_gflop'] / conv_ms * 1e3:.0f} GFLOP/s, {100 * k['conv_gflop'] / conv_ms * 1e3 / ceiling:.0f} % of its "
                f"SGEMM ceiling) and {other_ms:,.0f} ms of everything else; {TIME_TARGET}x spconv's step is {target_ms:,.0f} ms, ")
        if target_ms > other_ms:
            need = k["conv_gflop"] / (target_ms - other_ms) * 1e3
            line += f"which would need the convolutions at {need:.0f} GFLOP/s, {100 * need / ceiling:.0f} % of that ceiling"
            line += f" ({100 * need / best:.0f} % of the best SGEMM of this run, {best:.0f} GFLOP/s)." if best else "."
        else:
            line += "less than the non-convolution time alone."
        notes.append(line)
    notes += ceiling_notes(rounds)
    for key in ("load_before",):  # load after includes this run itself
        try:
            load1 = float(meta.get(key, "").split()[0])
        except (ValueError, IndexError):
            continue
        if load1 > 0.5:
            warn.append(f"the machine was busy ({key.replace('_', ' ')} the run: load average {load1:.2f}): "
                        "other processes skew these figures, spconv's OpenMP threads far more than pmunet's rayon "
                        "pool (2-thread spconv convs were seen 30-100x slower beside one busy process).")
    for r in rounds:
        where = os.path.relpath(r.folder, folder)
        where = "" if where == "." else where + "/"
        for name in sorted(os.listdir(r.folder)):
            if name.endswith(".log") and name.startswith("pmunet_"):
                with open(os.path.join(r.folder, name), errors="replace") as fh:
                    if any(l.lstrip().startswith("Compiling ") for l in fh):
                        warn.append(f"cargo compiled something before {where}{name[:-4]} ran (see {where}{name}).")
        for name, doc in [("spconv", r.peer)] + [(f"pmunet_conv_{b}", r.conv[b]) for b in BACKENDS] + \
                [(f"pmunet_model_{b}_b{k}", d[b]) for b in BACKENDS for k, d in ((1, r.model1), (2, r.model2))]:
            if isinstance(doc, Missing) and doc.why == "failed":
                warn.append(f"{where}{name} failed: see {where}{name}.log.")
        if not isinstance(r.peer, Missing):
            for sub in ("infer", "train"):
                err = get(r.part("minkunet"), "minkunet", sub, "error")
                if not isinstance(err, Missing):
                    warn.append(f"{where}spconv MinkUNet {sub} subprocess failed ({err}).")

    text = "\n".join(ctx) + "\n\n" + table + "\n\n" + "\n".join(f"* {n}" for n in notes)
    if warn:
        text += "\n\n" + "\n".join(f"**Warning:** {w}" for w in warn)
    text += "\n"
    with open(os.path.join(folder, "table.md"), "w") as fh:
        fh.write(text)
    print(text, end="")


if __name__ == "__main__":
    main()
