"""Quadruped on gymnasium's ant.xml: Ant-v5 on ukemi, without the contact-force terms."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import UnsupportedError
from .base import UkemiMujocoEnv


class AntEnv(UkemiMujocoEnv):
    """Four-legged walker (gymnasium ``Ant-v5`` on ukemi).

    Same as v5: ``ant.xml``, ``frame_skip=5`` (dt = 0.05 s), action Box(-1, 1, (8,)),
    reward ``ẋ(main body) + 1·healthy − 0.5·|a|² − contact cost``, healthy iff the state is
    finite and z = qpos[2] in [0.2, 1.0], terminated when unhealthy, reset noise uniform ±0.1
    on qpos and 0.1·N(0, 1) on qvel, 1000-step limit.

    Differences: MuJoCo's ``cfrc_ext`` (per-body external contact wrenches, 13×6 = 78 numbers)
    has no ukemi counterpart on the env's flat-state path, so the observation is
    ``[qpos[2:], qvel]`` (27,) as v5 with ``include_cfrc_ext_in_observation=False`` (passing
    True raises ``ukemi.UnsupportedError``), and the contact cost is 0 (``info["reward_contact"]``
    is 0.0; in MuJoCo it is at most 5e-4·78 ≈ 0.04 per step). Contact is ukemi's hard contact.
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
                 include_cfrc_ext_in_observation: bool = False, **kwargs: Any) -> None:
        if include_cfrc_ext_in_observation:
            raise UnsupportedError("unsupported: `include_cfrc_ext_in_observation=True` (ukemi's "
                                   "envs do not provide MuJoCo's cfrc_ext contact wrenches)")
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

    def _get_obs(self) -> np.ndarray:
        position = self.qpos[2:] if self._exclude_current_positions_from_observation else self.qpos
        return np.concatenate((position, self.qvel))

    def _reward(self, before, action):
        x_velocity, y_velocity = (self._main_xy() - before) / self.dt
        forward_reward = x_velocity * self._forward_reward_weight
        healthy_reward = self.is_healthy * self._healthy_reward
        ctrl_cost = self._ctrl_cost_weight * float(np.sum(np.square(action)))
        terminated = (not self.is_healthy) and self._terminate_when_unhealthy
        qpos = self.qpos
        info = {"x_position": qpos[0], "y_position": qpos[1],
                "distance_from_origin": float(np.linalg.norm(qpos[0:2])),
                "x_velocity": x_velocity, "y_velocity": y_velocity,
                "reward_forward": forward_reward, "reward_ctrl": -ctrl_cost, "reward_contact": 0.0,
                "reward_survive": healthy_reward}
        return forward_reward + healthy_reward - ctrl_cost, terminated, info

    def _reset_model(self) -> None:
        s = self._reset_noise_scale
        self.set_state(self.init_qpos + self._uniform(s, self.model.nq),
                       self.init_qvel + s * self.np_random.standard_normal(self.model.nv))

    def _reset_info(self) -> dict[str, Any]:
        qpos = self.qpos
        return {"x_position": qpos[0], "y_position": qpos[1],
                "distance_from_origin": float(np.linalg.norm(qpos[0:2]))}
