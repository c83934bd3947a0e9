"""Batched vector environment: N copies of one ukemi env stepped in one Rust call.

The full engine states of all sub-environments are the rows of one ``EnvStates`` and are
stepped by a single call (parallel in Rust, GIL released); observations, rewards and
terminations are computed per sub-env by the same code as the single env, so sub-env ``i``
reproduces a single env seeded with ``seed + i`` and given the same actions, number for
number.
"""

from __future__ import annotations

import importlib
from typing import Any

import gymnasium
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from .. import _ukemi
from ._physics import step_rows
from .base import UkemiMujocoEnv


def resolve_env_class(env: str | type[UkemiMujocoEnv]) -> type[UkemiMujocoEnv]:
    """An env class from itself, ``"module:Class"`` or a registered id (``"ukemi/Hopper-v0"``)."""
    if isinstance(env, type):
        return env
    if ":" not in env:
        env = gymnasium.spec(env).entry_point
    module, name = env.split(":")
    return getattr(importlib.import_module(module), name)


class BatchedEnvs:
    """N sub-envs with batched physics and per-env time limits; no autoreset (the gymnasium
    and SB3 front ends add their own)."""

    def __init__(self, env: str | type[UkemiMujocoEnv], num_envs: int,
                 max_episode_steps: int | None = None, **kwargs: Any) -> None:
        if int(num_envs) < 1:
            raise ValueError(f"`num_envs` must be >= 1, got {num_envs!r}")
        cls = resolve_env_class(env)
        self.envs = [cls(**kwargs) for _ in range(int(num_envs))]
        self.num_envs = len(self.envs)
        self.max_episode_steps = max_episode_steps
        self.elapsed = np.zeros(self.num_envs, dtype=np.int64)
        first = self.envs[0]
        self.model, self.frame_skip = first.model, first.frame_skip
        self.states = _ukemi.EnvStates(self.model, self.num_envs)
        for i, e in enumerate(self.envs):
            e._attach(self.states, i)

    def reset_one(self, i: int, seed: int | None = None, options: dict | None = None):
        self.elapsed[i] = 0
        return self.envs[i].reset(seed=seed, options=options)

    def step_rows(self, rows: np.ndarray, actions: np.ndarray) -> list[tuple]:
        """Step the sub-envs ``rows`` with ``actions`` (len(rows), nu) in one physics call.
        Returns one ``(obs, reward, terminated, truncated, info)`` per row."""
        envs = [self.envs[i] for i in rows]
        acts = [e._check_action(a) for e, a in zip(envs, actions, strict=True)]
        befores = [e._snapshot() for e in envs]
        ctrls = np.stack([e._ctrl(a) for e, a in zip(envs, acts, strict=True)])
        phys = step_rows(self.states, rows, ctrls, self.frame_skip)
        out = []
        for k, i in enumerate(rows):
            obs, rew, term, trunc, info = envs[k]._after_physics(acts[k], befores[k],
                                                                 *(p[k] for p in phys))
            self.elapsed[i] += 1
            if self.max_episode_steps is not None and self.elapsed[i] >= self.max_episode_steps:
                trunc = True
            out.append((obs, rew, term, trunc, info))
        return out


class UkemiVectorEnv(VectorEnv):
    """A gymnasium ``VectorEnv`` of ``num_envs`` copies of a ukemi env with batched physics.

    Made by ``gymnasium.make_vec("ukemi/Hopper-v0", num_envs=8)`` (the registered
    ``vector_entry_point``), or directly.

    Args:
        env: Env class, ``"module:Class"`` or registered id.
        num_envs: Number of sub-environments.
        max_episode_steps: Truncate each episode after this many steps (the registered limit
            when made through ``make_vec``); None for no limit.
        autoreset_mode: ``AutoresetMode.NEXT_STEP`` (gymnasium's default: the step after an
            episode ends resets that sub-env and ignores its action), ``SAME_STEP`` (reset at
            once; the final observation and info are in ``info["final_obs"]`` and
            ``info["final_info"]``) or ``DISABLED`` (reset with ``options={"reset_mask": m}``).
        **kwargs: Keyword arguments of the env class (``frame_skip``, ``timestep``, ...).

    Seeding: ``reset(seed=s)`` seeds sub-env ``i`` with ``s + i`` (a list gives one seed each).
    """

    def __init__(self, env: str | type[UkemiMujocoEnv], num_envs: int,
                 max_episode_steps: int | None = None,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 render_mode: str | None = None, **kwargs: Any) -> None:
        self._batch = BatchedEnvs(env, num_envs, max_episode_steps, render_mode=render_mode, **kwargs)
        self.envs = self._batch.envs
        self.num_envs = self._batch.num_envs
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        first = self.envs[0]
        self.render_mode = render_mode
        self.metadata = {**first.metadata, "autoreset_mode": self.autoreset_mode}
        self.single_observation_space = first.observation_space
        self.single_action_space = first.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._obs = np.zeros((self.num_envs, *self.single_observation_space.shape), np.float64)

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None):
        if seed is None or isinstance(seed, (int, np.integer)):
            seeds = [None if seed is None else int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"`seed` has {len(seeds)} entries for {self.num_envs} envs")
        if seed is not None:
            self._np_random, self._np_random_seed = gymnasium.utils.seeding.np_random(
                seeds[0] if isinstance(seed, list) else int(seed))
        options = dict(options or {})
        mask = np.asarray(options.pop("reset_mask", np.ones(self.num_envs, bool)), dtype=bool)
        infos: dict[str, Any] = {}
        for i in np.flatnonzero(mask):
            self._obs[i], info = self._batch.reset_one(int(i), seeds[i], options or None)
            infos = self._add_info(infos, info, int(i))
        self._autoreset[mask] = False
        return self._obs.copy(), infos

    def step(self, actions):
        actions = np.asarray(actions)
        n = self.num_envs
        rewards, terms, truncs = np.zeros(n), np.zeros(n, bool), np.zeros(n, bool)
        infos: dict[str, Any] = {}
        resetting = self._autoreset if self.autoreset_mode == AutoresetMode.NEXT_STEP else np.zeros(n, bool)
        for i in np.flatnonzero(resetting):
            self._obs[i], info = self._batch.reset_one(int(i))
            infos = self._add_info(infos, info, int(i))
        rows = np.flatnonzero(~resetting)
        results = self._batch.step_rows(rows, actions[rows]) if len(rows) else []
        for i, (obs, rew, term, trunc, info) in zip(rows, results, strict=True):
            i = int(i)
            rewards[i], terms[i], truncs[i] = rew, term, trunc
            if self.autoreset_mode == AutoresetMode.SAME_STEP and (term or trunc):
                reset_obs, reset_info = self._batch.reset_one(i)
                infos = self._add_info(infos, {"final_obs": obs, "final_info": info, **reset_info}, i)
                obs = reset_obs
            else:
                infos = self._add_info(infos, info, i)
            self._obs[i] = obs
        self._autoreset = terms | truncs
        return self._obs.copy(), rewards, terms, truncs, infos

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        return tuple(e.render() for e in self.envs)
