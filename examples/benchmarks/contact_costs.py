"""What each effect costs, and what warm starting buys.

1. Effect ladder: the same mechanism (a 4-link pendulum chain of capsules swinging over a floor)
   with effects switched on one by one: no contact -> impact only -> nonlinear friction cone ->
   pyramid -> joint limits -> tendon limits (and tendon limits alone, without contact). Prints the step's variable counts, Newton iterations and time.
2. Warm start: iterations and time per step with and without warm start for the contact scenes
   of the test suite (drops, sliding box, 5-box stack).

Run: .venv/bin/python examples/benchmarks/contact_costs.py [--steps 500]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import ukemi


def chain(contact: str | None, limits: bool, tendons: bool = False):
    b = ukemi.ModelBuilder(timestep=0.01)
    if contact is not None:
        b.add_geom("floor", "world", "plane", pos=(0, 0, -3.6), friction=0.8, contact=contact)
    for i in range(4):
        b.add_body(f"l{i}", 1.0, (0.09, 0.09, 0.005), pos=(0, 0, -0.5 - i))
        b.add_joint(f"j{i}", "revolute", "world" if i == 0 else f"l{i - 1}", f"l{i}",
                    axis=(0, 1, 0), parent_anchor=(0, 0, 0) if i == 0 else (0, 0, -0.5),
                    child_anchor=(0, 0, 0.5), range=(-1.0, 1.0) if limits else None)
        if contact is not None:
            b.add_geom(f"c{i}", f"l{i}", "capsule", size=(0.05, 0.45), friction=0.8,
                       contact=contact)
    if tendons:
        # hamstring-like couplings of neighbouring hinges: |½ q_i - ½ q_i+1| <= 0.3
        for i in (0, 2):
            b.add_tendon_limit(f"t{i}", terms=[(f"j{i}", 0.5), (f"j{i + 1}", -0.5)],
                               range=(-0.3, 0.3))
    return b.compile()


def timed(model, state, steps):
    ukemi.rollout(model, state, nsteps=3, on_failure="return")
    t0 = time.perf_counter()
    tr = ukemi.rollout(model, state, nsteps=steps, on_failure="return")
    dt = (time.perf_counter() - t0) / steps
    return dt, tr


def ladder(steps: int) -> None:
    print("effect ladder (4-link chain, h = 0.01 s, swinging into a floor)")
    print(f"{'effects':<28} {'variables':>9} {'it/step':>8} {'µs/step':>9} {'failed':>7}")
    rungs = [("no contact", None, False, False), ("+ impact", "impact", False, False),
             ("+ friction cone", "nonlinear", False, False),
             ("pyramid instead", "linear", False, False),
             ("+ joint limits", "nonlinear", True, False),
             ("+ tendon limits", "nonlinear", True, True),
             ("tendon limits, no contact", None, False, True)]
    for name, contact, limits, tendons in rungs:
        m = chain(contact, limits, tendons)
        s = m.make_state(qpos=[1.2, 0.3, -0.2, 0.1])
        dt, tr = timed(m, s, steps)
        nvar = sum(c for _, c in m.variable_counts)
        print(f"{name:<28} {nvar:9d} {tr.iterations.mean():8.2f} {dt * 1e6:9.1f} "
              f"{int(np.sum(tr.status != 'converged')):7d}")


def scene(kind: str):
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("floor", "world", "plane", friction=0.5)
    n = 5 if kind == "stack" else 1
    for i in range(n):
        z = 0.1 + 0.2 * i + 1e-4 * i if kind == "stack" else (0.6 if kind != "slide" else 0.1)
        b.add_body(f"b{i}", 1.0, (1 / 150,) * 3, pos=(0, 0, z))
        b.add_joint(f"f{i}", "free", "world", f"b{i}")
        shape, size = ("sphere", (0.1,)) if kind == "sphere drop" else ("box", (0.1, 0.1, 0.1))
        b.add_geom(f"g{i}", f"b{i}", shape, size=size, friction=0.5)
    m = b.compile()
    qvel = None
    if kind == "slide":
        qvel = [np.cos(np.pi / 6), np.sin(np.pi / 6), 0, 0, 0, 0]
    return m, m.make_state(qvel=qvel)


def warm_start(steps: int) -> None:
    print("\nwarm start (h = 0.01 s)")
    print(f"{'scene':<14} {'warm it/step':>13} {'µs/step':>9} {'cold it/step':>13} {'µs/step':>9}")
    for kind in ("sphere drop", "box drop", "slide", "stack"):
        m, s = scene(kind)
        row = []
        for warm in (True, False):
            mm = m.with_options(warm_start=warm)
            dt, tr = timed(mm, mm.make_state(qpos=s.qpos, qvel=s.qvel), steps)
            row += [tr.iterations.mean(), dt * 1e6]
        print(f"{kind:<14} {row[0]:13.2f} {row[1]:9.1f} {row[2]:13.2f} {row[3]:9.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=300)
    args = ap.parse_args()
    ladder(args.steps)
    warm_start(args.steps)


if __name__ == "__main__":
    main()
