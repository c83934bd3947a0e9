"""The shared Franka Panda under the accuracy bench's Table V random controls (issue #8)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import ukemi
from ukemi.bench import robots

PANDA = Path(__file__).resolve().parents[2] / "shared" / "models" / "panda.xml"

# Step 135 (fingers closing at 1.2 m/s onto their limits and each other while a finger pad
# slides on the floor under ~150 N) stops short of convergence with max_iter 50 in every retry
# and subdivision; the last-resort solve with four times the budget (`step::long_solve`)
# converges it without gaining energy (measured 2026-12-02: 141 iterations).
KNOWN_UNCONVERGED: set[int] = set()


def _table_v_run(steps: int):
    """The panda, Table V's first ``steps`` random controls and its start state (skips when the
    shared models are absent)."""
    if not PANDA.exists():
        pytest.skip(f"{PANDA} is absent (shared models live beside the repository)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = ukemi.Model.from_xml_path(str(PANDA)).with_options(timestep=robots.TABLE_V_DT)
    ctrls = robots.random_ctrls(np.array(model.actuator_ctrlrange), steps)
    return model, ctrls, model.make_state(key=model.keyframe_names[0])


def test_panda_table_v_random_controls_fingers_never_pass_each_other():
    """Table V's run (200 steps, dt 0.01, seed 0). At step 135 the fingers close 7.2 mm apart
    at 1.16 m/s each: the step's predicted poses put each finger's pads past the other's, and
    the pads' box faces chosen there were the far faces (−2.4e-2 m at the start of the step for
    pads 1.6e-2 m apart), contradicting the finger joints' limits. That step and the next four
    failed and the fingers ended 6.4 mm below their limits, the pads 3.5 mm inside each other."""
    model, ctrls, s0 = _table_v_run(200)
    traj = ukemi.rollout(model, s0, ctrls, on_failure="return")
    assert len(traj.status) == 200
    bad = set(np.nonzero(~np.isin(traj.status, ukemi.SUCCESS_STATUSES))[0].tolist())
    assert bad <= KNOWN_UNCONVERGED
    assert model.joint_names[-2:] == ["finger_joint1", "finger_joint2"]  # the last two qpos
    assert traj.qpos[:, -2:].min() >= -1e-8  # the fingers' limits are [0, 0.04]
    assert traj.min_distance.min() >= -1e-8


def test_panda_step_135_has_gradients():
    """The gradients take the same last-resort solve as the step (`substeps::retry`): at step
    135 they used to raise ConvergenceError; they must now exist and be finite."""
    model, ctrls, s0 = _table_v_run(136)
    s = ukemi.rollout(model, s0, ctrls[:135]).final_state
    nxt, info = ukemi.step(model, s, ctrls[135])
    assert info.converged
    jac = ukemi.step_jacobians(model, s, ctrls[135])
    assert np.all(np.isfinite(jac.A)) and np.all(np.isfinite(jac.B))
