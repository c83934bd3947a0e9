"""Throw a box so that it comes to rest on a target: `jax.grad` through a 100-step ukemi rollout
(hard contact with friction; gradients smoothed at kappa_grad) optimises the initial velocity.

    .venv/bin/python examples/jax_throw.py                # full: up to 60 iterations
    .venv/bin/python examples/jax_throw.py --iters 5      # CI smoke run
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import numpy as np

import ukemi
import ukemi.jax as ujax


def box_scene(h=0.01):
    b = ukemi.ModelBuilder(timestep=h)
    b.add_geom("floor", body="world", shape="plane", friction=0.4)
    b.add_body("box", mass=1.0, inertia=(1 / 600, 1 / 600, 1 / 600), pos=(0, 0, 0.3))
    b.add_joint("free", kind="floating", parent="world", child="box")
    b.add_geom("box", body="box", shape="box", size=(0.05, 0.05, 0.05), friction=0.4)
    return b.compile()


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--iters", type=int, default=60)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--kappa", type=float, default=1e-5)
    ap.add_argument("--target", type=float, nargs=2, default=(1.0, 0.4))
    args = ap.parse_args()
    model = box_scene()
    q0 = np.array(model.make_state().qpos)
    target = jnp.asarray(args.target)
    us = jnp.zeros((args.steps, 0))

    def final_xy(v):
        x0 = jnp.concatenate([jnp.asarray(q0), v, jnp.zeros(3)])
        xs = ujax.rollout(model, x0, us, kappa_grad=args.kappa)
        return xs[-1, :2], xs[-1, 7:10]

    def loss(v):
        xy, _ = final_xy(v)
        return jnp.sum((xy - target) ** 2)

    value_and_grad = jax.value_and_grad(loss)
    v = jnp.asarray([1.0, 0.0, 0.5])  # initial guess (m/s)
    lr, m1, m2 = 0.3, jnp.zeros(3), jnp.zeros(3)  # Adam
    t0 = time.perf_counter()
    for it in range(1, args.iters + 1):
        f, g = value_and_grad(v)
        err = float(jnp.sqrt(f))
        print(f"iter {it:3d}  distance to target {err * 100:7.2f} cm  v0 = {np.round(np.asarray(v), 3)}")
        if err < 0.005:
            break
        m1 = 0.9 * m1 + 0.1 * g
        m2 = 0.999 * m2 + 0.001 * g * g
        step = lr / (1 + it / 15) * (m1 / (1 - 0.9**it)) / (jnp.sqrt(m2 / (1 - 0.999**it)) + 1e-8)
        v = v - step
    xy, vel = final_xy(v)
    err = float(jnp.linalg.norm(xy - target))
    print(f"final: rests at {np.round(np.asarray(xy), 4)} (target {args.target}), "
          f"distance {err * 100:.2f} cm, final speed {float(jnp.linalg.norm(vel)):.2e} m/s, "
          f"{time.perf_counter() - t0:.1f} s")
    return err


if __name__ == "__main__":
    main()
