"""Throughput of trbc.Surrogate from Python: rows per second of evaluate() (and gradient()) on
10^6 rows drawn uniformly from the training box, on one OpenMP thread (one core), best of
--repeat runs, per wall second and per CPU second of the process (the same on an idle machine;
on a shared one the CPU rate is the per-core throughput). Usage: .venv/bin/python bench/python_surrogate.py [--rows 1000000] [--repeat 5]
[--precision double|single] [--threads 1]."""
import argparse
import time

import numpy as np

import trbc


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--precision", choices=["double", "single"], nargs="*", default=["double", "single"])
    a = ap.parse_args()
    lo = np.array([0.65, 1.0, 10.0, 0.0, 0.1, 0.0])
    hi = np.array([1.0, 10.0, 1000.0, 4.0, 1.0, 200.0])
    x = lo + (hi - lo) * np.random.default_rng(1).uniform(size=(a.rows, 6))
    print(f"trbc {trbc.__version__}: Surrogate on {a.rows} rows, {a.threads} thread(s), best of {a.repeat}")
    for precision in a.precision:
        s = trbc.Surrogate(precision=precision)
        for what, call in [("evaluate", lambda: s.evaluate(x, threads=a.threads)),
                           ("evaluate_array", lambda: s.evaluate_array(x, threads=a.threads))]:
            times = [_timed(call) for _ in range(a.repeat)]
            wall, cpu = min(t[0] for t in times), min(t[1] for t in times)
            print(f"  {what:<15} {precision:<6} {a.rows / wall / 1e6:7.3f} M rows/s wall, {a.rows / cpu / 1e6:7.3f} M rows/s CPU")
    s = trbc.Surrogate()
    n = min(a.rows, 200_000)
    w = np.ones((n, 6))
    times = [_timed(lambda: s.gradient(x[:n], weights=w, threads=a.threads)) for _ in range(a.repeat)]
    wall, cpu = min(t[0] for t in times), min(t[1] for t in times)
    print(f"  {'gradient (VJP)':<15} double {n / wall / 1e6:7.3f} M rows/s wall, {n / cpu / 1e6:7.3f} M rows/s CPU ({n} rows)")


def _timed(call):
    t0, c0 = time.perf_counter(), time.process_time()
    call()
    return time.perf_counter() - t0, time.process_time() - c0


if __name__ == "__main__":
    main()
