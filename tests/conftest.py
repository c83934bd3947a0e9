"""Shared small models for the Python tests."""

from __future__ import annotations

import os

import numpy as np
import pytest

import ukemi


@pytest.fixture(autouse=True, scope="session")
def _sb3_logs_in_pytest_tmp(tmp_path_factory):
    """stable-baselines3 makes an (empty) log folder in the system temp dir at every `learn`
    unless told where: keep them in pytest's own temp dir (examples run as subprocesses
    inherit it)."""
    os.environ.setdefault("SB3_LOGDIR", str(tmp_path_factory.mktemp("sb3")))


def pendulum(timestep=0.01, length=1.0, damping=0.0, actuated=True):
    b = ukemi.ModelBuilder(timestep=timestep)
    b.add_body("bob", mass=1.0, inertia=(1e-6, 1e-6, 1e-6), pos=(0, 0, -length))
    b.add_joint("hinge", kind="revolute", parent="world", child="bob", axis=(0, 1, 0),
                child_anchor=(0, 0, length), damping=damping)
    if actuated:
        b.add_actuator("motor", joint="hinge", gear=2.0, ctrlrange=(-1.0, 1.0))
    return b.compile()


@pytest.fixture
def pend():
    return pendulum()


@pytest.fixture
def free_body():
    b = ukemi.ModelBuilder(timestep=0.01, gravity=(0, 0, 0))
    R = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    inertia = R @ np.diag([1.0, 2.0, 2.5]) @ R.T
    b.add_body("box", mass=2.0, inertia=inertia, pos=(0, 0, 1))
    b.add_joint("free", kind="floating", parent="world", child="box")
    return b.compile()


def arm():
    """Floating box with a hinged arm: a quaternion in the flat state, two motors."""
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_body("base", mass=2.0, inertia=(0.2, 0.3, 0.25), pos=(0, 0, 1))
    b.add_body("arm", mass=0.5, inertia=(0.01, 0.02, 0.02), pos=(0.3, 0, 1))
    b.add_joint("root", kind="floating", parent="world", child="base")
    b.add_joint("elbow", kind="revolute", parent="base", child="arm", axis=(0, 1, 0),
                parent_anchor=(0.15, 0, 0), child_anchor=(-0.15, 0, 0), damping=0.05)
    b.add_actuator("elbow_motor", joint="elbow", gear=2.0)
    b.add_actuator("root_x", joint="root", gear=1.0)
    return b.compile().with_options(rtol=1e-14, max_iter=100)


def ball_on_floor():
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("floor", body="world", shape="plane", friction=0.5)
    b.add_body("ball", mass=1.0, inertia=(0.004, 0.004, 0.004), pos=(0, 0, 0.1))
    b.add_joint("free", kind="floating", parent="world", child="ball")
    b.add_geom("ball", body="ball", shape="sphere", size=(0.1,), friction=0.5)
    b.add_actuator("push_x", joint="free", gear=1.0)
    return b.compile().with_options(rtol=1e-14, max_iter=100)


def x0_of(model, qvel_scale=0.5):
    s = model.make_state()
    rng = np.random.default_rng(1)
    return np.concatenate([s.qpos, qvel_scale * rng.normal(size=model.nv)])


def beside_mujoco(model, state, mj, ctrls):
    """Step `model` from `state` and MuJoCo's `mj` (an `MjModel` of the same MJCF, from its
    first keyframe if it has one, else qpos0 at rest) under the same controls, one row of
    `ctrls` a step. Returns ukemi's last state, MuJoCo's data, and the largest qpos gap over
    the run (hinge and slide models: plain differences). Every ukemi step must converge."""
    import mujoco

    data = mujoco.MjData(mj)
    if mj.nkey:
        mujoco.mj_resetDataKeyframe(mj, data, 0)
    worst = 0.0
    for u in ctrls:
        state, info = ukemi.step(model, state, u)
        assert info.converged
        data.ctrl[:] = u
        mujoco.mj_step(mj, data)
        worst = max(worst, np.abs(state.qpos[:mj.nq] - data.qpos).max())
    return state, data, worst
