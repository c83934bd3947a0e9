"""The gym tasks as pure, differentiable functions for analytic policy gradients (JAX or torch).

``make_task("ukemi/Pendulum-v0", backend="jax")`` returns a :class:`Task` built from the same
env class (same model, ``frame_skip``, action-to-control map, reward weights) whose functions
act on the flat state ``x = [qpos, qvel]`` (..., nq + nv) and action ``u`` (..., nu):

* ``task.step(x, u) -> x_next``: ``frame_skip`` calls of ``ukemi.jax.step`` /
  ``ukemi.torch.step`` (gradients by the engine's implicit function theorem at
  ``kappa_grad``; smoothing matters for contact tasks, not for the pendulums);
* ``task.reward(x, u, x_next)``: the env's reward of that transition (the env returns the same
  number, tests/test_envs.py);
* ``task.terminated(x_next)``: the env's termination rule (boolean array);
* ``task.reset_state(key)``: a state from the env's reset distribution (a ``jax.random`` key,
  or a ``torch.Generator``), not the same numbers as ``env.reset(seed=...)``.

Leading axes batch, and a batch is one engine call. Indicator terms (healthy rewards,
termination) are piecewise constant: their gradient is zero. Tasks: Pendulum, CartPole,
InvertedPendulum, Hopper, HalfCheetah, Ant, BoxPush, Quadruped (the others need body positions
from forward kinematics in the reward, which the flat-state API does not give).

Differences from the env. The env keeps its full engine state between engine steps (the
integrator's midpoint velocities and the solver's warm start); a flat step rebuilds the
maximal state from ``[qpos, qvel]`` and restarts the solver at every engine step. So an env
step from a fresh state (``env.set_state``) with ``frame_skip=1`` is ``task.step`` to the
solver tolerance, while over ``frame_skip`` engine steps the two drift apart by O(timestep)
(measured in tests/test_envs.py, largest entry of ``x_next`` after one env step: 7e-4
Pendulum, 1e-3 Hopper, 2e-2 Ant and Quadruped). Ant's task reward has no contact cost (the
flat state holds no contact forces): it is the env's with ``contact_cost_weight=0``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import gymnasium
import numpy as np

__all__ = ["Task", "make_task", "TASKS"]


class _Ops:
    """The few array operations the tasks need, for ``jax.numpy`` or ``torch``."""

    def __init__(self, backend: str) -> None:
        self.backend = backend
        if backend == "jax":
            import jax.numpy as jnp

            from .. import jax as uj

            self.xp, self.physics = jnp, uj
            self.cat = jnp.concatenate
        elif backend == "torch":
            import torch

            from .. import torch as ut

            self.xp, self.physics = torch, ut
            self.cat = torch.cat
        else:
            raise ValueError(f"`backend` must be 'jax' or 'torch', got {backend!r}")

    def const(self, a):
        a = np.asarray(a, np.float64)
        return self.xp.asarray(a) if self.backend == "jax" else self.xp.as_tensor(a)

    def uniform(self, key, low, high):
        low, high = np.asarray(low, np.float64), np.asarray(high, np.float64)
        if self.backend == "jax":
            import jax

            return jax.random.uniform(key, low.shape, minval=low, maxval=high, dtype=np.float64)
        import torch

        r = torch.rand(low.shape, generator=key, dtype=torch.float64)
        return self.const(low) + r * self.const(high - low)

    def normal(self, key, shape):
        if self.backend == "jax":
            import jax

            return jax.random.normal(key, shape, dtype=np.float64)
        import torch

        return torch.randn(shape, generator=key, dtype=torch.float64)

    def split(self, key):
        if self.backend == "jax":
            import jax

            return jax.random.split(key)
        return key, key  # a torch.Generator advances by itself


@dataclass
class Task:
    """One task's pure functions; see the module docstring. Attributes mirror the env's."""

    name: str
    model: Any
    frame_skip: int
    dt: float
    ops: _Ops
    _ctrl: Callable = field(repr=False)
    _reward: Callable = field(repr=False)
    _terminated: Callable = field(repr=False)
    _reset: Callable = field(repr=False)
    _post: Callable | None = field(default=None, repr=False)
    kappa_grad: float | None = 3e-4
    goal: Any = None

    def step(self, x, u):
        """``x_next`` (..., nq + nv) after one env step with action ``u`` (..., nu)."""
        ctrl = self._ctrl(self.ops, u)
        for _ in range(self.frame_skip):
            x = self.ops.physics.step(self.model, x, ctrl, kappa_grad=self.kappa_grad)
        return x if self._post is None else self._post(self.ops, x)

    def reward(self, x, u, x_next):
        """The env's reward of the transition ``(x, u) -> x_next``, shape (...)."""
        return self._reward(self, x, u, x_next)

    def terminated(self, x_next):
        """The env's termination rule at ``x_next``, shape (...), boolean."""
        return self._terminated(self, x_next)

    def reset_state(self, key):
        """A state (nq + nv,) from the env's reset distribution."""
        return self._reset(self, key)


# -- task definitions (xp = jax.numpy or torch) ----------------------------------------------
def _sq(o, a):
    return (a * a).sum(-1)


def _never(task, x):
    return task.ops.xp.zeros(x.shape[:-1], dtype=bool)


def _identity(o, u):
    return u


def _pendulum(env):
    lo, hi = -env.max_torque, env.max_torque

    def ctrl(o, u):
        return o.xp.clip(u, lo, hi)

    def post(o, x):  # gymnasium's speed limit on the new velocity
        return o.cat([x[..., :1], o.xp.clip(x[..., 1:], -env.max_speed, env.max_speed)], -1)

    def reward(t, x, u, x1):
        theta, theta_dot = x[..., 0], x[..., 1]
        th = t.ops.xp.remainder(theta + np.pi, 2 * np.pi) - np.pi
        uc = ctrl(t.ops, u)[..., 0]
        return -(th**2 + 0.1 * theta_dot**2 + 0.001 * uc**2)

    def reset(t, key):
        return t.ops.uniform(key, [-np.pi, -1.0], [np.pi, 1.0])

    return dict(_ctrl=ctrl, _reward=reward, _terminated=_never, _reset=reset, _post=post)


def _cartpole(env):
    def reward(t, x, u, x1):
        return t.ops.xp.ones(x1.shape[:-1], dtype=x1.dtype)

    def terminated(t, x1):
        return (abs(x1[..., 0]) > env.x_threshold) | (abs(x1[..., 1]) > env.theta_threshold)

    def reset(t, key):
        s = env._reset_noise_scale
        return t.ops.uniform(key, [-s] * 4, [s] * 4)

    return dict(_ctrl=_identity, _reward=reward, _terminated=terminated, _reset=reset)


def _inverted_pendulum(env):
    def terminated(t, x1):
        return (abs(x1[..., 1]) > 0.2) | ~t.ops.xp.isfinite(x1).all(-1)

    def reward(t, x, u, x1):
        return (~terminated(t, x1)).to(x1.dtype) if t.ops.backend == "torch" else \
            (~terminated(t, x1)).astype(x1.dtype)

    return dict(_ctrl=_identity, _reward=reward, _terminated=terminated,
                _reset=_uniform_reset(env, env._reset_noise_scale, env._reset_noise_scale))


def _uniform_reset(env, qpos_scale, qvel_scale, normal_qvel=False):
    qpos0, nv = np.asarray(env.init_qpos), env.model.nv

    def reset(t, key):
        k1, k2 = t.ops.split(key)
        q = t.ops.const(qpos0) + t.ops.uniform(k1, [-qpos_scale] * len(qpos0), [qpos_scale] * len(qpos0))
        v = (qvel_scale * t.ops.normal(k2, (nv,)) if normal_qvel
             else t.ops.uniform(k2, [-qvel_scale] * nv, [qvel_scale] * nv))
        return t.ops.cat([q, v], -1)

    return reset


def _as_float(t, b, like):
    return b.to(like.dtype) if t.ops.backend == "torch" else b.astype(like.dtype)


def _runner(env, healthy: Callable | None, normal_qvel: bool, x_index: int = 0):
    w_fwd, w_ctrl, w_alive = env._forward_reward_weight, env._ctrl_cost_weight, env._healthy_reward

    def is_healthy(t, x1):
        return t.ops.xp.ones(x1.shape[:-1], dtype=bool) if healthy is None else healthy(t, x1)

    def reward(t, x, u, x1):
        v = (x1[..., x_index] - x[..., x_index]) / t.dt
        return w_fwd * v + w_alive * _as_float(t, is_healthy(t, x1), x1) - w_ctrl * _sq(t.ops, u)

    def terminated(t, x1):
        unhealthy = ~is_healthy(t, x1)
        return unhealthy if env._terminate_when_unhealthy else unhealthy & False

    s = env._reset_noise_scale
    return dict(_ctrl=_identity, _reward=reward, _terminated=terminated,
                _reset=_uniform_reset(env, s, s, normal_qvel))


def _hopper(env):
    (slo, shi), (zlo, zhi), (alo, ahi) = (env._healthy_state_range, env._healthy_z_range,
                                          env._healthy_angle_range)

    def healthy(t, x1):
        state = x1[..., 2:]
        z, angle = x1[..., 1], x1[..., 2]
        return (((state > slo) & (state < shi)).all(-1) & (z > zlo) & (z < zhi)
                & (angle > alo) & (angle < ahi))

    return _runner(env, healthy, normal_qvel=False)


def _half_cheetah(env):
    return _runner(env, None, normal_qvel=True)


def _ant(env):
    lo, hi = env._healthy_z_range

    def healthy(t, x1):
        return t.ops.xp.isfinite(x1).all(-1) & (x1[..., 2] >= lo) & (x1[..., 2] <= hi)

    # the torso is the free joint's body, so its xpos is qpos[0:3] (main_body = 1); no
    # contact cost (see the module docstring)
    return _runner(env, healthy, normal_qvel=True)


def _box_push(env):
    w_ctrl = env._ctrl_cost_weight

    def reward(t, x, u, x1):
        d = x1[..., 2:4] - t.ops.const(t.goal)
        return -(d * d).sum(-1) ** 0.5 - w_ctrl * _sq(t.ops, u)

    def reset(t, key):
        q0 = np.asarray(env.init_qpos)
        s = env._reset_noise_scale
        arm = t.ops.const(q0[:2]) + t.ops.uniform(key, [-s, -s], [s, s])
        return t.ops.cat([arm, t.ops.const(q0[2:]), t.ops.const(np.zeros(env.model.nv))], -1)

    return dict(_ctrl=_identity, _reward=reward, _terminated=_never, _reset=reset)


def _quadruped(env):
    lo_c, hi_c = np.asarray(env.model.actuator_ctrlrange).T
    stand, scale = env._ctrl_stand, env._action_scale
    zlo, zhi = env._healthy_z_range

    def ctrl(o, u):
        c = o.const(stand) + scale * u
        return o.xp.minimum(o.xp.maximum(c, o.const(lo_c)), o.const(hi_c))

    def healthy(t, x1):
        w, qx, qy = x1[..., 3], x1[..., 4], x1[..., 5]
        upright = 1 - 2 * (qx * qx + qy * qy)  # z of the trunk's up axis (unit quaternion)
        z = x1[..., 2]
        return (t.ops.xp.isfinite(x1).all(-1) & (z > zlo) & (z < zhi)
                & (upright > env._min_upright) & (w == w))

    d = _runner(env, healthy, normal_qvel=False)
    d["_ctrl"] = ctrl

    def reset(t, key):
        k1, k2 = t.ops.split(key)
        q0, s, n = np.asarray(env.init_qpos), env._reset_noise_scale, env.model.nq - 7
        q = t.ops.cat([t.ops.const(q0[:7]), t.ops.const(q0[7:]) + t.ops.uniform(k1, [-s] * n, [s] * n)], -1)
        v = t.ops.uniform(k2, [-s] * env.model.nv, [s] * env.model.nv)
        return t.ops.cat([q, v], -1)

    d["_reset"] = reset
    return d


TASKS: dict[str, Callable] = {
    "Pendulum": _pendulum, "CartPole": _cartpole, "InvertedPendulum": _inverted_pendulum,
    "Hopper": _hopper, "HalfCheetah": _half_cheetah, "Ant": _ant, "BoxPush": _box_push,
    "Quadruped": _quadruped,
}


def make_task(env_id: str, backend: str = "jax", kappa_grad: float | None = 3e-4,
              goal=None, **env_kwargs: Any) -> Task:
    """The differentiable task of a registered env.

    Args:
        env_id: ``"ukemi/Pendulum-v0"`` (or ``"Pendulum"``); one of :data:`TASKS`.
        backend: ``"jax"`` or ``"torch"``.
        kappa_grad: Contact smoothing of the gradients (``ukemi.jax.step``); None: exact.
        goal: BoxPush's goal (2,) (default: the env's default goal).
        **env_kwargs: Keyword arguments of the env class (weights, ``frame_skip``, ...).

    Raises:
        ValueError: unknown task or backend.
    """
    name = env_id.split("/")[-1].rsplit("-v", 1)[0]
    if name not in TASKS:
        raise ValueError(f"`env_id` = {env_id!r}: no differentiable task; expected one of {sorted(TASKS)}")
    ops = _Ops(backend)
    env = gymnasium.make(f"ukemi/{name}-v0", **env_kwargs).unwrapped
    parts = TASKS[name](env)
    task = Task(name=name, model=env.model, frame_skip=env.frame_skip, dt=env.dt, ops=ops,
                kappa_grad=kappa_grad, goal=None if goal is None and name != "BoxPush"
                else np.asarray(env.goal if goal is None else goal, np.float64), **parts)
    env.close()
    return task
