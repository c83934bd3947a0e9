"""Quadruped: ukemi's own legged-locomotion task on the zoo's A1-sized quadruped."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from ._assets import rotate
from .base import UkemiMujocoEnv

MODEL = Path(__file__).resolve().parents[1] / "models" / "quadruped.xml"


class QuadrupedEnv(UkemiMujocoEnv):
    """Walk forward (``ukemi/Quadruped-v0``) on ``ukemi.models.quadruped``.

    Model: box trunk on a free joint, four legs (hip abduction, hip flexion, knee) with position
    servos (kp 40), spherical feet, hard contact with friction 0.8. ``frame_skip=2`` at the
    model's 0.01 s (dt = 0.02 s, 50 Hz control), 1000-step limit.

    Action Box(−1, 1, (12,)): joint targets relative to the ``"stand"`` keyframe,
    ``ctrl = clip(ctrl_stand + action_scale·a, ctrlrange)`` with ``action_scale`` = 0.3 rad.

    Reward: ``forward_reward_weight·ẋ + healthy_reward·healthy − ctrl_cost_weight·|a|²``
    (1.0, 1.0, 0.05) with ẋ the trunk's x velocity over the env step. Healthy iff the state is
    finite, trunk height z in ``healthy_z_range`` = (0.2, 0.6) m and the trunk's up axis has
    z component > ``min_upright`` = 0.5 (tilt < 60°); terminated when unhealthy.

    Observation (35,): ``[qpos[2:] (17), qvel (18)]`` (``exclude_current_positions_from_
    observation=False`` keeps x, y). Reset: the ``"stand"`` keyframe with joint angles and all
    velocities uniform ±``reset_noise_scale`` (0.05). By default the solver uses contact
    activation (``solver_options={"activation_margin": 0.01}``: candidates far from touching
    are left out of a step's solve), which makes standing steps ~10× cheaper without changing
    which contacts are enforced.
    """

    _view = ("xz", 1, 0.8)

    def __init__(self, xml_file: str = str(MODEL), frame_skip: int = 2,
                 forward_reward_weight: float = 1.0, healthy_reward: float = 1.0,
                 ctrl_cost_weight: float = 0.05, action_scale: float = 0.3,
                 healthy_z_range: tuple[float, float] = (0.2, 0.6), min_upright: float = 0.5,
                 terminate_when_unhealthy: bool = True, reset_noise_scale: float = 0.05,
                 exclude_current_positions_from_observation: bool = True,
                 solver_options: dict[str, Any] | None = None, **kwargs: Any) -> None:
        self._forward_reward_weight = forward_reward_weight
        self._healthy_reward = healthy_reward
        self._ctrl_cost_weight = ctrl_cost_weight
        self._action_scale = action_scale
        self._healthy_z_range = healthy_z_range
        self._min_upright = min_upright
        self._terminate_when_unhealthy = terminate_when_unhealthy
        self._reset_noise_scale = reset_noise_scale
        self._exclude = exclude_current_positions_from_observation
        solver_options = {"activation_margin": 0.01, **(solver_options or {})}
        super().__init__(xml_file, frame_skip, solver_options=solver_options, **kwargs)
        key = list(self.model.keyframe_names).index("stand")
        self.init_qpos = np.array(self.model.key_qpos[key], dtype=np.float64)
        self._ctrl_stand = np.array(self.model.key_ctrl[key], dtype=np.float64)
        self._set_x(np.concatenate([self.init_qpos, self.init_qvel]))
        self.action_space = spaces.Box(-1.0, 1.0, (self.model.nu,), np.float32)

    def _ctrl(self, action: np.ndarray) -> np.ndarray:
        lo, hi = np.asarray(self.model.actuator_ctrlrange).T
        return np.clip(self._ctrl_stand + self._action_scale * action, lo, hi)

    @property
    def upright(self) -> float:
        """z component of the trunk's up axis (1 upright, −1 upside down)."""
        return float(rotate(self._x[3:7], np.array([0.0, 0.0, 1.0]))[2])

    @property
    def is_healthy(self) -> bool:
        lo, hi = self._healthy_z_range
        return bool(np.isfinite(self._x).all() and lo < self._x[2] < hi
                    and self.upright > self._min_upright)

    def _get_obs(self) -> np.ndarray:
        position = self.qpos[2:] if self._exclude else self.qpos
        return np.concatenate([position, self.qvel])

    def _reward(self, before, action):
        x_velocity = (self.qpos[0] - before[0]) / self.dt
        forward_reward = self._forward_reward_weight * x_velocity
        healthy_reward = self.is_healthy * self._healthy_reward
        ctrl_cost = self._ctrl_cost_weight * float(np.sum(np.square(action)))
        terminated = (not self.is_healthy) and self._terminate_when_unhealthy
        info = {"x_position": self.qpos[0], "y_position": self.qpos[1], "x_velocity": x_velocity,
                "reward_forward": forward_reward, "reward_survive": healthy_reward,
                "reward_ctrl": -ctrl_cost}
        return forward_reward + healthy_reward - ctrl_cost, terminated, info

    def _reset_model(self) -> None:
        s = self._reset_noise_scale
        qpos = self.init_qpos.copy()
        qpos[7:] += self._uniform(s, self.model.nq - 7)
        self.set_state(qpos, self.init_qvel + self._uniform(s, self.model.nv))

    def _reset_info(self) -> dict[str, Any]:
        return {"x_position": self.qpos[0], "y_position": self.qpos[1]}
