"""gymnasium environments on ukemi physics, mirroring gymnasium's MuJoCo v5 tasks.

``import ukemi`` registers ``ukemi/InvertedPendulum-v0``, ``ukemi/InvertedDoublePendulum-v0``,
``ukemi/Reacher-v0``, ``ukemi/Hopper-v0``, ``ukemi/Walker2d-v0``, ``ukemi/HalfCheetah-v0`` and
``ukemi/Ant-v0`` (when gymnasium is installed)::

    import gymnasium, ukemi
    env = gymnasium.make("ukemi/Hopper-v0")                 # single env (TimeLimit 1000)
    venv = gymnasium.make_vec("ukemi/Hopper-v0", num_envs=8) # batched physics in one Rust call
    from ukemi.envs.sb3 import UkemiSB3VecEnv                # SB3 VecEnv with batched physics

Each env uses the same MJCF asset, observation layout, action space, reward terms, termination
rule, reset noise and ``frame_skip`` as the v5 env of the same name; the docstring of each
class lists what differs (contact model, MuJoCo-only quantities such as ``cfrc_ext``). A step
whose solve fails truncates the episode with ``info["solver_status"]``
(:mod:`ukemi.envs.base`). Swimmer is not provided: it needs fluid forces (MJCF ``density`` and
``viscosity``) that ukemi does not model, so it could not swim. Humanoid loads and runs but is
slow (about 10 ms per engine step) and is not registered yet.

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
    "UkemiSB3VecEnv": "sb3",
}

__all__ = ["ENV_IDS", "register_envs", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'ukemi.envs' has no attribute {name!r}")
