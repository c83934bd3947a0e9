"""Overhead of ``ukemi.jax.step`` over the engine, per step, for the XLA FFI backend and the
``pure_callback`` fallback, eagerly and inside ``jax.lax.scan`` (printed, not asserted).

Rows (µs per step, and the ratio to the Rust flat step):

* ``ukemi.step``: the engine's Python entry point in a Python loop (warm-started full state,
  includes pyo3 call and State object costs);
* ``flat step (Rust)``: the same Rust function ``ukemi.jax.step`` runs (flat state, contact solve
  from the neutral point), timed as a batch of 256 on one rayon thread, so Python overhead is
  amortised away: the engine's own cost;
* ``jax.step eager``: ``ukemi.jax.step(model, x, u)`` called from Python, result awaited;
* ``flat step (Rust), scan states``: the same, on the T states the scan visits (the reference
  for the scan rows: a falling humanoid's later steps have contact and cost more);
* ``jax.step in scan``: a jitted ``lax.scan`` of ``ukemi.jax.step`` over T steps, divided by T.

Overhead and ratio are against the matching flat-step row. On a shared, loaded machine the
numbers are noisy (best of ``--repeat`` is reported).

Run: .venv/bin/python examples/benchmarks/jax_overhead.py [--steps 300] [--repeat 5]
"""

from __future__ import annotations

import argparse
import os
import time

# one rayon thread: the batch timing below measures per-element cost, not parallel speed-up
os.environ.setdefault("RAYON_NUM_THREADS", "1")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import ukemi  # noqa: E402
import ukemi.jax as ujax  # noqa: E402


def pendulum():
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_body("bob", mass=1.0, inertia=(1e-6, 1e-6, 1e-6), pos=(0, 0, -1.0))
    b.add_joint("hinge", kind="revolute", parent="world", child="bob", axis=(0, 1, 0),
                child_anchor=(0, 0, 1.0))
    b.add_actuator("motor", joint="hinge", gear=2.0, ctrlrange=(-1.0, 1.0))
    return b.compile()


def humanoid():
    return ukemi.Model.from_xml_path(ukemi.gymnasium_asset_path("humanoid"))


def best(f, repeat):
    f()  # warm up (compile)
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return min(ts)


def bench(name, model, steps, repeat):
    s0 = model.make_state()
    x0 = np.concatenate([s0.qpos, s0.qvel])
    u = np.zeros(model.nu)
    us = np.zeros((steps, model.nu))
    n_eager = max(steps // 4, 20)
    rows = []

    def engine():
        s = s0
        for _ in range(steps):
            s, _info = ukemi.step(model, s, u)
    rows.append(("ukemi.step (Python loop)", best(engine, repeat) / steps))

    xb, ub = np.tile(x0, (256, 1)), np.tile(u, (256, 1))
    flat = best(lambda: ukemi._ukemi._flat_step(model, xb, ub), repeat) / 256
    rows.append(("flat step (Rust)", flat))

    xj, uj = jnp.asarray(x0), jnp.asarray(u)
    usj = jnp.asarray(us)

    @jax.jit
    def scan(x, us):
        return jax.lax.scan(lambda x, u: (ujax.step(model, x, u),) * 2, x, us)[1]

    # the scan's own reference: the same flat steps (same states) as one Rust batch
    traj = np.concatenate([x0[None], np.asarray(scan(xj, usj))[:-1]])
    flat_traj = best(lambda: ukemi._ukemi._flat_step(model, traj, us), repeat) / steps
    rows.append(("flat step (Rust), scan states", flat_traj))
    for how in ("ffi", "callback"):
        ujax.set_backend(how)

        def eager():
            for _ in range(n_eager):
                ujax.step(model, xj, uj).block_until_ready()
        rows.append((f"jax.step eager [{how}]", best(eager, repeat) / n_eager))

        scan_b = jax.jit(lambda x, us: jax.lax.scan(
            lambda x, u: (ujax.step(model, x, u),) * 2, x, us)[1])
        rows.append((f"jax.step in lax.scan [{how}]",
                     best(lambda: scan_b(xj, usj).block_until_ready(), repeat) / steps))
    ujax.set_backend("auto")

    print(f"\n{name}: nq={model.nq} nv={model.nv} nu={model.nu}, {steps} steps, best of {repeat}")
    print(f"{'':<34} {'µs/step':>10} {'overhead µs':>12} {'ratio':>8}")
    for label, t in rows:
        ref = flat_traj if "scan" in label else flat
        over = "" if label.startswith(("flat", "ukemi")) else f"{(t - ref) * 1e6:12.2f}"
        print(f"{label:<34} {t * 1e6:10.2f} {over:>12} {t / ref:8.3f}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    print(f"jax {jax.__version__}, backend {jax.default_backend()}, "
          f"ukemi FFI registered: {ujax.ffi_available()}, RAYON_NUM_THREADS="
          f"{os.environ['RAYON_NUM_THREADS']}")
    bench("pendulum", pendulum(), a.steps * 4, a.repeat)
    bench("humanoid (gymnasium)", humanoid(), a.steps, a.repeat)


if __name__ == "__main__":
    main()
