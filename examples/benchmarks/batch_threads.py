"""Batched steps in parallel: a batch of N gymnasium-humanoid (or pendulum) flat steps in one
call, timed with 1 thread and with every core (`ukemi.set_num_threads`). Printed, not asserted.

    .venv/bin/python examples/benchmarks/batch_threads.py [--batch 64] [--model humanoid]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

import ukemi
from ukemi import _ukemi


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--model", default="humanoid")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = ukemi.Model.from_xml_path(ukemi.gymnasium_asset_path(args.model))
    s = m.make_state()
    for _ in range(20):  # settle so the batch is in contact, a realistic load
        s, _ = ukemi.step(m, s, np.zeros(m.nu), on_failure="return")
    rng = np.random.default_rng(0)
    x = np.concatenate([s.qpos, s.qvel])
    xs = np.tile(x, (args.batch, 1))
    xs[:, m.nq:] += 0.05 * rng.normal(size=(args.batch, m.nv))
    us = 0.1 * rng.normal(size=(args.batch, m.nu))
    cores = os.cpu_count() or 1
    times = {}
    for n in (1, cores):
        ukemi.set_num_threads(n)
        best = np.inf
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            try:
                _ukemi._flat_step(m, xs, us, None)
            except ukemi.ConvergenceError as e:
                print("note:", str(e)[:100])
            best = min(best, time.perf_counter() - t0)
        times[n] = best
        print(f"{args.model}: batch {args.batch}, {n} thread(s): {best * 1e3:8.1f} ms "
              f"({best / args.batch * 1e3:.2f} ms per step)")
    ukemi.set_num_threads(0)
    print(f"speed-up {cores} threads vs 1: {times[1] / times[cores]:.2f}x (target >= 1.8x on 2 cores)")


if __name__ == "__main__":
    main()
