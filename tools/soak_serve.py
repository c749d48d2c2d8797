#!/usr/bin/env python3
"""Soak test of `train serve`: many concurrent clients, valid clouds of several sizes mixed with
every hostile input (sizes claiming billions of points, far points, an LZF bomb, …), truncated
bodies and slow or stalled senders, for a fixed time and at least a fixed number of requests. Reports requests by kind and status, the latency of the
valid ones, and the service's resident memory at start, peak and end.

It starts the service itself (so it can read its memory from /proc) unless --addr is given:

    python3 tools/soak_serve.py --minutes 10 --min-requests 20000 --out docs/results/soak/<date>

Standard library only. Exit status 1 if a valid request got a 5xx, the service died, or its
memory grew more than --max-growth between the end of warm-up and the end.
"""

import argparse
import json
import math
import os
import random
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections import Counter, defaultdict

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


# ---------------------------------------------------------------- clouds

def scene(n, seed):
    """n points of a plausible scan in JRDB's base frame: floor rings, walls and a few people."""
    rng = random.Random(seed)
    pts = []
    people = [(rng.uniform(2, 15) * math.cos(a), rng.uniform(2, 15) * math.sin(a)) for a in [rng.uniform(0, 6.283) for _ in range(12)]]
    while len(pts) < n:
        r = rng.random()
        if r < 0.5:
            d, a = rng.uniform(1.5, 25), rng.uniform(0, 6.283)
            pts.append((d * math.cos(a), d * math.sin(a), -0.7 + rng.gauss(0, 0.01)))
        elif r < 0.8:
            a = rng.uniform(0, 6.283)
            pts.append((20 * math.cos(a), 20 * math.sin(a), rng.uniform(-0.7, 2.5)))
        else:
            cx, cy = people[rng.randrange(len(people))]
            a = rng.uniform(0, 6.283)
            pts.append((cx + 0.22 * math.cos(a), cy + 0.18 * math.sin(a), rng.uniform(-0.7, 1.0)))
    return pts


def pcd_header(fields, sizes, types, counts, n, data, width=None, height=1):
    width = n if width is None else width
    return (f"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {sizes}\nTYPE {types}\n"
            f"COUNT {counts}\nWIDTH {width}\nHEIGHT {height}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n").encode()


def pcd_ascii(pts):
    body = "".join(f"{x:.4f} {y:.4f} {z:.4f} 1\n" for x, y, z in pts).encode()
    return pcd_header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", len(pts), "ascii") + body


def pcd_binary(pts):
    body = b"".join(struct.pack("<4f", x, y, z, 1.0) for x, y, z in pts)
    return pcd_header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", len(pts), "binary") + body


def pcd_binary_compressed(pts):
    """Columns, then an LZF block of literal runs only (valid liblzf input)."""
    raw = b"".join(struct.pack(f"<{len(pts)}f", *[p[k] for p in pts]) for k in range(3))
    block = b"".join(bytes([len(raw[i:i + 32]) - 1]) + raw[i:i + 32] for i in range(0, len(raw), 32))
    return pcd_header("x y z", "4 4 4", "F F F", "1 1 1", len(pts), "binary_compressed") + struct.pack("<II", len(block), len(raw)) + block


def kitti_bin(pts):
    return b"".join(struct.pack("<4f", x, y, z, 0.5) for x, y, z in pts)


def npy(pts, shape=None):
    shape = shape or f"({len(pts)}, 4)"
    header = f"{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}"
    header += " " * ((64 - (10 + len(header) + 1) % 64) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode() + b"".join(struct.pack("<4f", x, y, z, 1.0) for x, y, z in pts)


def hostile(max_body, max_points):
    """(name, query, body, expected statuses) of every hostile input, and the bodies of valid clouds."""
    small = scene(2000, 1)
    claim = lambda data: (pcd_header("x y z intensity", "4 4 4 4", "F F F F", "1 1 1 1", 4000000000, data) + b"1" * 271)[:271]
    lzf_bomb = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 100000000, "binary_compressed") + struct.pack("<II", 16, 1200000000) + bytes(16)
    count = pcd_header("x y z pad", "4 4 4 8", "F F F F", "1 1 1 2000000000", 1, "binary") + bytes(64)
    wh = pcd_header("x y z", "4 4 4", "F F F", "1 1 1", 1, "binary", width=4294967296, height=4294967296)
    far = small + [(1e6, 1e6, 1e6), (-1e6, -1e6, -1e6)]
    nan = float("nan")
    huge = [(nan, 0, 0), (float("inf"), 1, 1), (1e38, 1e38, 1e38), (-1e38, -1e38, -1e38)]
    return [
        ("pcd_claims_4e9_binary", "", claim("binary"), {413}),
        ("pcd_claims_4e9_ascii", "", claim("ascii"), {413}),
        ("npy_shape_1e12", "", npy([], "(1000000000000, 3)"), {400}),
        ("far_points_bin", "?format=bin", kitti_bin(far), {200}),
        ("huge_after_nan_bin", "?format=bin", kitti_bin(huge), {200}),
        ("lzf_bomb", "", lzf_bomb, {400, 413}),
        ("count_2e9", "", count, {400, 413}),
        ("width_x_height_overflow", "", wh, {400}),
        ("truncated_header", "", b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4", {400}),
        ("odd_sized_bin", "?format=bin", bytes(17), {400}),
        ("empty_body", "", b"", {400}),
        ("unknown_query", "?frmat=bin", kitti_bin(small), {400}),
        ("bad_threshold", "?format=bin&score_threshold=nan", kitti_bin(small), {400}),
        ("garbage_no_format", "", bytes(random.Random(3).randrange(256) for _ in range(4096)), {415}),
        ("over_max_points", "?format=bin", kitti_bin(scene(max_points + 1, 5)), {413}),
        # Announced over the limit: refused from its Content-Length before the body is read.
        ("over_max_body", "?format=bin", bytes(1024), {413}, max_body + 16),
    ]


# ---------------------------------------------------------------- HTTP

def send(addr, query, body, *, announce=None, chunks=1, pause=0.0, stall=False, close_early=False, timeout=180):
    """One request on its own connection; returns (status or an error word, seconds)."""
    host, port = addr.rsplit(":", 1)
    t0 = time.monotonic()
    try:
        s = socket.create_connection((host, int(port)), timeout=timeout)
    except OSError:
        return "connect-error", time.monotonic() - t0
    try:
        n = len(body) if announce is None else announce
        s.sendall(f"POST /detect{query} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: {n}\r\n\r\n".encode())
        try:
            step = max(1, math.ceil(len(body) / chunks))
            for i in range(0, len(body), step):
                s.sendall(body[i:i + step])
                if pause:
                    time.sleep(pause)
            if close_early:
                s.shutdown(socket.SHUT_WR)
        except OSError:
            pass  # the service may answer (413) and close before the body is sent
        raw = b""
        while b"\r\n\r\n" not in raw:
            try:
                chunk = s.recv(65536)
            except OSError:
                break
            if not chunk:
                break
            raw += chunk
        if not raw:
            return "no-answer", time.monotonic() - t0
        status = int(raw.split(b" ", 2)[1])
        head, _, rest = raw.partition(b"\r\n\r\n")
        length = next((int(l.split(b":")[1]) for l in head.split(b"\r\n") if l.lower().startswith(b"content-length:")), None)
        while length is not None and len(rest) < length:
            chunk = s.recv(65536)
            if not chunk:
                break
            rest += chunk
        return status, time.monotonic() - t0
    except (OSError, ValueError, IndexError):
        return "io-error", time.monotonic() - t0
    finally:
        s.close()


def health(addr):
    host, port = addr.rsplit(":", 1)
    try:
        with socket.create_connection((host, int(port)), timeout=10) as s:
            s.sendall(f"GET /health HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n".encode())
            raw = s.recv(4096)
            return int(raw.split(b" ", 2)[1])
    except (OSError, ValueError, IndexError):
        return None


def rss_kib(pid):
    try:
        with open(f"/proc/{pid}/status") as f:
            return int(next(l for l in f if l.startswith("VmRSS:")).split()[1])
    except (OSError, StopIteration):
        return None


# ---------------------------------------------------------------- the soak

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--min-requests", type=int, default=20000)
    ap.add_argument("--clients", type=int, default=8)
    ap.add_argument("--addr", help="a running service (its memory is then read from --pid, if given)")
    ap.add_argument("--pid", type=int)
    ap.add_argument("--binary", default=os.path.join(ROOT, "target/debug/train"))
    ap.add_argument("--max-body-mb", type=float, default=16)
    ap.add_argument("--max-points", type=int, default=500000)
    ap.add_argument("--read-timeout-s", type=float, default=3)
    ap.add_argument("--warmup-s", type=float, default=60, help="memory growth is measured from the end of this")
    ap.add_argument("--max-growth", type=float, default=0.10)
    ap.add_argument("--valid-share", type=float, default=0.12, help="share of requests that are valid clouds")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", help="folder for soak.json and soak.csv")
    ap.add_argument("--write-hostile", metavar="DIR", help="only write the hostile bodies as files into DIR (for `train detect`) and exit")
    args = ap.parse_args()

    max_body = int(args.max_body_mb * 1024 * 1024)
    if args.write_hostile:
        os.makedirs(args.write_hostile, exist_ok=True)
        for name, query, body, _, *announce in hostile(max_body, args.max_points):
            if announce or not body or name in ("unknown_query", "bad_threshold", "over_max_points"):
                continue  # hostile as a request (its size, its query, the service's limit), not as a file
            ext = "bin" if "format=bin" in query else "npy" if body.startswith(b"\x93NUMPY") else "pcd"
            with open(os.path.join(args.write_hostile, f"{name}.{ext}"), "wb") as f:
                f.write(body)
        print("\n".join(sorted(os.listdir(args.write_hostile))))
        return
    server = None
    if args.addr:
        addr, pid = args.addr, args.pid
    else:
        cmd = [args.binary, "serve", "--addr", "127.0.0.1:0", "--max-body-mb", str(args.max_body_mb), "--max-points", str(args.max_points),
               "--read-timeout-s", str(args.read_timeout_s), "--timeout-s", "120"]
        server = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        line = server.stdout.readline()
        if not line.startswith("listening on http://"):
            sys.exit(f"the service did not start: {line!r}")
        addr, pid = line.strip().removeprefix("listening on http://"), server.pid
    print(f"soaking http://{addr} (pid {pid}) with {args.clients} clients for {args.minutes} min and >= {args.min_requests} requests", flush=True)

    sizes = {"valid_1k_pcd_ascii": (1000, pcd_ascii, ""), "valid_10k_bin": (10000, kitti_bin, "?format=bin"),
             "valid_30k_pcd_binary_compressed": (30000, pcd_binary_compressed, ""), "valid_60k_npy": (60000, npy, ""),
             "valid_300k_pcd_binary": (300000, pcd_binary, "")}
    valid = [(name, q, enc(scene(n, i + 10)), {200}) for i, (name, (n, enc, q)) in enumerate(sizes.items())]
    # Smaller clouds more often, as a robot's stream of crops and single scans would send them.
    valid_weights = [8, 6, 3, 2, 1]
    hostiles = hostile(max_body, args.max_points)
    slow_body = kitti_bin(scene(10000, 99))
    print(f"valid bodies: {', '.join(f'{n} {len(b) / 1e6:.1f} MB' for n, _, b, _ in valid)}", flush=True)

    results = defaultdict(Counter)
    latencies = defaultdict(list)
    unexpected = Counter()
    lock = threading.Lock()
    stop = threading.Event()
    count = [0]
    start = time.monotonic()
    end_at = start + args.minutes * 60

    def client(k):
        rng = random.Random(args.seed * 1000 + k)
        while not stop.is_set():
            r = rng.random()
            if r < args.valid_share:
                name, q, body, want = rng.choices(valid, weights=valid_weights)[0]
                status, secs = send(addr, q, body)
            elif r < args.valid_share + 0.01:
                name, want = "slow_sender_valid_10k", {200}
                status, secs = send(addr, "?format=bin", slow_body, chunks=8, pause=0.1)
            elif r < args.valid_share + 0.013:
                name, want = "stalled_sender", {408}
                status, secs = send(addr, "?format=bin", slow_body[:4096], announce=len(slow_body), stall=True)
            elif r < args.valid_share + 0.05:
                name, want = "truncated_body_closed", {400, "no-answer", "io-error"}
                status, secs = send(addr, "?format=bin", slow_body[: len(slow_body) // 2], announce=len(slow_body), close_early=True)
            else:
                name, q, body, want, *announce = rng.choice(hostiles)
                status, secs = send(addr, q, body, announce=announce[0] if announce else None)
            with lock:
                results[name][status] += 1
                count[0] += 1
                if name.startswith("valid") or name.startswith("slow"):
                    latencies[name].append(secs)
                if status not in want:
                    unexpected[(name, status)] += 1
            if time.monotonic() >= end_at and count[0] >= args.min_requests:
                stop.set()

    rss = []
    def monitor():
        while not stop.is_set():
            rss.append((time.monotonic() - start, rss_kib(pid) if pid else None, health(addr)))
            time.sleep(1.0)

    threads = [threading.Thread(target=client, args=(k,), daemon=True) for k in range(args.clients)]
    mon = threading.Thread(target=monitor, daemon=True)
    rss.append((0.0, rss_kib(pid) if pid else None, health(addr)))
    mon.start()
    for t in threads:
        t.start()
    last = 0
    while not stop.wait(30):
        with lock:
            n = count[0]
        print(f"{time.monotonic() - start:6.0f} s  {n} requests ({(n - last) / 30:.1f}/s)  rss {rss[-1][1]} KiB  health {rss[-1][2]}", flush=True)
        last = n
    for t in threads:
        t.join(timeout=200)
    elapsed = time.monotonic() - start
    final_health = health(addr)
    rss.append((elapsed, rss_kib(pid) if pid else None, final_health))
    alive = server is None or server.poll() is None
    if server is not None:
        server.send_signal(signal.SIGTERM)
        try:
            code = server.wait(timeout=60)
        except subprocess.TimeoutExpired:
            server.kill()
            code = "killed after 60 s"
    else:
        code = None

    def pct(xs, q):
        xs = sorted(xs)
        return xs[min(len(xs) - 1, int(q * len(xs)))] if xs else None

    mem = [m for _, m, _ in rss if m]
    after_warmup = [m for t, m, _ in rss if m and t >= args.warmup_s]
    growth = (mem[-1] - after_warmup[0]) / after_warmup[0] if after_warmup and mem else None
    five_xx_valid = sum(c for name, ctr in results.items() if name.startswith(("valid", "slow")) for st, c in ctr.items() if isinstance(st, int) and st >= 500)
    health_fail = sum(1 for _, _, h in rss if h != 200)
    report = {
        "addr": addr, "clients": args.clients, "seconds": round(elapsed, 1), "requests": count[0],
        "requests_per_s": round(count[0] / elapsed, 2),
        "by_kind": {k: {str(s): c for s, c in sorted(v.items(), key=str)} for k, v in sorted(results.items())},
        "unexpected": {f"{k} -> {s}": c for (k, s), c in unexpected.items()},
        "latency_s": {k: {"n": len(v), "p50": round(pct(v, 0.5), 4), "p99": round(pct(v, 0.99), 4)} for k, v in sorted(latencies.items())},
        "latency_all_valid_s": {"p50": pct(sum((v for k, v in latencies.items() if k.startswith("valid")), []), 0.5),
                                "p99": pct(sum((v for k, v in latencies.items() if k.startswith("valid")), []), 0.99)},
        "rss_kib": {"start": mem[0] if mem else None, "after_warmup": after_warmup[0] if after_warmup else None,
                    "peak": max(mem) if mem else None, "end": mem[-1] if mem else None},
        "rss_growth_after_warmup": growth, "health_checks": len(rss), "health_failures": health_fail,
        "five_xx_on_valid": five_xx_valid, "service_alive_at_end": alive, "exit_code_after_sigterm": code,
        "settings": {"max_body_mb": args.max_body_mb, "max_points": args.max_points, "read_timeout_s": args.read_timeout_s,
                     "valid_share": args.valid_share, "seed": args.seed, "minutes": args.minutes},
    }
    ok = five_xx_valid == 0 and alive and health_fail == 0 and (growth is None or growth <= args.max_growth) and (code in (0, None))
    report["passed"] = ok
    text = json.dumps(report, indent=1, default=str)
    print(text)
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "soak.json"), "w") as f:
            f.write(text + "\n")
        with open(os.path.join(args.out, "soak.csv"), "w") as f:
            f.write("seconds,rss_kib,health\n" + "".join(f"{t:.1f},{m},{h}\n" for t, m, h in rss))
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
