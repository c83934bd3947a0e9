"""What `kappa_grad` does to a robot: how far the smoothed step (the map the gradients at κ
differentiate) is from the simulated, hard one, and what a gradient at κ costs.

Along a trajectory of random controls (uniform in the control range, from the first keyframe),
every `--every`-th state is stepped hard and smoothed at each κ (`ukemi.step_smoothed`); the
table prints the median and largest `max |qvel_smoothed - qvel_hard|` over those states, and the
mean milliseconds of `ukemi.step_jacobians(..., kappa_grad=κ)` against the hard gradient's.
At κ each complementarity pair the step activated is held at `b ∘ c = κ` and pushes with
`κ / gap`, so the difference grows with κ and with the lightness of the bodies pushed;
`--every-candidate` holds every candidate of the model so (`smooth_every_candidate=True`,
the Dojo paper's relaxed problem), which then costs the gradient with their number.

    PYTHONPATH=python .venv/bin/python examples/benchmarks/smoothing_bias.py            # the four shared robots
    PYTHONPATH=python .venv/bin/python examples/benchmarks/smoothing_bias.py --every-candidate
    PYTHONPATH=python .venv/bin/python examples/benchmarks/smoothing_bias.py --kappa 1e-8 1e-6 3e-4 \\
        --models ../shared/models/a1.xml --steps 120
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import ukemi

SHARED = Path(__file__).resolve().parents[3] / "shared" / "models"


def measure(path: Path, kappas: list[float], steps: int, every: int, seed: int,
            every_candidate: bool = False):
    m = ukemi.load(str(path)).with_options(smooth_every_candidate=every_candidate)
    rng = np.random.default_rng(seed)
    s = m.make_state(key=m.keyframe_names[0]) if m.keyframe_names else m.make_state()
    cr = np.asarray(m.actuator_ctrlrange)
    bias = {k: [] for k in kappas}
    cost = {k: [] for k in [None, *kappas]}
    for i in range(steps):
        u = rng.uniform(cr[:, 0], cr[:, 1])
        nxt, info = ukemi.step(m, s, u, on_failure="return")
        if i % every == 0 and info.converged:
            for k in [None, *kappas]:
                t0 = time.perf_counter()
                try:
                    ukemi.step_jacobians(m, s, u, kappa_grad=k)
                except ukemi.ConvergenceError:
                    continue
                cost[k].append(time.perf_counter() - t0)
                if k is not None:
                    smoothed, _ = ukemi.step_smoothed(m, s, u, kappa=k)
                    bias[k].append(np.abs(smoothed.qvel - nxt.qvel).max())
        s = nxt
    return m, bias, cost


def main() -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--models", nargs="*",
                   default=[str(SHARED / f"{n}.xml") for n in ("humanoid", "a1", "panda", "x2")])
    p.add_argument("--kappa", nargs="*", type=float, default=[1e-8, 1e-6, 1e-4, 3e-4])
    p.add_argument("--steps", type=int, default=60)
    p.add_argument("--every", type=int, default=6, help="measure every this many steps")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--every-candidate", action="store_true",
                   help="smooth over every candidate of the model (smooth_every_candidate=True)")
    a = p.parse_args()
    print("| model | candidates | κ | largest Δqvel: median / max | gradient ms (hard) | × hard |")
    print("|---|---|---|---|---|---|")
    rows = []
    for path in a.models:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the MJCF loaders' notes on ignored attributes
            m, bias, cost = measure(Path(path), a.kappa, a.steps, a.every, a.seed,
                                   a.every_candidate)
        hard = 1e3 * float(np.mean(cost[None]))
        for k in a.kappa:
            if not bias[k]:
                print(f"| {Path(path).stem} | {m.ncontact} | {k:g} | (no central-path point found) | | |")
                continue
            ms = 1e3 * float(np.mean(cost[k]))
            b = np.asarray(bias[k])
            print(f"| {Path(path).stem} | {m.ncontact} | {k:g} | {np.median(b):.2g} / {b.max():.2g} "
                  f"| {ms:.2f} ({hard:.2f}) | {ms / hard:.1f} |")
            rows.append({"model": Path(path).stem, "kappa": k, "median": float(np.median(b)),
                         "max": float(b.max()), "ms": ms, "hard_ms": hard})
    return rows


if __name__ == "__main__":
    main()
