"""A step whose whole-step solve fails is taken again as n equal sub-steps (option
``max_subdivisions``): the result must be exactly n steps of the model at timestep / n, with the
impulses summed over the sub-steps, and it must be reported."""

from __future__ import annotations

import numpy as np
import pytest
from stress._random_scenes import random_scene

import ukemi


def _scene_before_failure(seed: int, step: int):
    m, _ = random_scene(seed)
    tr = ukemi.rollout(m, m.make_state(), nsteps=step, on_failure="return")
    assert tr.converged and np.all(tr.subdivisions == 1)
    return m, tr.final_state


# random stress scene 73 (one loose body) stalls at step 86 at h = 0.01 (measured 2026-11-23)
SEED, STEP = 73, 86


def test_failed_step_is_subdivided_and_reported():
    m, s = _scene_before_failure(SEED, STEP)
    _, whole = ukemi.step(m.with_options(max_subdivisions=1), s, None, on_failure="return")
    assert not whole.converged and whole.subdivisions == 1

    nxt, info = ukemi.step(m, s, None)
    assert info.converged and info.subdivisions == 2

    # exactly two steps of h / 2 from the same state
    half = m.with_options(timestep=m.timestep / 2)
    a, ia = ukemi.step(half, s, None)
    b, ib = ukemi.step(half, a, None)
    assert ia.converged and ib.converged
    np.testing.assert_allclose(nxt.qpos, b.qpos, rtol=0, atol=1e-13)
    np.testing.assert_allclose(nxt.qvel, b.qvel, rtol=0, atol=1e-13)
    assert nxt.time == pytest.approx(s.time + m.timestep, abs=1e-15)
    # the reported impulse is the whole step's: the sum over the sub-steps
    total = a.contact_impulse + b.contact_impulse
    assert np.abs(total).max() > 0.1  # the body is in contact at this step
    np.testing.assert_allclose(nxt.contact_impulse, total, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(nxt.joint_impulse, a.joint_impulse + b.joint_impulse,
                               rtol=1e-12, atol=1e-15)


def test_rollout_reports_subdivisions():
    m, _ = random_scene(SEED)
    tr = ukemi.rollout(m, m.make_state(), nsteps=STEP + 1)
    assert tr.converged
    assert tr.subdivisions.shape == (STEP + 1,)
    assert list(np.nonzero(tr.subdivisions > 1)[0]) == [STEP]
    off = ukemi.rollout(m.with_options(max_subdivisions=1), m.make_state(), nsteps=STEP + 1,
                        on_failure="return")
    assert not off.converged and np.all(off.subdivisions == 1)


@pytest.mark.parametrize("bad", [0, 2000])
def test_max_subdivisions_is_validated(bad):
    m, _ = random_scene(SEED)
    with pytest.raises(ValueError, match="max_subdivisions"):
        m.with_options(max_subdivisions=bad)
