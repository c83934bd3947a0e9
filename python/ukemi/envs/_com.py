"""MuJoCo's "com-based" contact wrenches ``cfrc_ext`` from ukemi's contact forces.

MuJoCo (``mj_rnePostConstraint``, called by gymnasium after each env step) writes, per body,
the external contact wrench ``(torque, force)`` in world axes with the torque taken about
``subtree_com`` of the body's root: for a robot that is one tree on a free joint (Ant,
Humanoid) that point is the centre of mass ``c`` of all bodies but the world. The world row
is zero. Verified against mujoco on a resting Ant (tests/test_envs.py): the forces sum to the
weight and the torques about ``c`` to zero in both engines.
"""

from __future__ import annotations

import numpy as np


def subtree_com(env) -> np.ndarray:
    """Centre of mass of bodies 1.. of the env's current state, world (m), (3,)."""
    mass = np.asarray(env.model.body_mass)
    com = np.asarray(env.state.com_pos)
    return (mass[1:, None] * com[1:]).sum(0) / mass[1:].sum()


def cfrc_ext(env, c: np.ndarray | None = None) -> np.ndarray:
    """Per-body contact wrench ``(torque about c, force)`` of the last env step's last engine
    step (impulse / time step), world axes (N·m, N), (nbody, 6); zero after a reset.

    ``c`` defaults to :func:`subtree_com` of the current state. MuJoCo takes it at the last
    substep's initial configuration, one engine step earlier: the torques differ by
    ``Δc × force``, O(timestep) (zero at rest).
    """
    if c is None:
        c = subtree_com(env)
    wrench = env.body_contact_wrench
    force = wrench[:, 3:]
    out = np.concatenate([wrench[:, :3] - np.cross(c, force), force], axis=1)
    out[0] = 0.0
    return out
