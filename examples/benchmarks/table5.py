"""Dojo paper Table V workload: forward step + full minimal-coordinate Jacobians A and B every
step, for 1000 steps at dt = 0.01 with random controls in the control range, against MuJoCo
(mj_step + mjd_transitionFD with forward differences, as ../shared/models/README.md measures
its reference figures) on the same MJCF file, in the same run, each timing the mean of
`--repeats` runs. Also forward only, the rollout VJP, and MuJoCo with centred differences
(errors ~1e-10 relative, as ukemi's implicit Jacobians have, where forward differences at eps
1e-6 have ~1e-6). Numbers are printed, not asserted.

    .venv/bin/python examples/benchmarks/table5.py            # reduced: 100 steps
    .venv/bin/python examples/benchmarks/table5.py --steps 1000 --repeats 5   # the README's
    .venv/bin/python examples/benchmarks/table5.py --only shared/   # the four shared robots
    .venv/bin/python examples/benchmarks/table5.py --kappa-grad 1e-4   # smoothed gradients
    .venv/bin/python examples/benchmarks/table5.py --tol 1e-6   # looser solver (Dojo.jl's rtol)
    .venv/bin/python examples/benchmarks/table5.py --threads 1   # rollouts on one thread
    .venv/bin/python examples/benchmarks/table5.py --seed 3   # other random controls

`ukemi.rollout_jacobians` (the A,B workload in one call) and the rollout VJP linearise their
steps on the other threads while their forward pass runs (rayon's default: one thread per core;
`--threads` sets `ukemi.set_num_threads`); the step-by-step columns and MuJoCo run on one
thread.

Per-phase timings of the Jacobians (solve, central path, factorisation, partials,
back-substitution): `cargo run --release -p ukemi-engine --example gradient_phases -- MODEL.xml`.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import ukemi

SHARED = Path(__file__).resolve().parents[3] / "shared" / "models"


def models():
    out = [(f"gymnasium/{n}", Path(ukemi.gymnasium_asset_path(n)))
           for n in ("inverted_double_pendulum", "reacher", "hopper", "humanoid")]
    out += [(f"shared/{n}", SHARED / f"{n}.xml") for n in ("humanoid", "a1", "panda", "x2")]
    return out


def random_ctrls(lo, hi, steps, rng):
    return lo + (hi - lo) * rng.random((steps, len(lo)))


def bench_ukemi(model, ctrls, with_jac, kappa_grad):
    """Seconds for the rollout, failed steps, and (with Jacobians) the gradient overhead: the
    time of step_jacobians minus that of a plain step from the same state, summed over the
    steps whose Jacobians succeeded."""
    s = model.make_state(key=model.keyframe_names[0]) if model.keyframe_names else model.make_state()
    total = overhead = 0.0
    fails = 0
    for u in ctrls:
        if with_jac:
            t0 = time.perf_counter()
            ukemi.step(model, s, u, on_failure="return")
            t1 = time.perf_counter()
            try:
                s = ukemi.step_jacobians(model, s, u, wrt=("state", "ctrl"),
                                         kappa_grad=kappa_grad).next_state
                overhead += (time.perf_counter() - t1) - (t1 - t0)
            except ukemi.ConvergenceError:
                fails += 1
                s, _ = ukemi.step(model, s, u, on_failure="return")
            total += time.perf_counter() - t1
        else:
            t0 = time.perf_counter()
            s, info = ukemi.step(model, s, u, on_failure="return")
            total += time.perf_counter() - t0
            fails += not info.converged
    return total, fails, overhead


def bench_rollout_vjp(model, ctrls, kappa_grad):
    s = model.make_state(key=model.keyframe_names[0]) if model.keyframe_names else model.make_state()
    adj = np.ones((len(ctrls) + 1, 2 * model.nv))
    t0 = time.perf_counter()
    try:
        ukemi.rollout_vjp(model, s, ctrls, adj, params=False, kappa_grad=kappa_grad)
        ok = True
    except ukemi.ConvergenceError:
        ok = False
    return time.perf_counter() - t0, ok


def bench_rollout_jacobians(model, ctrls, kappa_grad):
    """The A,B workload in one call: `ukemi.rollout_jacobians` (its steps linearised on the
    other threads while the forward pass runs)."""
    s = model.make_state(key=model.keyframe_names[0]) if model.keyframe_names else model.make_state()
    t0 = time.perf_counter()
    try:
        ukemi.rollout_jacobians(model, s, ctrls, wrt=("state", "ctrl"), kappa_grad=kappa_grad)
        ok = True
    except ukemi.ConvergenceError:
        ok = False
    return time.perf_counter() - t0, ok


def bench_mujoco(path, ctrls, with_jac, centred=False):
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(path))
    m.opt.timestep = 0.01
    if m.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4:
        m.opt.integrator = mujoco.mjtIntegrator.mjINT_EULER  # mjd_transitionFD has no RK4
    d = mujoco.MjData(m)
    if m.nkey:
        mujoco.mj_resetDataKeyframe(m, d, 0)
    n = 2 * m.nv + m.na
    A, B = np.zeros((n, n)), np.zeros((n, m.nu))
    t0 = time.perf_counter()
    for u in ctrls:
        d.ctrl[:] = u
        if with_jac:
            # forward differences (the and ../shared/models/README.md's reference), or
            # centred ones: errors ~1e-10 like ukemi's implicit Jacobians, not ~1e-6
            mujoco.mjd_transitionFD(m, d, 1e-6, int(centred), A, B, None, None)
        mujoco.mj_step(m, d)
    return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=1, help="timings are the mean of this many runs")
    ap.add_argument("--only", default="", help="run models whose name contains this")
    ap.add_argument("--seed", type=int, default=0,
                    help="seed of the random controls (the models run draw from it in turn)")
    ap.add_argument("--kappa-grad", type=float, default=None,
                    help="central-path parameter of the gradients (default: exact, None)")
    ap.add_argument("--tol", type=float, default=None,
                    help="solver tolerance, rtol = kappa_tol = TOL (default: the model's, 1e-10 "
                         "and 1e-11); what accuracy costs in time")
    ap.add_argument("--threads", type=int, default=0,
                    help="threads of the rollouts (ukemi.set_num_threads; 0: one per core)")
    args = ap.parse_args()
    ukemi.set_num_threads(args.threads)
    kappa = args.kappa_grad
    mean = lambda f: [sum(x) / args.repeats for x in zip(*(f() for _ in range(args.repeats)))]
    rng = np.random.default_rng(args.seed)
    print(f"{'model':24s} {'nv':>4s} {'nu':>3s} | {'ukemi fwd':>10s} {'mj fwd':>9s} | "
          f"{'ukemi A,B':>10s} {'mj FD':>9s} {'ratio':>6s} {'grad ovh':>9s} | "
          f"{'rollout A,B':>11s} {'/mj FD':>7s} | {'rollout VJP':>11s} {'/mj FD':>7s} | "
          f"{'mj cFD':>8s} {'A,B/cFD':>7s}")
    for name, path in models():
        if args.only not in name:
            continue
        if not path.exists():
            print(f"{name:24s} skipped: {path} not found")
            continue
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = ukemi.Model.from_xml_path(str(path)).with_options(timestep=0.01)
                if args.tol is not None:
                    model = model.with_options(rtol=args.tol, kappa_tol=args.tol)
        except ukemi.UkemiError as e:
            print(f"{name:24s} skipped: {type(e).__name__}: {str(e)[:90]}")
            continue
        r = np.array(model.actuator_ctrlrange) if model.nu else np.zeros((0, 2))
        lo = np.where(np.isfinite(r[:, 0]), r[:, 0], -1.0) if model.nu else np.zeros(0)
        hi = np.where(np.isfinite(r[:, 1]), r[:, 1], 1.0) if model.nu else np.zeros(0)
        ctrls = random_ctrls(lo, hi, args.steps, rng)
        tf, ff, _ = mean(lambda: bench_ukemi(model, ctrls, False, kappa))
        tj, fj, oj = mean(lambda: bench_ukemi(model, ctrls, True, kappa))
        tr, okr = mean(lambda: bench_rollout_jacobians(model, ctrls, kappa))
        tv, okv = mean(lambda: bench_rollout_vjp(model, ctrls, kappa))
        mf, mj, mc = mean(lambda: (bench_mujoco(path, ctrls, False), bench_mujoco(path, ctrls, True),
                                   bench_mujoco(path, ctrls, True, centred=True)))
        print(f"{name:24s} {model.nv:4d} {model.nu:3d} | {tf:9.3f}s {mf:8.3f}s | {tj:9.3f}s {mj:8.3f}s "
              f"{tj / mj:6.2f} {oj:8.3f}s | {tr:10.3f}s{'' if okr else '*'} {tr / mj:7.2f} | "
              f"{tv:10.3f}s{'' if okv else '*'} {tv / mj:7.2f} | {mc:7.3f}s {tj / mc:7.2f}"
              + (f"   ({ff} fwd / {fj} jac steps unconverged)" if ff or fj else ""))
    print("ratio = ukemi/MuJoCo (target: A,B ≤ 0.5; rollout VJP ≤ 0.1 of MuJoCo's FD); "
          "grad ovh = step_jacobians minus a plain step from the same states (successful ones); "
          "rollout A,B = the same workload in one ukemi.rollout_jacobians call; "
          "mj cFD = MuJoCo with centred differences (the accuracy of ukemi's Jacobians), "
          "A,B/cFD = ukemi A,B against it; "
          "* = the rollout stopped at an unconverged step; "
          f"the rollouts ran on {ukemi.get_num_threads()} thread(s)")


if __name__ == "__main__":
    main()
