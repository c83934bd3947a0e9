"""Analytic policy gradient on ukemi/Pendulum-v0 through the differentiable task API.

A small tanh-MLP policy is trained by gradient ascent on the return of short rollouts
(``jax.grad`` through ``task.step``, i.e. the engine's implicit gradients, and through
``task.reward``), from a fixed batch of start states drawn with ``task.reset_state``. Prints
the mean return of the batch per iteration; the same reward the gymnasium env returns.

Run: .venv/bin/python examples/pendulum_apg.py [--iters 30] [--horizon 40] [--batch 16]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--iters", type=int, default=30)
    p.add_argument("--horizon", type=int, default=40, help="env steps per rollout (dt = 0.05 s)")
    p.add_argument("--batch", type=int, default=16, help="start states per iteration")
    p.add_argument("--lr", type=float, default=3e-2)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()

    import jax
    import jax.numpy as jnp

    from ukemi.envs.differentiable import make_task

    task = make_task("ukemi/Pendulum-v0", backend="jax")
    key = jax.random.PRNGKey(args.seed)
    k_init, k_states = jax.random.split(key)
    x0 = jax.vmap(task.reset_state)(jax.random.split(k_states, args.batch))  # (batch, 2)

    def init(key, sizes=(3, 32, 1)):
        keys = jax.random.split(key, len(sizes) - 1)
        return [(jax.random.normal(k, (m, n)) / np.sqrt(m), jnp.zeros(n))
                for k, m, n in zip(keys, sizes[:-1], sizes[1:], strict=True)]

    def policy(params, x):
        h = jnp.stack([jnp.cos(x[..., 0]), jnp.sin(x[..., 0]), x[..., 1]], -1)
        for w, b in params[:-1]:
            h = jnp.tanh(h @ w + b)
        w, b = params[-1]
        return 2.0 * jnp.tanh(h @ w + b)  # torque in [-2, 2]

    def mean_return(params):
        def body(x, _):
            u = policy(params, x)
            x1 = task.step(x, u)  # batched: one engine call per step
            return x1, task.reward(x, u, x1)

        _, rewards = jax.lax.scan(body, x0, None, length=args.horizon)
        return rewards.sum(0).mean()

    value_and_grad = jax.jit(jax.value_and_grad(mean_return))
    params = init(k_init)
    # Adam
    m = jax.tree_util.tree_map(jnp.zeros_like, params)
    v = jax.tree_util.tree_map(jnp.zeros_like, params)
    curve = []
    t0 = time.perf_counter()
    for i in range(args.iters):
        ret, g = value_and_grad(params)
        curve.append(float(ret))
        m = jax.tree_util.tree_map(lambda a, b: 0.9 * a + 0.1 * b, m, g)
        v = jax.tree_util.tree_map(lambda a, b: 0.999 * a + 0.001 * b * b, v, g)
        c1, c2 = 1 - 0.9 ** (i + 1), 1 - 0.999 ** (i + 1)
        params = jax.tree_util.tree_map(
            lambda w, a, b: w + args.lr * (a / c1) / (jnp.sqrt(b / c2) + 1e-8), params, m, v)
        if i % 5 == 0 or i == args.iters - 1:
            print(f"iter {i:3d}  mean return over {args.horizon} steps: {ret:9.2f}")
    wall = time.perf_counter() - t0
    print(f"return {curve[0]:.2f} -> {curve[-1]:.2f} in {args.iters} iterations, {wall:.1f} s")
    print(f"command: .venv/bin/python examples/pendulum_apg.py --iters {args.iters} "
          f"--horizon {args.horizon} --batch {args.batch} --lr {args.lr} --seed {args.seed}")
    return np.array(curve)


if __name__ == "__main__":
    main()
