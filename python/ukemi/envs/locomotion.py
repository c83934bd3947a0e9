"""Planar runners on gymnasium's MJCF assets: Hopper-v5, Walker2d-v5 and HalfCheetah-v5.

Reward ``forward_reward_weight · ẋ + healthy_reward · healthy − ctrl_cost_weight · |a|²`` with
``ẋ = (qpos[0]_after − qpos[0]_before) / dt``; observation ``[qpos[1:], qvel]`` (Hopper and
Walker2d clip qvel to ±10; ``exclude_current_positions_from_observation=False`` keeps
qpos[0]). Contact is ukemi's hard contact (Dojo: signed distance ≥ 0 at the next
configuration, exact friction cone, perfectly inelastic impacts) instead of MuJoCo's soft
contact, so gaits, returns and episode lengths are comparable but not equal to MuJoCo's.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import UkemiMujocoEnv


class _PlanarRunnerEnv(UkemiMujocoEnv):
    _view = ("xz", 1, 1.5)
    _clip_qvel = True

    def __init__(self, xml_file: str, frame_skip: int, *, forward_reward_weight: float,
                 ctrl_cost_weight: float, healthy_reward: float, terminate_when_unhealthy: bool,
                 reset_noise_scale: float, exclude_current_positions_from_observation: bool,
                 **kwargs: Any) -> None:
        self._forward_reward_weight = forward_reward_weight
        self._ctrl_cost_weight = ctrl_cost_weight
        self._healthy_reward = healthy_reward
        self._terminate_when_unhealthy = terminate_when_unhealthy
        self._reset_noise_scale = reset_noise_scale
        self._exclude_current_positions_from_observation = exclude_current_positions_from_observation
        super().__init__(xml_file, frame_skip, **kwargs)

    @property
    def is_healthy(self) -> bool:
        return True

    @property
    def healthy_reward(self) -> float:
        return self.is_healthy * self._healthy_reward

    def control_cost(self, action) -> float:
        return self._ctrl_cost_weight * float(np.sum(np.square(action)))

    def _get_obs(self) -> np.ndarray:
        position = self.qpos
        velocity = np.clip(self.qvel, -10, 10) if self._clip_qvel else self.qvel
        if self._exclude_current_positions_from_observation:
            position = position[1:]
        return np.concatenate((position, velocity))

    def _reward(self, before, action):
        x_velocity = (self.qpos[0] - before[0]) / self.dt
        forward_reward = self._forward_reward_weight * x_velocity
        healthy_reward = self.healthy_reward
        ctrl_cost = self.control_cost(action)
        terminated = (not self.is_healthy) and self._terminate_when_unhealthy
        info = {"x_position": self.qpos[0], "z_distance_from_origin": self.qpos[1] - self.init_qpos[1],
                "x_velocity": x_velocity, "reward_forward": forward_reward, "reward_ctrl": -ctrl_cost,
                "reward_survive": healthy_reward}
        return forward_reward + healthy_reward - ctrl_cost, terminated, info

    def _reset_model(self) -> None:
        s = self._reset_noise_scale
        self.set_state(self.init_qpos + self._uniform(s, self.model.nq),
                       self.init_qvel + self._uniform(s, self.model.nv))

    def _reset_info(self) -> dict[str, Any]:
        return {"x_position": self.qpos[0], "z_distance_from_origin": self.qpos[1] - self.init_qpos[1]}


class HopperEnv(_PlanarRunnerEnv):
    """One-legged hopper (gymnasium ``Hopper-v5`` on ukemi).

    Same as v5: ``hopper.xml``, ``frame_skip=4`` (dt = 0.008 s), action Box(-1, 1, (3,)),
    observation (11,), reward ``ẋ + 1·healthy − 1e-3·|a|²``, healthy iff all of
    ``state_vector()[2:]`` in (−100, 100), z = qpos[1] in (0.7, ∞) and angle = qpos[2] in
    (−0.2, 0.2); terminated when unhealthy; reset noise uniform ±0.005 on qpos and qvel;
    1000-step limit. Differences: hard contact (module docstring).
    """

    def __init__(self, xml_file: str = "hopper.xml", frame_skip: int = 4,
                 forward_reward_weight: float = 1.0, ctrl_cost_weight: float = 1e-3,
                 healthy_reward: float = 1.0, terminate_when_unhealthy: bool = True,
                 healthy_state_range: tuple[float, float] = (-100.0, 100.0),
                 healthy_z_range: tuple[float, float] = (0.7, float("inf")),
                 healthy_angle_range: tuple[float, float] = (-0.2, 0.2),
                 reset_noise_scale: float = 5e-3,
                 exclude_current_positions_from_observation: bool = True, **kwargs: Any) -> None:
        self._healthy_state_range = healthy_state_range
        self._healthy_z_range = healthy_z_range
        self._healthy_angle_range = healthy_angle_range
        super().__init__(xml_file, frame_skip, forward_reward_weight=forward_reward_weight,
                         ctrl_cost_weight=ctrl_cost_weight, healthy_reward=healthy_reward,
                         terminate_when_unhealthy=terminate_when_unhealthy,
                         reset_noise_scale=reset_noise_scale,
                         exclude_current_positions_from_observation=exclude_current_positions_from_observation,
                         **kwargs)

    @property
    def is_healthy(self) -> bool:
        z, angle = self.qpos[1:3]
        state = self._x[2:]
        lo, hi = self._healthy_state_range
        healthy_state = bool(np.all((lo < state) & (state < hi)))
        return (healthy_state and self._healthy_z_range[0] < z < self._healthy_z_range[1]
                and self._healthy_angle_range[0] < angle < self._healthy_angle_range[1])


class Walker2dEnv(_PlanarRunnerEnv):
    """Two-legged planar walker (gymnasium ``Walker2d-v5`` on ukemi).

    Same as v5: ``walker2d_v5.xml``, ``frame_skip=4`` (dt = 0.008 s), action Box(-1, 1, (6,)),
    observation (17,), reward ``ẋ + 1·healthy − 1e-3·|a|²``, healthy iff z in (0.8, 2.0) and
    angle in (−1, 1); reset noise uniform ±0.005; 1000-step limit. Differences: hard contact.
    """

    def __init__(self, xml_file: str = "walker2d_v5.xml", frame_skip: int = 4,
                 forward_reward_weight: float = 1.0, ctrl_cost_weight: float = 1e-3,
                 healthy_reward: float = 1.0, terminate_when_unhealthy: bool = True,
                 healthy_z_range: tuple[float, float] = (0.8, 2.0),
                 healthy_angle_range: tuple[float, float] = (-1.0, 1.0),
                 reset_noise_scale: float = 5e-3,
                 exclude_current_positions_from_observation: bool = True, **kwargs: Any) -> None:
        self._healthy_z_range = healthy_z_range
        self._healthy_angle_range = healthy_angle_range
        super().__init__(xml_file, frame_skip, forward_reward_weight=forward_reward_weight,
                         ctrl_cost_weight=ctrl_cost_weight, healthy_reward=healthy_reward,
                         terminate_when_unhealthy=terminate_when_unhealthy,
                         reset_noise_scale=reset_noise_scale,
                         exclude_current_positions_from_observation=exclude_current_positions_from_observation,
                         **kwargs)

    @property
    def is_healthy(self) -> bool:
        z, angle = self.qpos[1:3]
        return (self._healthy_z_range[0] < z < self._healthy_z_range[1]
                and self._healthy_angle_range[0] < angle < self._healthy_angle_range[1])


class HalfCheetahEnv(_PlanarRunnerEnv):
    """Planar cheetah (gymnasium ``HalfCheetah-v5`` on ukemi).

    Same as v5: ``half_cheetah.xml``, ``frame_skip=5`` (dt = 0.05 s), action Box(-1, 1, (6,)),
    observation ``[qpos[1:], qvel]`` (17,) unclipped, reward ``ẋ − 0.1·|a|²``, never
    terminated, reset noise uniform ±0.1 on qpos and 0.1·N(0, 1) on qvel, 1000-step limit.
    ``info`` has no ``reward_survive``/``z_distance_from_origin`` entries in v5; here they are
    present (0 and the z offset). Differences: hard contact.
    """

    _clip_qvel = False

    def __init__(self, xml_file: str = "half_cheetah.xml", frame_skip: int = 5,
                 forward_reward_weight: float = 1.0, ctrl_cost_weight: float = 0.1,
                 reset_noise_scale: float = 0.1,
                 exclude_current_positions_from_observation: bool = True, **kwargs: Any) -> None:
        super().__init__(xml_file, frame_skip, forward_reward_weight=forward_reward_weight,
                         ctrl_cost_weight=ctrl_cost_weight, healthy_reward=0.0,
                         terminate_when_unhealthy=False, reset_noise_scale=reset_noise_scale,
                         exclude_current_positions_from_observation=exclude_current_positions_from_observation,
                         **kwargs)

    def _reset_model(self) -> None:
        s = self._reset_noise_scale
        self.set_state(self.init_qpos + self._uniform(s, self.model.nq),
                       self.init_qvel + s * self.np_random.standard_normal(self.model.nv))
