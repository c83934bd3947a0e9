"""Quadruped on gymnasium's ant.xml: Ant-v5 on ukemi, contact-force observation and cost included."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._com import cfrc_ext
from .base import UkemiMujocoEnv, planar_locomotion_reward


class AntEnv(UkemiMujocoEnv):
    """Four-legged walker (gymnasium ``Ant-v5`` on ukemi).

    Same as v5: ``ant.xml``, ``frame_skip=5`` (dt = 0.05 s), action Box(-1, 1, (8,)),
    reward ``ẋ(main body) + 1·healthy − 0.5·|a|² − 5e-4·|clip(cfrc_ext, −1, 1)|²``, healthy iff
    the state is finite and z = qpos[2] in [0.2, 1.0], terminated when unhealthy, reset noise
    uniform ±0.1 on qpos and 0.1·N(0, 1) on qvel, 1000-step limit. Observation (105,) =
    ``[qpos[2:] (13), qvel (14), clip(cfrc_ext[1:], −1, 1) (78)]``; (27,) with
    ``include_cfrc_ext_in_observation=False`` (the contact cost stays in the reward, as in v5).

    ``cfrc_ext`` is MuJoCo's per-body external contact wrench (torque about the ant's centre
    of mass, force; world axes), built from ukemi's contact impulses / time step of the last
    engine step (:mod:`ukemi.envs._com`). Contact is ukemi's hard contact, MuJoCo's is soft, so
    the numbers differ in motion; at rest both carry the weight (the totals agree to 1e-6, the
    split between feet need not: four feet on a plane are statically indeterminate).
    """

    _view = ("xz", 1, 1.5)

    def __init__(self, xml_file: str = "ant.xml", frame_skip: int = 5,
                 forward_reward_weight: float = 1.0, ctrl_cost_weight: float = 0.5,
                 contact_cost_weight: float = 5e-4, healthy_reward: float = 1.0,
                 main_body: int | str = 1, terminate_when_unhealthy: bool = True,
                 healthy_z_range: tuple[float, float] = (0.2, 1.0),
                 contact_force_range: tuple[float, float] = (-1.0, 1.0),
                 reset_noise_scale: float = 0.1,
                 exclude_current_positions_from_observation: bool = True,
                 include_cfrc_ext_in_observation: bool = True, **kwargs: Any) -> None:
        self._forward_reward_weight = forward_reward_weight
        self._ctrl_cost_weight = ctrl_cost_weight
        self._contact_cost_weight = contact_cost_weight
        self._healthy_reward = healthy_reward
        self._main_body = main_body
        self._terminate_when_unhealthy = terminate_when_unhealthy
        self._healthy_z_range = healthy_z_range
        self._contact_force_range = contact_force_range
        self._reset_noise_scale = reset_noise_scale
        self._exclude_current_positions_from_observation = exclude_current_positions_from_observation
        self._include_cfrc_ext_in_observation = include_cfrc_ext_in_observation
        super().__init__(xml_file, frame_skip, **kwargs)

    def _main_xy(self) -> np.ndarray:
        b = self._main_body
        index = b if isinstance(b, (int, np.integer)) else self._body_index[b]
        return self.state.body_pos[index, :2].copy()

    @property
    def is_healthy(self) -> bool:
        lo, hi = self._healthy_z_range
        return bool(np.isfinite(self._x).all() and lo <= self._x[2] <= hi)

    def _snapshot(self) -> np.ndarray:
        return self._main_xy()

    @property
    def cfrc_ext(self) -> np.ndarray:
        """MuJoCo's ``cfrc_ext`` of the last env step, unclipped, (nbody, 6). v5's
        ``contact_forces`` is ``np.clip(env.cfrc_ext, *contact_force_range)`` here: in ukemi's
        envs ``contact_forces`` is the per-candidate force of ``info["contact_forces"]``."""
        return cfrc_ext(self)

    def _clipped_cfrc_ext(self) -> np.ndarray:
        return np.clip(self.cfrc_ext, *self._contact_force_range)

    @property
    def contact_cost(self) -> float:
        """``contact_cost_weight · |clip(cfrc_ext)|²`` of the last env step."""
        return self._contact_cost_weight * float(np.sum(np.square(self._clipped_cfrc_ext())))

    def _get_obs(self) -> np.ndarray:
        position = self.qpos[2:] if self._exclude_current_positions_from_observation else self.qpos
        if self._include_cfrc_ext_in_observation:
            return np.concatenate((position, self.qvel, self._clipped_cfrc_ext()[1:].ravel()))
        return np.concatenate((position, self.qvel))

    def _reward(self, before, action):
        x_velocity, y_velocity = (self._main_xy() - before) / self.dt
        return planar_locomotion_reward(self, x_velocity, y_velocity, action)

    def _reset_model(self) -> None:
        s = self._reset_noise_scale
        self.set_state(self.init_qpos + self._uniform(s, self.model.nq),
                       self.init_qvel + s * self.np_random.standard_normal(self.model.nv))

    def _reset_info(self) -> dict[str, Any]:
        qpos = self.qpos
        return {"x_position": qpos[0], "y_position": qpos[1],
                "distance_from_origin": float(np.linalg.norm(qpos[0:2]))}
