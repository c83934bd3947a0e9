"""Is a random scene's energy growth integration error? Rerun every scene that fails the
energy bound only (``_measured.py``) at timestep h, h/2 and h/4 and print each energy gain.

    python -m tests.stress.energy_refinement      # from the repository root, ~2 min

A gain that shrinks under refinement (to within the 5% bound at h/4) is the variational
integrator's discretisation error at large h|ω|, not an instability of the solver.
"""

from __future__ import annotations

import numpy as np

import ukemi

from ._measured import RANDOM_SCENES
from ._random_scenes import random_scene


def gains(seed: int, refinements=(1, 2, 4), nsteps: int = 300) -> list[float]:
    """Energy gain (relative to max(1 J, |E0|)) of scene ``seed`` over ``nsteps`` steps of h,
    at timestep h / n for each n (n × the steps)."""
    m0, _ = random_scene(seed)
    out = []
    for n in refinements:
        m = m0.with_options(timestep=m0.timestep / n)
        tr = ukemi.rollout(m, m.make_state(), nsteps=nsteps * n, on_failure="return")
        e = tr.energy
        out.append(float((e.max() - e[0]) / max(1.0, abs(e[0]))))
    return out


def main() -> None:
    energy_only = [k for k, v in RANDOM_SCENES.items() if "unconverged" not in v]
    within = 0
    for seed in energy_only:
        g = gains(seed)
        within += g[-1] < 0.05
        print(f"scene {seed}: energy gain at h, h/2, h/4: " + ", ".join(f"{x:.3f}" for x in g),
              flush=True)
    print(f"{within} of {len(energy_only)} energy-only failures stay within 5% at h/4")


if __name__ == "__main__":
    main()
