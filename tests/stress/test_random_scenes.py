"""Random scenes from a seeded generator: shapes, sizes, masses and poses on a floor."""

from __future__ import annotations

import numpy as np
import pytest

import ukemi

from ._util import add_free, assert_stable, floor_builder, steps

NSCENES = 100
SHAPES = ("sphere", "box", "capsule", "cylinder", "ellipsoid")
PAIRWISE = ("sphere", "box", "capsule")  # cylinders and ellipsoids collide only with planes


def _inertia(shape: str, size, mass: float):
    """Inertia of a solid of that shape (approximate for capsule/cylinder), principal."""
    if shape == "sphere":
        return (0.4 * mass * size[0] ** 2,) * 3
    if shape in ("box", "ellipsoid"):
        a, b, c = (2 * s for s in size) if shape == "box" else size
        k = 1 / 12 if shape == "box" else 1 / 5
        return (k * mass * (b * b + c * c), k * mass * (a * a + c * c), k * mass * (a * a + b * b))
    r, half = size
    ixx = mass * (3 * r * r + (2 * half) ** 2) / 12
    return (ixx, ixx, 0.5 * mass * r * r)


def random_scene(seed: int):
    rng = np.random.default_rng(seed)
    b = floor_builder(friction=float(rng.uniform(0.2, 1.0)))
    nbody = int(rng.integers(1, 4))
    for i in range(nbody):
        shapes = SHAPES if nbody == 1 else PAIRWISE
        shape = shapes[int(rng.integers(len(shapes)))]
        if shape == "sphere":
            size = (float(rng.uniform(0.03, 0.2)),)
        elif shape in ("box", "ellipsoid"):
            size = tuple(float(x) for x in rng.uniform(0.03, 0.2, 3))
        else:
            size = (float(rng.uniform(0.03, 0.1)), float(rng.uniform(0.03, 0.2)))
        mass = float(np.exp(rng.uniform(np.log(0.1), np.log(10.0))))
        quat = rng.normal(size=4)
        pos = (float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)), 0.5 + 0.6 * i)
        add_free(b, f"b{i}", shape, size, mass, _inertia(shape, size, mass), pos,
                 tuple(quat / np.linalg.norm(quat)), friction=float(rng.uniform(0.2, 1.0)))
    return b.compile()


MEASURED_FAILURES = {  # 2026-11-23, dt 0.01, 300 steps (the first 100 fail the same way)
    6: "2 bodies: 1/300 max_iterations, from step 36",
    14: "2 bodies: 1/300 max_iterations, from step 63",
    18: "1 body: 1/300 max_iterations, from step 39, least -2.5e-03 m",
    21: "2 bodies: 2/300 max_iterations, from step 27",
    24: "3 bodies: 1/300 max_iterations, from step 51",
    28: "1 body: 1/300 max_iterations, from step 32, least -1.2e-03 m",
    30: "3 bodies: 2/300 max_iterations, from step 29",
    35: "3 bodies: 15/300 max_iterations, from step 29, energy +2.3e+00, least -4.7e-02 m",
    37: "2 bodies: 1/300 max_iterations, from step 45",
    41: "3 bodies: 4/300 max_iterations, from step 46",
    44: "3 bodies: 6/300 max_iterations, from step 58, energy +5.8e-01",
    49: "3 bodies: 1/300 max_iterations, from step 33",
    57: "3 bodies: 1/300 max_iterations, from step 55",
    61: "3 bodies: 1/300 max_iterations, from step 59",
    62: "2 bodies: 1/300 max_iterations, from step 56",
    69: "3 bodies: 3/300 max_iterations, from step 38",
    71: "2 bodies: 6/300 unconverged (2 line_search_failed, 4 max_iterations), from step 41",
    88: "3 bodies: 1/300 max_iterations, from step 59",
    89: "1 body: 2/300 line_search_failed, from step 90",
    91: "2 bodies: 1/300 max_iterations, from step 54",
    93: "2 bodies: 1/300 max_iterations, from step 48",
    94: "3 bodies: 2/300 max_iterations, from step 55",
}

REASON = ("engine limit (README 'Known limits': contact solves stall in the friction cones, "
          "Nesterov-Todd scaling pending); measured: ")


@pytest.mark.parametrize("seed", [
    pytest.param(seed, marks=pytest.mark.xfail(strict=False,
                                               reason=REASON + MEASURED_FAILURES[seed]))
    if seed in MEASURED_FAILURES else seed for seed in range(NSCENES)])
def test_random_scene(seed):
    m = random_scene(seed)
    tr = ukemi.rollout(m, m.make_state(), nsteps=steps(100, 300), on_failure="return")
    assert_stable(m, tr)
