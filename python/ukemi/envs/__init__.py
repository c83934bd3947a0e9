"""gymnasium environments on ukemi physics, mirroring gymnasium's MuJoCo v5 and classic tasks.

``import ukemi`` registers (when gymnasium is installed) ``ukemi/Pendulum-v0`` and a continuous
``ukemi/CartPole-v0`` (classic-control semantics, :mod:`ukemi.envs.classic`),
``ukemi/InvertedPendulum-v0``, ``ukemi/InvertedDoublePendulum-v0``, ``ukemi/Reacher-v0``,
``ukemi/Hopper-v0``, ``ukemi/Walker2d-v0``, ``ukemi/HalfCheetah-v0``, ``ukemi/Ant-v0`` and
``ukemi/Humanoid-v0`` (MuJoCo v5 semantics), and ukemi's own ``ukemi/BoxPush-v0`` and
``ukemi/Quadruped-v0``::

    import gymnasium, ukemi
    env = gymnasium.make("ukemi/Hopper-v0")                 # single env (TimeLimit 1000)
    venv = gymnasium.make_vec("ukemi/Hopper-v0", num_envs=8) # batched physics in one Rust call
    from ukemi.envs.sb3 import UkemiSB3VecEnv                # SB3 VecEnv with batched physics

Each env uses the same MJCF asset, observation layout, action space, reward terms, termination
rule, reset noise and ``frame_skip`` as the v5 env of the same name; the docstring of each
class lists what differs (contact model, MuJoCo quantities such as ``cfrc_ext`` rebuilt from
ukemi's contact impulses). Each env keeps its full engine state between steps, so its
trajectory is ``ukemi.rollout``'s under the same controls (:mod:`ukemi.envs.base`). A step
whose solve fails truncates the episode with ``info["solver_status"]``
(:mod:`ukemi.envs.base`); every step's ``info["contact_forces"]`` is the (ncontact, 3) contact
force per candidate (impulse / time step, contact frame). Swimmer is not provided: it needs
fluid forces (MJCF ``density`` and ``viscosity``) that ukemi does not model, so it could not
swim. :mod:`ukemi.envs.differentiable` gives the tasks' dynamics and rewards as JAX or torch
functions for analytic policy gradients.

Names here load lazily, so ``import ukemi.envs`` stays cheap.
"""

from __future__ import annotations

import importlib

from ._registration import ENV_IDS, register_envs

_LAZY = {
    "UkemiMujocoEnv": "base", "SolverFailureWarning": "base",
    "InvertedPendulumEnv": "pendulums", "InvertedDoublePendulumEnv": "pendulums",
    "ReacherEnv": "reacher", "HopperEnv": "locomotion", "Walker2dEnv": "locomotion",
    "HalfCheetahEnv": "locomotion", "AntEnv": "ant", "UkemiVectorEnv": "vector",
    "UkemiSB3VecEnv": "sb3", "PendulumEnv": "classic", "CartPoleEnv": "classic",
    "HumanoidEnv": "humanoid", "BoxPushEnv": "push", "QuadrupedEnv": "quadruped",
    "make_task": "differentiable",
}

__all__ = ["ENV_IDS", "register_envs", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'ukemi.envs' has no attribute {name!r}")
