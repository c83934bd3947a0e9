"""Register ukemi's environments with gymnasium under the ``ukemi/`` namespace.

Called by ``import ukemi``; it imports gymnasium only (entry points are strings, the env
modules load on ``gymnasium.make``).
"""

from __future__ import annotations

from typing import Any

#: (name, entry point, max_episode_steps, reward_threshold), as gymnasium's envs of the same name
ENVS: tuple[tuple[str, str, int, float | None], ...] = (
    ("Pendulum", "ukemi.envs.classic:PendulumEnv", 200, None),
    ("CartPole", "ukemi.envs.classic:CartPoleEnv", 500, 475.0),
    ("InvertedPendulum", "ukemi.envs.pendulums:InvertedPendulumEnv", 1000, 950.0),
    ("InvertedDoublePendulum", "ukemi.envs.pendulums:InvertedDoublePendulumEnv", 1000, 9100.0),
    ("Reacher", "ukemi.envs.reacher:ReacherEnv", 50, -3.75),
    ("Hopper", "ukemi.envs.locomotion:HopperEnv", 1000, 3800.0),
    ("Walker2d", "ukemi.envs.locomotion:Walker2dEnv", 1000, None),
    ("HalfCheetah", "ukemi.envs.locomotion:HalfCheetahEnv", 1000, 4800.0),
    ("Ant", "ukemi.envs.ant:AntEnv", 1000, 6000.0),
    ("Humanoid", "ukemi.envs.humanoid:HumanoidEnv", 1000, None),
    ("BoxPush", "ukemi.envs.push:BoxPushEnv", 100, None),
    ("Quadruped", "ukemi.envs.quadruped:QuadrupedEnv", 1000, None),
)

ENV_IDS: tuple[str, ...] = tuple(f"ukemi/{name}-v0" for name, *_ in ENVS)


def _vector_entry(entry_point: str):
    def make(num_envs: int, **kwargs: Any):
        from .vector import UkemiVectorEnv

        return UkemiVectorEnv(entry_point, num_envs, **kwargs)

    return make


def register_envs() -> None:
    """Register every env id in :data:`ENV_IDS` (ids already registered are left alone)."""
    import gymnasium

    for (name, entry_point, steps, threshold), env_id in zip(ENVS, ENV_IDS, strict=True):
        if env_id in gymnasium.registry:
            continue
        gymnasium.register(id=env_id, entry_point=entry_point, max_episode_steps=steps,
                           reward_threshold=threshold, vector_entry_point=_vector_entry(entry_point))
