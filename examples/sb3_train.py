"""Train stable-baselines3 agents on ukemi envs and on gymnasium's counterparts, same budget.

For every (env, algorithm) pair, trains on the ukemi env and on its gymnasium counterpart
(MuJoCo v5 env of the same name, or classic-control ``Pendulum-v1`` for ``ukemi/Pendulum-v0``)
with the same algorithm, hyperparameters, seed and number of steps, in the same run. Prints
each learning curve (mean return of the last episodes against environment steps) and the
final deterministic evaluation return, and saves all curves as one PNG (a panel per pair).

Run:
    .venv/bin/python examples/sb3_train.py                     # PPO and SAC on Hopper and Pendulum
    .venv/bin/python examples/sb3_train.py --reduced           # CI: a few hundred steps each
    .venv/bin/python examples/sb3_train.py --envs ukemi/Hopper-v0 --algos SAC --timesteps 50000
    .venv/bin/python examples/sb3_train.py --envs ukemi/BoxPush-v0 --no-reference
(``--no-reference`` skips the gymnasium runs; MuJoCo counterparts need the mujoco package.)
Budgets that learn well are 10⁵–10⁶ steps; the default (5,000) shows the pipeline, not a policy.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import ukemi  # noqa: F401  (registers the ukemi/ envs)


#: gymnasium counterparts that are not "<name>-v5" (None: no counterpart)
_REFERENCE = {"Pendulum": "Pendulum-v1", "CartPole": None, "BoxPush": None, "Quadruped": None}


def reference_env(env_id: str) -> str | None:
    """``ukemi/Hopper-v0`` -> ``Hopper-v5``, ``ukemi/Pendulum-v0`` -> ``Pendulum-v1``."""
    name = env_id.split("/")[-1].rsplit("-", 1)[0]
    return _REFERENCE.get(name, f"{name}-v5")


def train(env_id: str, algo: str, timesteps: int, seed: int, n_envs: int, eval_episodes: int = 5,
          n_steps: int = 512):
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    torch.set_num_threads(1)
    if algo == "PPO":
        venv = make_vec_env(env_id, n_envs=n_envs, seed=seed)
        model = PPO("MlpPolicy", venv, seed=seed, n_steps=n_steps, batch_size=min(128, n_steps), n_epochs=5,
                    learning_rate=1e-3, device="cpu")
    else:
        venv = make_vec_env(env_id, n_envs=1, seed=seed)
        model = SAC("MlpPolicy", venv, seed=seed, learning_starts=min(1000, timesteps // 4),
                    device="cpu")
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
    final, final_std = evaluate_policy(model, eval_env, n_eval_episodes=eval_episodes, deterministic=True)
    return steps, returns, final, final_std, wall


def smooth(x: np.ndarray, k: int = 10) -> np.ndarray:
    return np.array([x[max(0, i - k + 1) : i + 1].mean() for i in range(len(x))])


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", nargs="+", default=["ukemi/Hopper-v0", "ukemi/Pendulum-v0"])
    p.add_argument("--algos", nargs="+", default=["PPO", "SAC"], choices=["PPO", "SAC"])
    p.add_argument("--timesteps", type=int, default=5_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-envs", type=int, default=4, help="PPO only")
    p.add_argument("--reduced", action="store_true",
                   help="CI budget: 400 steps per run (PPO: 2 envs x 100-step rollouts), 1 evaluation episode")
    p.add_argument("--no-reference", action="store_true", help="skip the gymnasium runs")
    p.add_argument("--out", default="sb3_learning_curve.png")
    args = p.parse_args()
    timesteps, n_envs, episodes, n_steps = args.timesteps, args.n_envs, 5, 512
    if args.reduced:
        timesteps, n_envs, episodes, n_steps = 400, 2, 1, 100

    runs: dict[tuple[str, str], dict[str, tuple]] = {}
    for env_id in args.envs:
        for algo in args.algos:
            ids = [env_id] + ([] if args.no_reference or reference_env(env_id) is None
                              else [reference_env(env_id)])
            runs[env_id, algo] = {i: train(i, algo, timesteps, args.seed, n_envs, episodes, n_steps)
                                for i in ids}
    for (env_id, algo), pair in runs.items():
        for run_id, (steps, returns, final, std, wall) in pair.items():
            print(f"\n{run_id} {algo}, {timesteps} steps, {wall:.1f} s "
                  f"({timesteps / wall:.0f} steps/s including learning)")
            print("  steps    mean return (last 10 episodes)")
            curve = smooth(returns) if len(returns) else returns
            for i in np.unique(np.linspace(0, len(steps) - 1, 12).astype(int)) if len(steps) else []:
                print(f"  {steps[i]:7d}  {curve[i]:9.1f}")
            print(f"  final deterministic return ({episodes} episodes): {final:.1f} ± {std:.1f}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(runs), figsize=(5 * len(runs), 3.8), squeeze=False)
    for ax, ((env_id, algo), pair) in zip(axes[0], runs.items(), strict=True):
        for run_id, (steps, returns, final, *_rest) in pair.items():
            if len(steps):
                ax.plot(steps, smooth(returns), label=f"{run_id} (final {final:.0f})")
        ax.set_title(f"{algo} on {env_id.split('/')[-1]}, seed {args.seed}")
        ax.set_xlabel("environment steps")
        ax.set_ylabel("episode return (mean of last 10)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=100)
    print(f"\nlearning curves saved to {args.out}")
    print("command: .venv/bin/python examples/sb3_train.py --envs " + " ".join(args.envs)
          + " --algos " + " ".join(args.algos) + f" --timesteps {timesteps} --seed {args.seed}"
          + (" --reduced" if args.reduced else "") + (" --no-reference" if args.no_reference else ""))
    return runs


if __name__ == "__main__":
    main()
