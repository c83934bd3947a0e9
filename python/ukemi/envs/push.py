"""BoxPush: ukemi's own manipulation task — a planar two-link arm pushes a free box across a
floor to a goal (the box-pushing setting of the Dojo paper, with a learned pusher)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ._assets import rotate
from .base import UkemiMujocoEnv

MODEL = Path(__file__).resolve().parents[1] / "models" / "box_pusher.xml"


def box_yaw(quat: np.ndarray) -> float:
    """Heading of a (w, x, y, z) orientation about z (rad)."""
    w, x, y, z = quat
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


class BoxPushEnv(UkemiMujocoEnv):
    """Push the box to the goal (``ukemi/BoxPush-v0``).

    Model: ``ukemi.models.box_pusher`` — shoulder and elbow hinges about z (motors, gear 5,
    action Box(−1, 1, (2,))), a spherical fingertip, a free 0.5 kg, 0.2 m box with friction 0.5
    on the floor, hard contact. ``frame_skip=5`` at the model's 0.01 s (dt = 0.05 s), 100-step
    limit (5 s), never terminated.

    Reward: ``−|box_xy − goal| − ctrl_cost_weight·|a|²`` (``ctrl_cost_weight`` = 0.1); the
    distance is after the step. ``info``: ``distance``, ``reward_dist``, ``reward_ctrl``,
    ``is_success`` (distance < ``success_radius`` = 0.05 m) and the contact forces.

    Observation (17,): ``[cos q_arm (2), sin q_arm (2), q̇_arm (2), box_xy (2), cos/sin of the
    box yaw (2), box linear velocity xy (2), box yaw rate (1), fingertip_xy − box_xy (2),
    goal − box_xy (2)]``.

    Reset: arm angles from the reference pose plus U(±``reset_noise_scale`` = 0.05) rad, at
    rest; box at its reference pose (x = 1.03 m); goal uniform in the sector of radius
    [0.8, 1.1] m and bearing ±30° about the shoulder — inside the arm's reach (the box centre
    cannot pass 1.15 m).
    """

    _view = ("xy", None, 1.0)

    def __init__(self, xml_file: str = str(MODEL), frame_skip: int = 5,
                 ctrl_cost_weight: float = 0.1, reset_noise_scale: float = 0.05,
                 goal_radius: tuple[float, float] = (0.8, 1.1), goal_bearing: float = np.pi / 6,
                 success_radius: float = 0.05, **kwargs: Any) -> None:
        self._ctrl_cost_weight = ctrl_cost_weight
        self._reset_noise_scale = reset_noise_scale
        self._goal_radius, self._goal_bearing = goal_radius, goal_bearing
        self._success_radius = success_radius
        self.goal = np.array([1.0, 0.0])
        super().__init__(xml_file, frame_skip, **kwargs)

    def fingertip_xy(self) -> np.ndarray:
        """World x, y of the fingertip sphere's centre."""
        s = self.state
        i = self._body_index["forearm"]
        return (s.body_pos[i] + rotate(s.body_quat[i], np.array([0.5, 0.0, 0.0])))[:2]

    def box_xy(self) -> np.ndarray:
        return self._x[2:4].copy()

    def _get_obs(self) -> np.ndarray:
        qpos, qvel = self.qpos, self.qvel
        arm, box = qpos[:2], qpos[2:4]
        yaw = box_yaw(qpos[5:9])
        return np.concatenate([np.cos(arm), np.sin(arm), qvel[:2], box, [np.cos(yaw), np.sin(yaw)],
                               qvel[2:4], qvel[7:8], self.fingertip_xy() - box, self.goal - box])

    def _reward(self, before, action):
        distance = float(np.linalg.norm(self.box_xy() - self.goal))
        ctrl_cost = self._ctrl_cost_weight * float(np.sum(np.square(action)))
        info = {"distance": distance, "reward_dist": -distance, "reward_ctrl": -ctrl_cost,
                "is_success": distance < self._success_radius}
        return -distance - ctrl_cost, False, info

    def _reset_model(self) -> None:
        qpos = self.init_qpos.copy()
        qpos[:2] += self._uniform(self._reset_noise_scale, 2)
        r = self.np_random.uniform(*self._goal_radius)
        bearing = self.np_random.uniform(-self._goal_bearing, self._goal_bearing)
        self.goal = r * np.array([np.cos(bearing), np.sin(bearing)])
        self.set_state(qpos, self.init_qvel)

    def _reset_info(self) -> dict[str, Any]:
        return {"distance": float(np.linalg.norm(self.box_xy() - self.goal)), "goal": self.goal.copy()}
