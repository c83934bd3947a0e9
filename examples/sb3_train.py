"""Train a stable-baselines3 agent on a ukemi env and on gymnasium's MuJoCo counterpart.

Prints the learning curve (mean return of the last episodes against environment steps) of
each run, the final deterministic evaluation return, and saves both curves as a PNG.

Run (reduced default budget, about a minute on 2 cores):
    .venv/bin/python examples/sb3_train.py
    .venv/bin/python examples/sb3_train.py --env ukemi/Hopper-v0 --algo SAC --timesteps 50000
    .venv/bin/python examples/sb3_train.py --env ukemi/InvertedPendulum-v0 --no-mujoco
(``--no-mujoco`` skips the MuJoCo comparison run; it needs the mujoco package.)
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import ukemi  # noqa: F401  (registers the ukemi/ envs)


def mujoco_counterpart(env_id: str) -> str:
    """``ukemi/Hopper-v0`` -> ``Hopper-v5``."""
    return env_id.split("/")[-1].rsplit("-", 1)[0] + "-v5"


def train(env_id: str, algo: str, timesteps: int, seed: int, n_envs: int):
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    torch.set_num_threads(1)
    if algo == "PPO":
        venv = make_vec_env(env_id, n_envs=n_envs, seed=seed)
        model = PPO("MlpPolicy", venv, seed=seed, n_steps=512, batch_size=128, n_epochs=5,
                    learning_rate=1e-3, device="cpu")
    else:
        venv = make_vec_env(env_id, n_envs=1, seed=seed)
        model = SAC("MlpPolicy", venv, seed=seed, learning_starts=1000, device="cpu")
    t0 = time.perf_counter()
    model.learn(timesteps)
    wall = time.perf_counter() - t0
    # learning curve from the Monitor wrappers: (cumulative steps, episode return)
    monitors = [e for e in venv.envs if isinstance(e, Monitor)]
    episodes = sorted((t, r, n) for m in monitors
                      for t, r, n in zip(m.get_episode_times(), m.get_episode_rewards(),
                                         m.get_episode_lengths(), strict=True))
    steps = np.cumsum([n for _, _, n in episodes])
    returns = np.array([r for _, r, _ in episodes])
    eval_env = Monitor(gym.make(env_id))
    final, final_std = evaluate_policy(model, eval_env, n_eval_episodes=5, deterministic=True)
    return steps, returns, final, final_std, wall


def smooth(x: np.ndarray, k: int = 10) -> np.ndarray:
    return np.array([x[max(0, i - k + 1) : i + 1].mean() for i in range(len(x))])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--env", default="ukemi/InvertedPendulum-v0")
    p.add_argument("--algo", default="PPO", choices=["PPO", "SAC"])
    p.add_argument("--timesteps", type=int, default=20_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-envs", type=int, default=4, help="PPO only")
    p.add_argument("--no-mujoco", action="store_true", help="skip the MuJoCo comparison run")
    p.add_argument("--out", default="sb3_learning_curve.png")
    args = p.parse_args()

    runs = {args.env: train(args.env, args.algo, args.timesteps, args.seed, args.n_envs)}
    if not args.no_mujoco:
        runs[mujoco_counterpart(args.env)] = train(mujoco_counterpart(args.env), args.algo,
                                                   args.timesteps, args.seed, args.n_envs)
    for env_id, (steps, returns, final, std, wall) in runs.items():
        print(f"\n{env_id} {args.algo}, {args.timesteps} steps, {wall:.1f} s "
              f"({args.timesteps / wall:.0f} steps/s including learning)")
        print("  steps    mean return (last 10 episodes)")
        curve = smooth(returns)
        for i in np.unique(np.linspace(0, len(steps) - 1, 12).astype(int)):
            print(f"  {steps[i]:7d}  {curve[i]:9.1f}")
        print(f"  final deterministic return (5 episodes): {final:.1f} ± {std:.1f}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for env_id, (steps, returns, *_rest) in runs.items():
        ax.plot(steps, smooth(returns), label=env_id)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episode return (mean of last 10)")
    ax.set_title(f"{args.algo}, seed {args.seed}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"\nlearning curve saved to {args.out}")
    print(f"command: .venv/bin/python examples/sb3_train.py --env {args.env} --algo {args.algo} "
          f"--timesteps {args.timesteps} --seed {args.seed}")


if __name__ == "__main__":
    main()
