"""What the gradient of a loss on a whole rollout costs (printed, not asserted): the Table V
workload (dt = 0.01, random controls in the control range, `--steps` steps) on the shared
robots, seconds for

* ``forward``: the rollout alone (``ukemi.jax.rollout`` under ``jit``);
* ``grad``: ``jax.grad`` of a loss on every state of that rollout (forward + reverse sweep);
* ``fwd + vjp``, ``kept``: the same two engine calls the gradient makes (``_flat.rollout`` then
  ``_flat.rollout_vjp``), without and with the forward pass kept for the VJP (what ``jax.grad``
  and torch's ``backward`` do since session 18: the VJP then only linearises the stored steps,
  all at once on the thread pool, instead of solving every step again);
* ``steps``: the same per step, as a policy in the loop differentiates it: ``--steps`` calls of
  ``_flat.step`` then as many ``_flat.step_vjp`` in reverse, without and with each solved step
  kept for its VJP; ``cold``: kept, with each flat step starting its solve cold
  (``ukemi.set_flat_warm_start(False)``) instead of where the step that returned its input
  ended (the default since session 19).

Run: .venv/bin/python examples/benchmarks/rollout_grad.py [--steps 300] [--threads N]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import ukemi
from ukemi import _flat

SHARED = Path(__file__).resolve().parents[3] / "shared" / "models"


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--threads", type=int, default=0, help="ukemi.set_num_threads (0: per core)")
    ap.add_argument("--only", default="", help="run models whose name contains this")
    args = ap.parse_args()
    ukemi.set_num_threads(args.threads)
    import jax
    import jax.numpy as jnp

    import ukemi.jax as ujax

    print(f"{'model':10s} | {'forward':>8s} {'grad':>8s} | {'fwd + vjp':>9s} {'kept':>8s} | "
          f"{'steps':>8s} {'kept':>8s} {'cold':>8s}")
    for name in ("humanoid", "a1", "panda", "x2"):
        path = SHARED / f"{name}.xml"
        if args.only not in name or not path.exists():
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = ukemi.Model.from_xml_path(str(path)).with_options(timestep=0.01)
        s = m.make_state(key=m.keyframe_names[0]) if m.keyframe_names else m.make_state()
        x0 = np.concatenate([s.qpos, s.qvel])
        r = np.array(m.actuator_ctrlrange)
        lo = np.where(np.isfinite(r[:, 0]), r[:, 0], -1.0)
        hi = np.where(np.isfinite(r[:, 1]), r[:, 1], 1.0)
        us = lo + (hi - lo) * np.random.default_rng(0).random((args.steps, m.nu))
        w = np.ones((args.steps + 1, x0.size))

        def loss(x0, us):
            return jnp.sum(w * ujax.rollout(m, x0, us, kappa_grad=None))

        fwd = jax.jit(lambda x0, us: ujax.rollout(m, x0, us, kappa_grad=None))
        grad = jax.jit(jax.grad(loss, argnums=(0, 1)))
        xj, uj = jnp.asarray(x0), jnp.asarray(us)
        times = []
        for f in (fwd, grad):
            jax.block_until_ready(f(xj, uj))  # compile (and a first run)
            t0 = time.perf_counter()
            jax.block_until_ready(f(xj, uj))
            times.append(time.perf_counter() - t0)
        for keep in (False, True):
            t0 = time.perf_counter()
            _flat.rollout(m, x0, us, None, keep)
            _flat.rollout_vjp(m, x0, us, None, w, None)
            times.append(time.perf_counter() - t0)
        for keep, warm in ((False, True), (True, True), (True, False)):
            ukemi.set_flat_warm_start(warm)
            t0 = time.perf_counter()
            xs = [x0]
            for u in us:
                xs.append(_flat.step(m, xs[-1], u, None, keep))
            lam = np.zeros_like(x0)
            for k in reversed(range(len(us))):
                lam = _flat.step_vjp(m, xs[k], us[k], None, lam + w[k + 1], None)[0]
            times.append(time.perf_counter() - t0)
        ukemi.set_flat_warm_start(True)
        print(f"{name:10s} | {times[0]:7.3f}s {times[1]:7.3f}s | {times[2]:8.3f}s {times[3]:7.3f}s"
              f" | {times[4]:7.3f}s {times[5]:7.3f}s {times[6]:7.3f}s")
    print(f"{ukemi.get_num_threads()} thread(s); exact gradients (kappa_grad=None)")


if __name__ == "__main__":
    main()
