"""Shared small models for the Python tests."""

from __future__ import annotations

import numpy as np
import pytest

import ukemi


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
