"""Cart-pole balancing tasks: gymnasium's InvertedPendulum-v5 and InvertedDoublePendulum-v5
on the same MJCF assets."""

from __future__ import annotations

from typing import Any

import numpy as np

from .base import UkemiMujocoEnv


class InvertedPendulumEnv(UkemiMujocoEnv):
    """Balance a pole on a cart (gymnasium ``InvertedPendulum-v5`` on ukemi).

    Same as v5: ``inverted_pendulum.xml``, ``frame_skip=2`` (dt = 0.04 s), action
    Box(-3, 3, (1,)), observation ``[qpos, qvel]`` (4,), reward 1 per step while
    ``|qpos[1]| <= 0.2`` and the observation is finite (then terminated), reset noise uniform
    ±0.01 on qpos and qvel, 1000-step limit. Physics: ukemi's variational integrator with
    constraint joints (MuJoCo: Euler with generalized coordinates); the MJCF ``integrator``
    option is ignored. See :class:`ukemi.envs.base.UkemiMujocoEnv` for the common keywords
    (``timestep``, ``solver_options``, ``render_mode``) and for solver failures (truncation).
    """

    _view = ("xz", None, 1.5)

    def __init__(self, xml_file: str = "inverted_pendulum.xml", frame_skip: int = 2,
                 reset_noise_scale: float = 0.01, **kwargs: Any) -> None:
        self._reset_noise_scale = reset_noise_scale
        super().__init__(xml_file, frame_skip, **kwargs)

    def _get_obs(self) -> np.ndarray:
        return self._x.copy()

    def _reward(self, before, action):
        obs = self._get_obs()
        terminated = bool(not np.isfinite(obs).all() or abs(obs[1]) > 0.2)
        reward = int(not terminated)
        return reward, terminated, {"reward_survive": reward}

    def _reset_model(self) -> None:
        s = self._reset_noise_scale
        self.set_state(self.init_qpos + self._uniform(s, self.model.nq),
                       self.init_qvel + self._uniform(s, self.model.nv))


class InvertedDoublePendulumEnv(UkemiMujocoEnv):
    """Balance a double pole on a cart (gymnasium ``InvertedDoublePendulum-v5`` on ukemi).

    Same as v5: ``inverted_double_pendulum.xml``, ``frame_skip=5`` (dt = 0.05 s), action
    Box(-1, 1, (1,)), reward ``healthy_reward·alive − (0.01 x² + (y − 2)²) − (1e-3 v1² +
    5e-3 v2²)`` with ``(x, y)`` the world x/z of the ``tip`` site, terminated when ``y <= 1``,
    reset noise uniform ±0.1 on qpos and 0.1·N(0, 1) on qvel, 1000-step limit.

    Observation (9,): ``[qpos[0], sin(qpos[1:]), cos(qpos[1:]), clip(qvel, ±10),
    constraint force]``. Difference: the last entry is MuJoCo's ``qfrc_constraint[0]`` clipped
    to ±10, the slider's limit force; ukemi does not expose joint-limit forces per dof, so it
    is 0.0 here. In MuJoCo it is nonzero only while the cart presses on its rail end
    (``|qpos[0]| = 1``).
    """

    _view = ("xz", None, 2.0)

    def __init__(self, xml_file: str = "inverted_double_pendulum.xml", frame_skip: int = 5,
                 healthy_reward: float = 10.0, reset_noise_scale: float = 0.1,
                 **kwargs: Any) -> None:
        self._healthy_reward = healthy_reward
        self._reset_noise_scale = reset_noise_scale
        super().__init__(xml_file, frame_skip, **kwargs)

    def _get_obs(self) -> np.ndarray:
        qpos, qvel = self.qpos, self.qvel
        return np.concatenate([qpos[:1], np.sin(qpos[1:]), np.cos(qpos[1:]),
                               np.clip(qvel, -10, 10), [0.0]])

    def _reward(self, before, action):
        x, _, y = self.site_xpos("tip")
        terminated = bool(y <= 1)
        v1, v2 = self.qvel[1:3]
        dist_penalty = 0.01 * x**2 + (y - 2) ** 2
        vel_penalty = 1e-3 * v1**2 + 5e-3 * v2**2
        alive_bonus = self._healthy_reward * int(not terminated)
        info = {"reward_survive": alive_bonus, "distance_penalty": -dist_penalty,
                "velocity_penalty": -vel_penalty}
        return alive_bonus - dist_penalty - vel_penalty, terminated, info

    def _reset_model(self) -> None:
        s = self._reset_noise_scale
        self.set_state(self.init_qpos + self._uniform(s, self.model.nq),
                       self.init_qvel + self.np_random.standard_normal(self.model.nv) * s)
