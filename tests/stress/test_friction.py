"""Friction: a sliding box over μ = 0 … 2 and a box on a 45° incline."""

from __future__ import annotations

import numpy as np
import pytest

import ukemi

from ._util import FULL, add_free, assert_stable, floor_builder, steps

G = 9.81
MUS = (0.0, 0.1, 0.25, 0.5, 1.0, 1.5, 2.0) if FULL else (0.0, 0.5, 2.0)


FLAT = (0.2, 0.2, 0.05)  # half-extents: a cube would sit exactly at its tipping limit at 45°
FLAT_INERTIA = ((0.2**2 + 0.05**2) / 3, (0.2**2 + 0.05**2) / 3, (0.2**2 + 0.2**2) / 3)

# dt 0.01, v0 = 2 m/s: every μ passes since the solver refines its Newton directions
# (2026-11-23; before: μ = 1.5 and 2.0 had 3 and 1 max_iterations steps)
MU_MEASURED: dict[float, str] = {}


@pytest.mark.parametrize("mu", [
    pytest.param(mu, marks=pytest.mark.xfail(strict=False, reason=(
        f"engine limit (README 'Known limits'), measured: {MU_MEASURED[mu]}")))
    if mu in MU_MEASURED else mu
    for mu in MUS])
def test_sliding_box_friction(mu):
    """A flat box (half-height / half-width = 1/4: it slides without tipping for μ < 4; a cube
    tips over its leading edge once μ > 1, which is physics, not drift) launched at 30° to its
    axes slides straight and stops at v0²/(2μg)."""
    dt, v0 = 0.01, 2.0
    b = floor_builder(dt, friction=mu)
    add_free(b, "box", "box", FLAT, 1.0, FLAT_INERTIA, (0, 0, FLAT[2]), friction=mu)
    m = b.compile()
    d = np.array([np.cos(np.pi / 6), np.sin(np.pi / 6), 0.0])
    n = steps(100, 300)
    tr = ukemi.rollout(m, m.make_state(qvel=[*(v0 * d), 0, 0, 0]), nsteps=n, on_failure="return")
    assert_stable(m, tr)
    disp = tr.body_pos[-1, 1] - tr.body_pos[0, 1]
    along = disp @ d
    assert np.linalg.norm(disp - along * d) < 1e-6  # no lateral drift
    if mu == 0.0:
        assert along == pytest.approx(v0 * n * dt, rel=1e-9)
    else:
        # v0²/(2μg), less the half step the midpoint velocity v_{-1/2} spends before contact
        assert along == pytest.approx(v0**2 / (2 * mu * G), abs=v0 * dt)




def incline(mu: float, angle: float = np.pi / 4, dt: float = 0.01):
    """A flat 1 kg box resting on a plane through the origin tilted by ``angle`` about y."""
    b = ukemi.ModelBuilder(timestep=dt)
    normal = np.array([np.sin(angle), 0.0, np.cos(angle)])
    b.add_geom("ramp", "world", "plane", normal=normal, friction=mu)
    quat = (np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0)  # cube face along the normal
    add_free(b, "box", "box", FLAT, 1.0, FLAT_INERTIA, tuple(FLAT[2] * normal), quat, friction=mu)
    downhill = np.array([np.cos(angle), 0.0, -np.sin(angle)])
    return b.compile(), downhill


def _stick(mu: float) -> float:
    m, downhill = incline(mu)
    tr = ukemi.rollout(m, m.make_state(), nsteps=steps(100, 500), on_failure="return")
    assert_stable(m, tr)
    return float((tr.body_pos[-1, 1] - tr.body_pos[0, 1]) @ downhill)


def test_incline_45_mu_1_sticks():
    # μ = tan 45° needs the whole friction cone to hold the box; the interior-point solution
    # alone crept 1.3e-5 m in 1 s (O(√kappa_tol)) until saturated cones were polished to κ = 0
    # (engine/src/solver/saturation.rs); measured 6e-11 m, all of it in the first step
    slide = _stick(1.0)
    assert abs(slide) < 1e-9, f"slid {slide:.3e} m at μ = tan 45°"


def test_incline_45_mu_105_sticks():
    slide = _stick(1.05)  # measured 5.6e-10 m in 1 s
    assert abs(slide) < 1e-8, f"slid {slide:.3e} m at μ = 1.05"


def test_incline_45_mu_09_slides():
    m, downhill = incline(0.9)
    dt = m.timestep
    tr = ukemi.rollout(m, m.make_state(), nsteps=steps(100, 300), on_failure="return")
    assert_stable(m, tr)
    slide = (tr.body_pos[:, 1] - tr.body_pos[0, 1]) @ downhill
    accel = np.diff(slide, 2) / dt**2
    expected = G * (np.sin(np.pi / 4) - 0.9 * np.cos(np.pi / 4))
    assert np.median(accel[5:]) == pytest.approx(expected, rel=1e-3)
