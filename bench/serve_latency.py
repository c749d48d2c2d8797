#!/usr/bin/env python3
"""Latency of `train serve` for one cloud under 1, 4 and 16 concurrent clients.

    cargo run -p train -- serve --addr 127.0.0.1:8080 &
    python3 bench/serve_latency.py FRAME.pcd --url http://127.0.0.1:8080 --clients 1,4,16 --requests 64

Each client posts the same file in a loop on its own connection per request; per concurrency
level it prints the median and 99th-percentile latency (ms), throughput (frames/s) and the
status codes seen. Only Python's standard library.
"""

import argparse
import statistics
import threading
import time
import urllib.request


def post(url, body):
    req = urllib.request.Request(url + "/detect", data=body, method="POST")
    t = time.perf_counter()
    with urllib.request.urlopen(req, timeout=600) as r:
        r.read()
        status = r.status
    return (time.perf_counter() - t) * 1e3, status


def level(url, body, clients, requests):
    lat, codes, lock = [], {}, threading.Lock()
    per_client = max(1, requests // clients)

    def client():
        for _ in range(per_client):
            ms, code = post(url, body)
            with lock:
                lat.append(ms)
                codes[code] = codes.get(code, 0) + 1

    threads = [threading.Thread(target=client) for _ in range(clients)]
    start = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    wall = time.perf_counter() - start
    lat.sort()
    p99 = lat[min(len(lat) - 1, int(round(0.99 * (len(lat) - 1))))]
    return statistics.median(lat), p99, len(lat) / wall, len(lat), codes


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file", help="a point-cloud file (PCD, .npy; a .bin needs the server's ?format)")
    ap.add_argument("--url", default="http://127.0.0.1:8080")
    ap.add_argument("--clients", default="1,4,16")
    ap.add_argument("--requests", type=int, default=64, help="requests per level (split over the clients)")
    ap.add_argument("--warmup", type=int, default=3)
    a = ap.parse_args()
    body = open(a.file, "rb").read()
    for _ in range(a.warmup):
        post(a.url, body)
    print(f"{a.file}: {len(body)} bytes")
    print("| clients | requests | median ms | p99 ms | frames/s | statuses |")
    print("|---|---|---|---|---|---|")
    for c in [int(x) for x in a.clients.split(",")]:
        med, p99, fps, n, codes = level(a.url, body, c, a.requests)
        print(f"| {c} | {n} | {med:.0f} | {p99:.0f} | {fps:.2f} | {codes} |")


if __name__ == "__main__":
    main()
