"""Environment steps per second: ukemi's gymnasium envs against gymnasium's MuJoCo v5 envs.

Same task, same control rate (env dt), uniformly random actions from fixed seeds, autoreset.
For each env: a single env (``gymnasium.make``) and vector envs of N copies (ukemi:
``gymnasium.make_vec`` with its batched physics, one Rust call per step over the full engine
states; MuJoCo: ``gymnasium.make_vec(..., vectorization_mode="sync")``). "env steps/s" counts
sub-env steps (N per vector step). The last rows run ukemi at a larger engine time step with a
smaller frame_skip at the same dt (half the frame_skip when it is even, else one engine step
per env step) and report solver failures there: a failed solve truncates the episode, so
"fail" says whether that time step is usable. Numbers are printed, not asserted.

Run: .venv/bin/python examples/benchmarks/env_throughput.py [--quick]
     [--envs Hopper HalfCheetah Ant Humanoid] [--num-envs 1 8 64] [--seconds 2]
     .venv/bin/python examples/benchmarks/env_throughput.py --failures 250
     (solver failures of Quadruped, Walker2d and Ant under random actions instead)
Envs: any registered ``ukemi/<name>-v0``; the reference is ``<name>-v5`` (``Pendulum-v1`` for
Pendulum; none for CartPole, BoxPush and Quadruped).
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import gymnasium as gym
import numpy as np

import ukemi

REFERENCES = {"Pendulum": "Pendulum-v1", "CartPole": None, "BoxPush": None, "Quadruped": None}


def _failures(info, n: int) -> int:
    """Solver failures reported in a (vector) step's info (0 for MuJoCo)."""
    status = info.get("solver_status")
    if status is None:
        return 0
    if n == 1 and isinstance(status, str):
        return int(status not in ukemi.SUCCESS_STATUSES)
    mask = info.get("_solver_status", np.ones(n, bool))
    return int(sum(m and s not in ukemi.SUCCESS_STATUSES for s, m in zip(status, mask, strict=True)))


def rate_single(env_id: str, seconds: float, **kwargs) -> tuple[float, int, int]:
    """(env steps/s, steps, solver failures) of one env, random actions, reset when done."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    env.action_space.seed(0)
    env.step(env.action_space.sample())  # warm-up
    steps = fails = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds or steps < 2:
        _, _, term, trunc, info = env.step(env.action_space.sample())
        steps += 1
        fails += _failures(info, 1)
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t0), steps, fails


def rate_vector(env_id: str, seconds: float, num_envs: int, mode: str, **kwargs) -> tuple[float, int, int]:
    """(sub-env steps/s, sub-env steps, solver failures) of a vector env."""
    venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode=mode, **kwargs)
    venv.reset(seed=0)
    venv.action_space.seed(0)
    venv.step(venv.action_space.sample())
    steps = fails = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds or steps < 2:
        *_, info = venv.step(venv.action_space.sample())
        steps += 1
        fails += _failures(info, num_envs)
    venv.close()
    return steps * num_envs / (time.perf_counter() - t0), steps * num_envs, fails


def coarse_step(env_id: str) -> dict[str, float] | None:
    """A larger engine time step at the same dt: half the frame_skip if even, else 1."""
    env = gym.make(env_id).unwrapped
    fs, h = env.frame_skip, env.model.timestep
    if fs == 1:
        return None
    new_fs = fs // 2 if fs % 2 == 0 else 1
    return {"timestep": h * fs / new_fs, "frame_skip": new_fs}


def failure_rates(names: list[str], num_envs: int, steps: int, coarse: bool) -> None:
    """Solver failures under uniformly random actions: a vector env of ``num_envs`` (seed 0,
    autoreset) stepped ``steps`` times per env; with ``coarse`` also at :func:`coarse_step`."""
    print("failed: env steps whose solve failed (each truncates its episode); statuses: every "
          "env step's solver status")
    print(f"{'env':<12}{'h, frame_skip':<16}{'env steps':>10}{'failed':>8}{'per 1000':>10}{'episodes':>10}  statuses")
    runs = [(name, {}) for name in names]
    if coarse:
        runs = [r for name in names for r in ((name, {}), (name, coarse_step(f"ukemi/{name}-v0")))
                if r[1] is not None]
    for name, kwargs in runs:
        venv = gym.make_vec(f"ukemi/{name}-v0", num_envs=num_envs, vectorization_mode="vector_entry_point",
                            **kwargs)
        base = venv.envs[0]
        config = f"{base.model.timestep:g} s, {base.frame_skip}"
        venv.reset(seed=0)
        venv.action_space.seed(0)
        failed = episodes = 0
        statuses: dict[str, int] = {}
        for _ in range(steps):
            *_, term, trunc, info = venv.step(venv.action_space.sample())
            for i, s in enumerate(info["solver_status"]):
                if info["_solver_status"][i]:
                    statuses[s] = statuses.get(s, 0) + 1
            failed += _failures(info, num_envs)
            episodes += int(np.sum(term | trunc))
        total = steps * num_envs
        shown = ", ".join(f"{k} {v}" for k, v in sorted(statuses.items()))
        print(f"{name:<12}{config:<16}{total:>10}{failed:>8}{1e3 * failed / total:>10.1f}{episodes:>10}  {shown}",
              flush=True)
    print(f"command: .venv/bin/python examples/benchmarks/env_throughput.py --failures {steps} "
          f"--envs {' '.join(names)} --num-envs {num_envs}" + (" --coarse" if coarse else ""))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--envs", nargs="+", help="default Hopper HalfCheetah Ant Humanoid "
                   "(Quadruped Walker2d Ant with --failures)")
    p.add_argument("--num-envs", type=int, nargs="+", help="default 1 8 64 (8 with --failures)")
    p.add_argument("--seconds", type=float, default=2.0, help="wall time per measurement")
    p.add_argument("--quick", action="store_true", help="Hopper only, N = 1 and 8, 0.3 s each")
    p.add_argument("--failures", type=int, metavar="STEPS",
                   help="instead: count solver failures over STEPS random-action steps of a vector "
                        "env of --num-envs (first value) per env (default envs Quadruped Walker2d Ant)")
    p.add_argument("--coarse", action="store_true",
                   help="with --failures: also at the larger engine time step of the throughput table")
    args = p.parse_args()
    if args.failures:
        warnings.simplefilter("ignore")
        failure_rates(args.envs or ["Quadruped", "Walker2d", "Ant"], (args.num_envs or [8])[0],
                      args.failures, args.coarse)
        return
    args.envs = args.envs or ["Hopper", "HalfCheetah", "Ant", "Humanoid"]
    args.num_envs = args.num_envs or [1, 8, 64]
    if args.quick:
        args.envs, args.num_envs, args.seconds = ["Hopper"], [1, 8], 0.3
    warnings.simplefilter("ignore")  # solver failures are counted in the table instead
    try:
        import mujoco  # noqa: F401
        has_mujoco = True
    except ImportError:
        has_mujoco = False

    print(f"{os.cpu_count()} CPUs, {ukemi.get_num_threads()} ukemi threads; "
          f"{args.seconds:g} s per measurement")
    header = f"{'env':<12}{'N':>4}{'dt (ms)':>9}  {'ukemi h, frame_skip':<22}{'ukemi/s':>10}{'fail':>6}{'MuJoCo/s':>11}{'ratio':>8}"
    print(header)
    print("-" * len(header))
    for name in args.envs:
        ours, ref = f"ukemi/{name}-v0", REFERENCES.get(name, f"{name}-v5")
        has_ref = ref is not None and (has_mujoco or not ref.endswith("-v5"))
        env = gym.make(ours).unwrapped
        dt, h, fs = env.dt, env.model.timestep, env.frame_skip
        configs = [({}, h, fs)]
        coarse = coarse_step(ours)
        if coarse is not None:
            configs.append((coarse, coarse["timestep"], coarse["frame_skip"]))
        for kwargs, hh, ff in configs:
            for n in [0, *args.num_envs]:  # 0: the single env
                if n == 0:
                    rate, _, fails = rate_single(ours, args.seconds, **kwargs)
                    ref_rate = rate_single(ref, args.seconds)[0] if has_ref and not kwargs else None
                else:
                    rate, _, fails = rate_vector(ours, args.seconds, n, "vector_entry_point", **kwargs)
                    ref_rate = (rate_vector(ref, args.seconds, n, "sync")[0]
                                if has_ref and not kwargs else None)
                label = "1" if n == 0 else f"{n}v"
                ref_cell = f"{ref_rate:>11.0f}{rate / ref_rate:>8.3f}" if ref_rate else f"{'':>11}{'':>8}"
                print(f"{name:<12}{label:>4}{1e3 * dt:>9.3g}  {f'{hh:g} s, {ff}':<22}"
                      f"{rate:>10.0f}{fails:>6}{ref_cell}", flush=True)
    print("\nN = 1: gymnasium.make; Nv: vector env of N (ukemi: batched make_vec, MuJoCo: "
          "make_vec sync). ratio = ukemi / MuJoCo env steps per second at the same dt. "
          "fail: solver failures (truncated episodes) during the ukemi run.")
    print("command: .venv/bin/python examples/benchmarks/env_throughput.py "
          + ("--quick" if args.quick else " ".join(
              ["--envs", *args.envs, "--num-envs", *map(str, args.num_envs), "--seconds", str(args.seconds)])))


if __name__ == "__main__":
    main()
