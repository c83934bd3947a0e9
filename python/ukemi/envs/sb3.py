"""stable-baselines3 adapter: an SB3 ``VecEnv`` over ukemi's batched sub-envs.

SB3 does not accept gymnasium's ``VectorEnv``; this adapter gives SB3 the batched physics with
the conventions of SB3's ``DummyVecEnv``: auto-reset on the step an episode ends, the last
observation in ``info["terminal_observation"]`` and ``info["TimeLimit.truncated"] = truncated
and not terminated``. Importing this module imports stable_baselines3.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium
import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from .vector import BatchedEnvs


class UkemiSB3VecEnv(VecEnv):
    """``num_envs`` copies of a ukemi env as one SB3 ``VecEnv`` with batched physics.

    Args:
        env: Registered id (``"ukemi/Hopper-v0"``), ``"module:Class"`` or env class.
        num_envs: Number of sub-environments.
        max_episode_steps: Episode limit; by default the registered one (1000 for Hopper).
        seed: Seed of the first reset (sub-env ``i`` gets ``seed + i``), as ``VecEnv.seed``.
        **kwargs: Keyword arguments of the env class.

    Example::

        from stable_baselines3 import PPO
        venv = UkemiSB3VecEnv("ukemi/Hopper-v0", num_envs=8, seed=0)
        PPO("MlpPolicy", venv).learn(100_000)
    """

    def __init__(self, env: Any, num_envs: int, max_episode_steps: int | None = None,
                 seed: int | None = None, **kwargs: Any) -> None:
        if max_episode_steps is None and isinstance(env, str) and ":" not in env:
            max_episode_steps = gymnasium.spec(env).max_episode_steps
        self._batch = BatchedEnvs(env, num_envs, max_episode_steps, **kwargs)
        self.envs = self._batch.envs
        first = self.envs[0]
        super().__init__(self._batch.num_envs, first.observation_space, first.action_space)
        self.metadata = first.metadata
        self.render_mode = first.render_mode
        self._actions: np.ndarray | None = None
        if seed is not None:
            self.seed(seed)

    def reset(self) -> np.ndarray:
        obs = np.zeros((self.num_envs, *self.observation_space.shape), np.float64)
        for i in range(self.num_envs):
            obs[i], self.reset_infos[i] = self._batch.reset_one(i, self._seeds[i], self._options[i] or None)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self):
        assert self._actions is not None, "step_async must be called before step_wait"
        rows = np.arange(self.num_envs)
        results = self._batch.step_rows(rows, self._actions.reshape(self.num_envs, -1))
        obs = np.zeros((self.num_envs, *self.observation_space.shape), np.float64)
        rewards = np.zeros(self.num_envs, np.float32)
        dones = np.zeros(self.num_envs, bool)
        infos: list[dict[str, Any]] = []
        for i, (o, r, term, trunc, info) in enumerate(results):
            rewards[i], dones[i] = r, term or trunc
            info["TimeLimit.truncated"] = trunc and not term
            if dones[i]:
                info["terminal_observation"] = o
                o, self.reset_infos[i] = self._batch.reset_one(i)
            obs[i] = o
            infos.append(info)
        self._actions = None
        return obs, rewards, dones, infos

    def close(self) -> None:
        for e in self.envs:
            e.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [e.render() for e in self.envs]

    def _targets(self, indices) -> list:
        if indices is None:
            indices = range(self.num_envs)
        elif isinstance(indices, int):
            indices = [indices]
        return [self.envs[i] for i in indices]

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(e, attr_name) for e in self._targets(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        for e in self._targets(indices):
            setattr(e, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        return [getattr(e, method_name)(*method_args, **method_kwargs) for e in self._targets(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._targets(indices)]
