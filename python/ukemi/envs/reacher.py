"""Two-link planar arm reaching a random target: gymnasium's Reacher-v5 on the same MJCF."""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import UkemiMujocoEnv


class ReacherEnv(UkemiMujocoEnv):
    """Move the fingertip to the target (gymnasium ``Reacher-v5`` on ukemi).

    Same as v5: ``reacher.xml``, ``frame_skip=2`` (dt = 0.02 s), action Box(-1, 1, (2,)),
    observation (10,) ``[cos θ, sin θ, target xy, joint rates, (fingertip − target)[:2]]``,
    reward ``−|fingertip − target|·w_dist − |a|²·w_ctrl``, never terminated, 50-step limit,
    reset: qpos uniform ±0.1, target uniform in the disc of radius 0.2, qvel uniform ±0.005
    (target at rest). Body positions are body-frame origins as MuJoCo's ``xpos``.
    """

    _view = ("xy", None, 0.25)

    def __init__(self, xml_file: str = "reacher.xml", frame_skip: int = 2,
                 reward_dist_weight: float = 1.0, reward_control_weight: float = 1.0,
                 **kwargs: Any) -> None:
        self._reward_dist_weight = reward_dist_weight
        self._reward_control_weight = reward_control_weight
        super().__init__(xml_file, frame_skip, **kwargs)

    def _fingertip_to_target(self) -> np.ndarray:
        return self.body_xpos("fingertip") - self.body_xpos("target")

    def _get_obs(self) -> np.ndarray:
        qpos, qvel = self.qpos, self.qvel
        theta = qpos[:2]
        return np.concatenate([np.cos(theta), np.sin(theta), qpos[2:], qvel[:2],
                               self._fingertip_to_target()[:2]])

    def _reward(self, before, action):
        reward_dist = -np.linalg.norm(self._fingertip_to_target()) * self._reward_dist_weight
        reward_ctrl = -np.square(action).sum() * self._reward_control_weight
        return reward_dist + reward_ctrl, False, {"reward_dist": reward_dist, "reward_ctrl": reward_ctrl}

    def _reset_model(self) -> None:
        qpos = self.np_random.uniform(low=-0.1, high=0.1, size=self.model.nq) + self.init_qpos
        while True:
            self.goal = self.np_random.uniform(low=-0.2, high=0.2, size=2)
            if np.linalg.norm(self.goal) < 0.2:
                break
        qpos[-2:] = self.goal
        qvel = self.init_qvel + self.np_random.uniform(low=-0.005, high=0.005, size=self.model.nv)
        qvel[-2:] = 0
        self.set_state(qpos, qvel)
