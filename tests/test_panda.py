"""The shared Franka Panda under the accuracy bench's Table V random controls (issue #8)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import ukemi
from conftest import beside_mujoco
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


def _panda_and_mujoco():
    """The shared Panda at dt = 0.01 in ukemi (with its state at the `home` keyframe) and in
    MuJoCo (its own `implicitfast` integrator, which the MJCF asks for; `beside_mujoco` starts
    it at the same keyframe)."""
    mujoco = pytest.importorskip("mujoco")
    if not PANDA.exists():
        pytest.skip(f"{PANDA} is absent (shared models live beside the repository)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = ukemi.Model.from_xml_path(str(PANDA)).with_options(timestep=0.01)
    mj = mujoco.MjModel.from_xml_path(str(PANDA))
    mj.opt.timestep = 0.01
    assert mj.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    assert mj.nkey and mujoco.mj_id2name(mj, mujoco.mjtObj.mjOBJ_KEY, 0) == "home"
    return model, model.make_state(key="home"), mj


HOME_CTRL = np.array([0, 0, 0, -1.57079, 0, 1.57079, -0.7853, 255.0])


def test_panda_holds_its_home_pose_as_mujoco_does():
    """Position servos are stiff dampers (kv = 200-450 N·m·s on ~0.1-2 kg·m²): taken
    explicitly at dt = 0.01 they shook the arm held at its home pose at ±3.5 rad/s (as MuJoCo's
    Euler integrator does). Their velocity gain is implicit (`actuation::split_force`): the arm
    settles where MuJoCo's `implicitfast` settles it, and stays."""
    model, s, mj = _panda_and_mujoco()
    s, data, _ = beside_mujoco(model, s, mj, [HOME_CTRL] * 200)
    assert np.abs(s.qvel[:7]).max() < 1e-6
    np.testing.assert_allclose(s.qpos[:7], data.qpos[:7], atol=1e-3)


def test_panda_servo_step_response_follows_mujoco():
    """Every arm joint's target moved by 0.2-0.5 rad at step 10 (joints 5-7 then saturate at
    their 12 N·m): the joints follow MuJoCo's `implicitfast` trajectory on the same MJCF to
    the integrators' difference (measured: at most 0.027 rad over 1.5 s, 2e-3 rad at the end;
    with the explicit velocity gain the arm shook by tenths of a radian)."""
    model, s, mj = _panda_and_mujoco()
    target = HOME_CTRL + np.array([0.3, 0.2, -0.3, 0.3, 0.4, -0.3, 0.5, 0.0])
    s, data, worst = beside_mujoco(model, s, mj, [HOME_CTRL] * 10 + [target] * 140)
    assert worst < 0.05
    np.testing.assert_allclose(s.qpos[:7], data.qpos[:7], atol=5e-3)
