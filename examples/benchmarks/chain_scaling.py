"""Per-step time of an N-link chain (N = 10 … 1000) in ukemi and in MuJoCo, same run.

The chain floats in zero gravity, bent slightly and moving (joint rates ±0.05 rad/s), time step
0.01 s; both engines get the same geometry and inertias (MuJoCo's model built with mjSpec). Prints time per
step, ukemi's Newton iterations, the ratio ukemi/MuJoCo and the fitted exponent of time vs N.

Run: .venv/bin/python examples/benchmarks/chain_scaling.py [--steps 200]
(MuJoCo is optional: `pip install mujoco`.)
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import ukemi

SIZES = (10, 30, 100, 300, 1000)


def ukemi_chain(n: int):
    b = ukemi.ModelBuilder(timestep=0.01, gravity=(0, 0, 0))
    for i in range(n):
        b.add_body(f"l{i}", 1.0, (1 / 12, 1 / 12, 1e-3), pos=(0, 0, -i - 0.5))
        b.add_joint(f"j{i}", "revolute", "world" if i == 0 else f"l{i - 1}", f"l{i}",
                    axis=(0, 1, 0), parent_anchor=(0, 0, 0) if i == 0 else (0, 0, -0.5),
                    child_anchor=(0, 0, 0.5))
    return b.compile()


def mujoco_chain(n: int):
    """The same chain built with MuJoCo's mjSpec (XML nesting is capped below 1000 levels)."""
    import mujoco

    spec = mujoco.MjSpec()
    spec.option.timestep = 0.01
    spec.option.gravity = [0, 0, 0]
    parent = spec.worldbody
    for i in range(n):
        body = parent.add_body(name=f"l{i}", pos=[0, 0, 0 if i == 0 else -1])
        body.add_joint(name=f"j{i}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0])
        body.mass = 1.0
        body.ipos = [0, 0, -0.5]
        body.inertia = [1 / 12, 1 / 12, 1e-3]
        body.explicitinertial = True
        parent = body
    return spec.compile()


def initial(n: int):
    return np.full(n, 0.3 / n), 0.05 * np.sin(np.arange(n) * 2.39)


def time_ukemi(n: int, steps: int) -> tuple[float, float]:
    model = ukemi_chain(n)
    q, v = initial(n)
    state = model.make_state(qpos=q, qvel=v)
    ukemi.rollout(model, state, nsteps=5)
    t0 = time.perf_counter()
    traj = ukemi.rollout(model, state, nsteps=steps)
    return (time.perf_counter() - t0) / steps, float(traj.iterations.mean())


def time_mujoco(n: int, steps: int) -> float | None:
    try:
        import mujoco
    except ImportError:
        return None
    m = mujoco_chain(n)
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = initial(n)
    t0 = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(m, d)
    return (time.perf_counter() - t0) / steps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=200)
    args = ap.parse_args()
    rows, ours = [], []
    print(f"{'N':>6} {'ukemi µs/step':>14} {'Newton it':>10} {'MuJoCo µs/step':>15} {'ratio':>7}")
    for n in SIZES:
        steps = max(20, args.steps * 10 // n)
        t, it = time_ukemi(n, steps)
        tm = time_mujoco(n, steps)
        ratio = f"{t / tm:7.1f}" if tm else "    n/a"
        mj = f"{tm * 1e6:15.1f}" if tm else f"{'n/a':>15}"
        print(f"{n:6d} {t * 1e6:14.1f} {it:10.2f} {mj} {ratio}")
        rows.append((n, t, tm))
        ours.append((n, t / max(it, 1.0)))
    ln = np.log
    slope = np.polyfit(ln([r[0] for r in rows]), ln([r[1] for r in rows]), 1)[0]
    slope_it = np.polyfit(ln([o[0] for o in ours]), ln([o[1] for o in ours]), 1)[0]
    print(f"fitted exponent: ukemi time/step {slope:.3f}, time/Newton iteration {slope_it:.3f} "
          "(target <= 1.1)")
    if all(r[2] for r in rows):
        s_mj = np.polyfit(ln([r[0] for r in rows]), ln([r[2] for r in rows]), 1)[0]
        print(f"fitted exponent: MuJoCo time/step {s_mj:.3f}")


if __name__ == "__main__":
    main()
