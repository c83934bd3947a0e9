"""Environment steps per second: ukemi's gymnasium envs against gymnasium's MuJoCo v5 envs.

Same task, same control rate (dt), random actions, autoreset; single env (``gymnasium.make``)
and vector envs of N copies (ukemi: ``gymnasium.make_vec`` with batched physics in one Rust
call; MuJoCo: ``SyncVectorEnv``). ``--timestep`` adds a ukemi run at a larger engine time step
with a smaller frame_skip at the same dt. Numbers are printed, not asserted.

Run: .venv/bin/python examples/benchmarks/env_throughput.py [--envs Hopper InvertedPendulum]
     [--steps 300] [--num-envs 8]
Envs: any registered ``ukemi/<name>-v0``; the reference is ``<name>-v5``, ``Pendulum-v1`` for
Pendulum, and none for CartPole (gymnasium's is discrete), BoxPush and Quadruped (ukemi's own).
"""

from __future__ import annotations

import argparse
import time
import warnings

import gymnasium as gym
import numpy as np

import ukemi  # noqa: F401  (registers the ukemi/ envs)


def rate_single(env_id: str, steps: int, **kwargs) -> float:
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(steps)]
    t = time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t)


def rate_vector(env_id: str, steps: int, num_envs: int, mode: str, **kwargs) -> float:
    venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode, **kwargs)
    venv.reset(seed=0)
    venv.action_space.seed(0)
    actions = [venv.action_space.sample() for _ in range(steps)]
    t = time.perf_counter()
    for a in actions:
        venv.step(a)
    return steps * num_envs / (time.perf_counter() - t)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", nargs="+", default=["InvertedPendulum", "Reacher", "Hopper", "HalfCheetah"])
    p.add_argument("--steps", type=int, default=300, help="env steps per measurement")
    p.add_argument("--num-envs", type=int, nargs="+", default=[8])
    p.add_argument("--timestep", action="store_true",
                   help="also time ukemi at 2x the engine time step, half the frame_skip")
    args = p.parse_args()
    warnings.simplefilter("ignore")  # solver-failure warnings are counted by the tests, not here
    try:
        import mujoco  # noqa: F401
        has_mujoco = True
    except ImportError:
        has_mujoco = False

    references = {"Pendulum": "Pendulum-v1", "CartPole": None, "BoxPush": None, "Quadruped": None}
    print(f"{'env':<22}{'engine':<26}{'N':>4}{'env steps/s':>14}")
    for name in args.envs:
        ours, ref = f"ukemi/{name}-v0", references.get(name, f"{name}-v5")
        has_ref = ref is not None and (has_mujoco or not ref.endswith("-v5"))
        rows = [(ours, "ukemi", 1, rate_single(ours, args.steps))]
        if has_ref:
            rows.append((ref, "gymnasium", 1, rate_single(ref, args.steps)))
        for n in args.num_envs:
            rows.append((ours, "ukemi (batched)", n, rate_vector(ours, args.steps, n, "vector_entry_point")))
            if has_ref:
                rows.append((ref, "gymnasium (SyncVectorEnv)", n, rate_vector(ref, args.steps, n, "sync")))
        if args.timestep:
            env = gym.make(ours).unwrapped
            if env.frame_skip % 2 == 0:
                kw = {"timestep": 2 * env.model.timestep, "frame_skip": env.frame_skip // 2}
                rows.append((ours, f"ukemi h={kw['timestep']:g}", 1, rate_single(ours, args.steps, **kw)))
        for env_id, engine, n, rate in rows:
            print(f"{name:<22}{engine:<26}{n:>4}{rate:>14.0f}")
    print("\ncommand: .venv/bin/python examples/benchmarks/env_throughput.py "
          + " ".join(["--envs", *args.envs, "--steps", str(args.steps), "--num-envs",
                      *map(str, args.num_envs)] + (["--timestep"] if args.timestep else [])))


if __name__ == "__main__":
    main()
