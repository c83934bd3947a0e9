"""Humanoid-v5 on ukemi: gymnasium's humanoid.xml with v5's observation, reward and termination.

The v5 observation concatenates MuJoCo quantities of the current state; here each is computed
from ukemi's state (:func:`com_quantities`), in MuJoCo's conventions: "com-based" vectors are
world-frame and taken about ``subtree_com`` of the body's root (for the humanoid every body's
root is the torso, so the point is the whole body's centre of mass ``c``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._assets import rotate
from ._com import cfrc_ext, subtree_com
from .base import UkemiMujocoEnv, planar_locomotion_reward


def quat_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4) in (w, x, y, z)."""
    return np.stack([rotate(quat, e) for e in np.eye(3)], axis=-1)


def com_quantities(env: UkemiMujocoEnv) -> dict[str, np.ndarray]:
    """MuJoCo's ``cinert`` (nbody, 10), ``cvel`` (nbody, 6) and ``cfrc_ext`` (nbody, 6) of the
    env's current state, about the centre of mass ``c`` of bodies 1.. (one tree on a free joint).

    * ``cinert`` = (I_xx, I_yy, I_zz, I_xy, I_xz, I_yz, m·d, m) with I the body's inertia about
      ``c`` in world axes and d = com − c (MuJoCo's ``mju_inertCom``).
    * ``cvel`` = (ω, v_c) with v_c the velocity of the point at ``c`` moving with the body.
      ukemi's velocities are the integrator's midpoint velocities, MuJoCo's the end-of-step
      ones: they differ by O(dt).
    * ``cfrc_ext`` = (torque about ``c``, force) of the contacts on the body, from the last
      engine step's contact impulses / time step.
    """
    s, m = env.state, env.model
    mass = np.asarray(m.body_mass)
    com = np.asarray(s.com_pos)
    c = subtree_com(env)
    rot = quat_matrix(np.asarray(s.body_quat))
    inertia = rot @ np.asarray(m.body_inertia) @ np.swapaxes(rot, -1, -2)
    d = com - c
    # parallel axis: I_c = I_com + m (|d|² 1 − d dᵀ)
    inertia = inertia + mass[:, None, None] * ((d * d).sum(1)[:, None, None] * np.eye(3)
                                               - d[:, :, None] * d[:, None, :])
    cinert = np.concatenate([inertia[:, [0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]],
                             mass[:, None] * d, mass[:, None]], axis=1)
    omega, v_origin, origin = np.asarray(s.body_angvel), np.asarray(s.body_linvel), np.asarray(s.body_pos)
    cvel = np.concatenate([omega, v_origin + np.cross(omega, c - origin)], axis=1)
    cinert[0], cvel[0] = 0.0, 0.0
    return {"cinert": cinert, "cvel": cvel, "cfrc_ext": cfrc_ext(env, c), "subtree_com": c}


def dof_index(model) -> dict[str, int]:
    """MuJoCo joint name -> dof index (ukemi merges several hinges of one body into one joint
    named ``"a+b"`` with MuJoCo's dofs in MuJoCo's order)."""
    index, k = {}, 0
    for name, kind in zip(model.joint_names, model.joint_kinds, strict=True):
        if kind == "floating":
            index[name] = k
            k += 6
        elif kind != "fixed":
            for part in name.split("+"):
                index[part] = k
                k += 1
    return index


class HumanoidEnv(UkemiMujocoEnv):
    """3D humanoid running forward (gymnasium ``Humanoid-v5`` on ukemi).

    Same as v5: ``humanoid.xml``, ``frame_skip=5`` (dt = 0.015 s), action Box(−0.4, 0.4, (17,)),
    reward ``1.25·ẋ(centre of mass) + 5·healthy − 0.1·|a|² − min(5e-7·|cfrc_ext|², 10)``,
    healthy iff z = qpos[2] in (1, 2), terminated when unhealthy, reset noise uniform ±0.01 on
    qpos and qvel, 1000-step limit. Observation (348,) =
    ``[qpos[2:] (22), qvel (23), cinert[1:] (130), cvel[1:] (78), qfrc_actuator[6:] (17),
    cfrc_ext[1:] (78)]`` with the ``include_*_in_observation`` switches of v5.

    Differences: ``cinert``, ``cvel`` and ``cfrc_ext`` are computed from ukemi's state
    (:func:`com_quantities`: velocities are midpoint velocities; contact wrenches come from
    ukemi's hard-contact impulses, which are impulsive at touchdown where MuJoCo's soft contact
    spreads the force over several steps). ``qfrc_actuator`` is ``gear · clip(ctrl)`` on each
    actuated dof, MuJoCo's value for these motors. Tendons of the MJCF have no actuator or
    limit here and are ignored (``info`` has no ``tendon_*`` entries). Contact is ukemi's
    hard contact; by default the solver uses contact activation
    (``solver_options={"activation_margin": 0.01}``), which changes cost, not the contacts
    enforced.
    """

    _view = ("xz", 1, 1.5)

    def __init__(self, xml_file: str = "humanoid.xml", frame_skip: int = 5,
                 forward_reward_weight: float = 1.25, ctrl_cost_weight: float = 0.1,
                 contact_cost_weight: float = 5e-7,
                 contact_cost_range: tuple[float, float] = (-np.inf, 10.0),
                 healthy_reward: float = 5.0, terminate_when_unhealthy: bool = True,
                 healthy_z_range: tuple[float, float] = (1.0, 2.0),
                 reset_noise_scale: float = 1e-2,
                 exclude_current_positions_from_observation: bool = True,
                 include_cinert_in_observation: bool = True,
                 include_cvel_in_observation: bool = True,
                 include_qfrc_actuator_in_observation: bool = True,
                 include_cfrc_ext_in_observation: bool = True,
                 solver_options: dict[str, Any] | None = None, **kwargs: Any) -> None:
        self._forward_reward_weight = forward_reward_weight
        self._ctrl_cost_weight = ctrl_cost_weight
        self._contact_cost_weight = contact_cost_weight
        self._contact_cost_range = contact_cost_range
        self._healthy_reward = healthy_reward
        self._terminate_when_unhealthy = terminate_when_unhealthy
        self._healthy_z_range = healthy_z_range
        self._reset_noise_scale = reset_noise_scale
        self._exclude = exclude_current_positions_from_observation
        self._include = (include_cinert_in_observation, include_cvel_in_observation,
                         include_qfrc_actuator_in_observation, include_cfrc_ext_in_observation)
        self._last_ctrl: np.ndarray | None = None
        solver_options = {"activation_margin": 0.01, **(solver_options or {})}
        super().__init__(xml_file, frame_skip, solver_options=solver_options, **kwargs)

    def _actuator_dofs(self) -> np.ndarray:
        if not hasattr(self, "_act_dofs"):
            index = dof_index(self.model)
            self._act_dofs = np.array([index[j] for j in self._info.actuator_joints])
        return self._act_dofs

    @property
    def qfrc_actuator(self) -> np.ndarray:
        """Generalized actuator forces of the last action (nv,): gear · clipped control."""
        out = np.zeros(self.model.nv)
        if self._last_ctrl is not None:
            lo, hi = np.asarray(self.model.actuator_ctrlrange).T
            ctrl = np.clip(self._last_ctrl, lo, hi)
            np.add.at(out, self._actuator_dofs(), np.asarray(self.model.actuator_gear) * ctrl)
        return out

    def mass_center(self) -> np.ndarray:
        """x, y of the centre of mass (MuJoCo's ``mass_center`` in humanoid_v5.py)."""
        mass = np.asarray(self.model.body_mass)
        return (mass[:, None] * np.asarray(self.state.com_pos)).sum(0)[:2] / mass.sum()

    @property
    def is_healthy(self) -> bool:
        lo, hi = self._healthy_z_range
        return bool(lo < self._x[2] < hi)

    @property
    def contact_cost(self) -> float:
        cost = self._contact_cost_weight * float(np.sum(np.square(com_quantities(self)["cfrc_ext"])))
        return float(np.clip(cost, *self._contact_cost_range))

    def _get_obs(self) -> np.ndarray:
        position = self.qpos[2:] if self._exclude else self.qpos
        parts = [position, self.qvel]
        q = com_quantities(self)
        cinert, cvel, qfrc, cfrc = self._include
        if cinert:
            parts.append(q["cinert"][1:].ravel())
        if cvel:
            parts.append(q["cvel"][1:].ravel())
        if qfrc:
            parts.append(self.qfrc_actuator[6:])
        if cfrc:
            parts.append(q["cfrc_ext"][1:].ravel())
        return np.concatenate(parts)

    def _snapshot(self) -> np.ndarray:
        return self.mass_center()

    def _reward(self, before, action):
        self._last_ctrl = np.asarray(action, np.float64)
        x_velocity, y_velocity = (self.mass_center() - before) / self.dt
        return planar_locomotion_reward(self, x_velocity, y_velocity, action)

    def _reset_model(self) -> None:
        self._last_ctrl = None
        s = self._reset_noise_scale
        self.set_state(self.init_qpos + self._uniform(s, self.model.nq),
                       self.init_qvel + self._uniform(s, self.model.nv))

    def _reset_info(self) -> dict[str, Any]:
        qpos = self.qpos
        return {"x_position": qpos[0], "y_position": qpos[1],
                "distance_from_origin": float(np.linalg.norm(qpos[0:2]))}
