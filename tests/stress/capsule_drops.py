"""Capsules dropped on a cylinder lying flat on the floor: a measurement, not a test.

Each drop draws a cylinder (radius 4-10 cm, half height 2-6 cm, 0.3-3 kg) resting on its end
disk and a capsule (radius 1.5-4 cm, half length 3-10 cm, 0.3-5 kg) tilted by two random
angles above it, thrown down at 1-6 m/s over a random point of the disk, friction 0.2-1; 40
steps at h = 0.01. A drop fails when a step is left unconverged or anything ends deeper than
1 µm. Prints the failures of each seed::

    PYTHONPATH=python .venv/bin/python -m tests.stress.capsule_drops [--seeds 0 1] [--drops 300]
"""

from __future__ import annotations

import argparse

import numpy as np

import ukemi

SCENE = """<mujoco><option timestep="0.01"/><worldbody>
<geom type="plane" size="5 5 .1" friction="{mu}"/>
<body pos="0 0 {h}"><freejoint/><geom type="cylinder" size="{r} {h}" mass="{m1}" friction="{mu}"/></body>
<body pos="{x} {y} {z}" euler="{ex} {ey} 0"><freejoint/>
<geom type="capsule" size="{cr} {chl}" mass="{m2}" friction="{mu}"/></body>
</worldbody></mujoco>"""


def drop(rng: np.random.Generator) -> tuple[ukemi.Model, ukemi.State]:
    """The next random drop of ``rng``: the model and its start state."""
    r, h = rng.uniform(0.04, 0.1), rng.uniform(0.02, 0.06)
    p = dict(r=r, h=h, x=rng.uniform(-r, r), y=rng.uniform(-r, r), z=2 * h + 0.15,
             ex=rng.uniform(0, 90), ey=rng.uniform(0, 90), cr=rng.uniform(0.015, 0.04),
             chl=rng.uniform(0.03, 0.1), m1=np.exp(rng.uniform(np.log(0.3), np.log(3))),
             m2=np.exp(rng.uniform(np.log(0.3), np.log(5))), mu=rng.uniform(0.2, 1.0))
    m = ukemi.Model.from_xml_string(SCENE.format(**p))
    qvel = np.zeros(m.nv)
    qvel[8] = -rng.uniform(1, 6)  # the capsule's vertical speed
    return m, m.make_state(qvel=qvel)


def measure(seed: int, drops: int) -> tuple[int, int, int]:
    """(failed drops, of them deeper than 0.1 mm, interior-point iterations) of ``seed``."""
    rng = np.random.default_rng(seed)
    failed = deep = iterations = 0
    for _ in range(drops):
        m, s = drop(rng)
        tr = ukemi.rollout(m, s, nsteps=40, on_failure="return")
        iterations += int(tr.iterations.sum())
        least = float(tr.min_distance.min())
        if not tr.converged or least < -1e-6:
            failed += 1
            deep += least < -1e-4
    return failed, deep, iterations


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--drops", type=int, default=300)
    args = ap.parse_args()
    for seed in args.seeds:
        failed, deep, iterations = measure(seed, args.drops)
        print(f"seed {seed}: {failed} of {args.drops} drops fail ({deep} deeper than 0.1 mm); "
              f"{iterations} iterations")


if __name__ == "__main__":
    main()
