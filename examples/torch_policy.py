"""Train a torch MLP policy to swing up and balance a pendulum by backpropagating the cost of
whole rollouts through ukemi (analytic implicit gradients, no reinforcement-learning noise).

    .venv/bin/python examples/torch_policy.py                  # full: 150 iterations
    .venv/bin/python examples/torch_policy.py --iters 3        # CI smoke run
Prints the learning curve and saves it as torch_policy.png.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
import torch

import ukemi
import ukemi.torch as ut

MAX_TORQUE = 6.0  # N·m, above m g l = 4.9 so a direct swing-up is possible


def pendulum(h=0.02):
    b = ukemi.ModelBuilder(timestep=h)
    b.add_body("bob", mass=1.0, inertia=(1e-3, 1e-3, 1e-3), pos=(0, 0, -0.5))
    b.add_joint("hinge", kind="revolute", parent="world", child="bob", axis=(0, 1, 0),
                parent_anchor=(0, 0, 0), child_anchor=(0, 0, 0.5), damping=0.05)
    b.add_actuator("motor", joint="hinge", gear=MAX_TORQUE, ctrlrange=(-1.0, 1.0))
    return b.compile()


class Policy(torch.nn.Module):
    def __init__(self):
        super().__init__()
        self.net = torch.nn.Sequential(torch.nn.Linear(3, 32), torch.nn.Tanh(),
                                       torch.nn.Linear(32, 32), torch.nn.Tanh(),
                                       torch.nn.Linear(32, 1))

    def forward(self, x):
        th, om = x[..., 0:1], x[..., 1:2]
        return torch.tanh(self.net(torch.cat([torch.sin(th), torch.cos(th), 0.1 * om], -1)))


def rollout_cost(model, policy, x0, steps):
    """Mean cost over the batch: upright is θ = π (θ = 0 hangs down)."""
    x, cost = x0, 0.0
    for _ in range(steps):
        u = policy(x)
        x = ut.step(model, x, u, kappa_grad=None)
        th, om = x[:, 0], x[:, 1]
        cost = cost + (1.0 + torch.cos(th)) + 0.01 * om**2 + 0.01 * u[:, 0] ** 2
    return cost.mean() / steps, x


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--iters", type=int, default=150)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--out", default="torch_policy.png")
    args = ap.parse_args()
    torch.manual_seed(0)
    model = pendulum()
    policy = Policy().double()
    opt = torch.optim.Adam(policy.parameters(), lr=1e-2)
    x0 = torch.tensor([[0.2 * (i / max(1, args.batch - 1) - 0.5), 0.0] for i in range(args.batch)],
                      dtype=torch.float64)
    curve = []
    t0 = time.perf_counter()
    for it in range(args.iters):
        opt.zero_grad()
        cost, xT = rollout_cost(model, policy, x0, args.steps)
        cost.backward()
        opt.step()
        curve.append(cost.item())
        if it % 10 == 0 or it == args.iters - 1:
            off = torch.remainder(xT[:, 0].detach(), 2 * math.pi) - math.pi  # wrapped θ - π
            print(f"iter {it:4d}  cost {curve[-1]:.4f}  final |θ-π| "
                  f"{float(off.abs().mean()):.3f} rad  ({time.perf_counter() - t0:.1f} s)")
    with torch.no_grad():
        _, xT = rollout_cost(model, policy, torch.tensor([[0.0, 0.0]], dtype=torch.float64),
                             2 * args.steps)
    err = abs(((float(xT[0, 0]) - math.pi) + math.pi) % (2 * math.pi) - math.pi)
    print(f"from rest hanging down, after {2 * args.steps} steps: |θ - π| = {err:.3f} rad, "
          f"ω = {float(xT[0, 1]):.3f} rad/s")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        plt.figure(figsize=(5, 3.5))
        plt.plot(np.arange(len(curve)), curve)
        plt.xlabel("iteration")
        plt.ylabel("mean cost per step")
        plt.title("pendulum swing-up, gradients through ukemi")
        plt.tight_layout()
        plt.savefig(args.out, dpi=120)
        print(f"wrote {args.out}")
    except ImportError:
        pass
    return err, curve


if __name__ == "__main__":
    main()
