"""Flat steps hand their solver warm start on: a flat step whose input is the state a flat
step returned starts its contact solve where that step ended (as a rollout does), and reaches
the same state as a cold start to within the solver's tolerance."""

from __future__ import annotations

import numpy as np
import pytest

import ukemi
from ukemi import _flat, _ukemi

from conftest import ball_on_floor


def _chain(m, x0, us):
    xs = [x0]
    for u in us:
        xs.append(_flat.step(m, xs[-1], u, None, False))
    return np.array(xs)


@pytest.fixture
def pushed_ball():
    m = ball_on_floor()
    s = m.make_state()
    x0 = np.concatenate([s.qpos, s.qvel])
    x0[0] += 0.37  # states no other test steps (the hints are shared by the process)
    us = 3.0 * np.sin(0.3 * np.arange(30) + 0.5)[:, None]
    return m, x0, us


def test_chained_flat_steps_start_where_the_last_one_ended(pushed_ball):
    m, x0, us = pushed_ball
    ukemi.set_flat_warm_start(True)
    hits = _ukemi._warm_hints()[0]
    warm = _chain(m, x0, us)
    assert _ukemi._warm_hints()[0] - hits >= len(us) - 1  # every step after the first
    again = _chain(m, x0, us)
    np.testing.assert_array_equal(warm, again)  # the same calls give the same bits
    try:
        assert ukemi.set_flat_warm_start(False) is True
        hits = _ukemi._warm_hints()[0]
        cold = _chain(m, x0, us)
        assert _ukemi._warm_hints()[0] == hits
    finally:
        assert ukemi.set_flat_warm_start(True) is False
    # the ball rolls and slides under the push: the states differ from step to step ...
    assert np.abs(np.diff(warm[:, 0])).min() > 1e-6
    # ... and warm and cold starts reach them to within the solver's tolerance
    np.testing.assert_allclose(warm, cold, rtol=0, atol=1e-9)
    # as does the rollout, which carries the full state from step to step
    np.testing.assert_allclose(warm, _flat.rollout(m, x0, us, None, False), rtol=0, atol=1e-9)


def test_set_flat_warm_start_takes_a_bool():
    with pytest.raises(TypeError):
        ukemi.set_flat_warm_start("yes")
