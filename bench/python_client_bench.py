"""Throughput of swarf_client against a swarfd it starts (memory-only, on a
free loopback port): the workload of swarf_stream_bench (a 1 mm ball, a
zig-zag raster of 0.1 mm moves over a 1000 x 1000 grid, taylor), then the
reads a frontend makes. Prints one line per figure (median of --runs).

usage: bench/python_client_bench.py SWARFD [--moves N] [--runs N]   (swarf_client importable)
"""

import argparse
import socket
import statistics
import subprocess
import time

import numpy as np

import swarf_client


def raster(moves: int) -> np.ndarray:
    """bench/stream_bench.cc's Raster: rows of 0.1 mm steps over [5, 95]."""
    per_row = 900
    rows = -(-moves // per_row)
    k = np.arange(per_row) * 0.1
    out = []
    for r in range(rows):
        y = 5 + r * (90.0 / rows)
        x = 5 + k if r % 2 == 0 else 95 - k
        out.append(np.column_stack(
            [x, np.full(per_row, y), -1 + 0.3 * np.sin(x * 0.2 + y * 0.1)]))
    return np.concatenate(out)[:moves + 1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("swarfd")
    ap.add_argument("--moves", type=int, default=1_000_000)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        target = f"127.0.0.1:{s.getsockname()[1]}"
    server = subprocess.Popen([args.swarfd, f"--listen={target}",
                               "--data_dir="], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    try:
        path = raster(args.moves)
        xy = np.random.default_rng(1).uniform(5, 95, (1_000_000, 2))
        times = {"send": [], "heights": [], "probe": []}
        with swarf_client.Client(target) as client:
            if not client.health(timeout=30):
                raise SystemExit("swarfd did not start")
            for _ in range(args.runs):
                with client.create_session((0, 0, 100, 100, 0), nx=1000,
                                           ny=1000, tools={1: 0.5},
                                           delete_on_exit=True) as s:
                    t0 = time.perf_counter()
                    s.send(path)
                    t1 = time.perf_counter()
                    h = s.heights()
                    t2 = time.perf_counter()
                    s.probe(xy)
                    t3 = time.perf_counter()
                    assert h.z.shape == (1001, 1001)
                times["send"].append(t1 - t0)
                times["heights"].append(t2 - t1)
                times["probe"].append(t3 - t2)
        med = {k: statistics.median(v) for k, v in times.items()}
        print(f"send {len(path) - 1} moves: {med['send']:.2f} s, "
              f"{(len(path) - 1) / med['send'] / 1e6:.2f}M moves/s")
        print(f"heights of 1001 x 1001 nodes (float64): {med['heights']:.2f} s")
        print(f"probe 1M points: {med['probe']:.2f} s")
    finally:
        server.terminate()
        server.wait()


if __name__ == "__main__":
    main()
