"""gymnasium environments (issue #7): checkers, seeding, the batched vector env, agreement with
gymnasium's MuJoCo v5 envs on the first step, solver-failure truncation and an SB3 smoke run."""

from __future__ import annotations

import subprocess
import sys
import warnings

import numpy as np
import pytest

import ukemi

gym = pytest.importorskip("gymnasium")

from ukemi.envs import ENV_IDS  # noqa: E402
from ukemi.envs.base import SolverFailureWarning  # noqa: E402
from ukemi.envs.vector import UkemiVectorEnv  # noqa: E402


def _rollout(env, seed, actions):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, r, term, trunc, info = env.step(a)
        out.append(np.append(obs, r))
        if term or trunc:
            break
    return out


def test_import_registers_envs_cheaply():
    code = ("import sys, ukemi, gymnasium; print(sorted(i for i in gymnasium.registry if i.startswith('ukemi/'))); "
            "print([m for m in ('torch', 'jax', 'mujoco', 'stable_baselines3', 'ukemi.envs.base') if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.splitlines()
    assert eval(out[0]) == sorted(ENV_IDS)
    assert eval(out[1]) == [], f"import ukemi loaded heavy modules: {out[1]}"


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_check_env(env_id):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(env_id, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # no checker warnings beyond infinite bounds
        warnings.filterwarnings("ignore", message=".*infinity.*")
        # InvertedPendulum's action space is Box(-3, 3) as in gymnasium's v5 env
        warnings.filterwarnings("ignore", message=".*symmetric and normalized.*")
        warnings.filterwarnings("ignore", category=SolverFailureWarning)
        check_env(env.unwrapped)
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == (480, 480, 3)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_check_env(env_id):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SolverFailureWarning)
        sb3_checker.check_env(gym.make(env_id).unwrapped, warn=True)


@pytest.mark.filterwarnings("ignore::ukemi.envs.base.SolverFailureWarning")
@pytest.mark.parametrize("env_id", ["ukemi/Hopper-v0", "ukemi/Reacher-v0", "ukemi/Ant-v0"])
def test_same_seed_same_trajectory(env_id):
    env_a, env_b = gym.make(env_id), gym.make(env_id)
    actions = np.random.default_rng(1).uniform(-1, 1, (15, env_a.action_space.shape[0]))
    a, b = _rollout(env_a, 7, actions), _rollout(env_b, 7, actions)
    assert len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    c = _rollout(env_a, 8, actions)
    assert not np.array_equal(a[0], c[0])
    # reset(seed=s) again on a used env reproduces the first trajectory
    assert all(np.array_equal(x, y) for x, y in zip(a, _rollout(env_a, 7, actions), strict=True))


@pytest.mark.parametrize("env_id", ["ukemi/InvertedPendulum-v0", "ukemi/Hopper-v0"])
def test_vector_env_equals_single_envs(env_id):
    n, seed, steps, limit = 3, 11, 25, 10
    venv = gym.make_vec(env_id, num_envs=n, max_episode_steps=limit)
    assert isinstance(venv, UkemiVectorEnv)
    singles = [gym.make(env_id, max_episode_steps=limit) for _ in range(n)]
    obs, _ = venv.reset(seed=seed)
    s_obs = [e.reset(seed=seed + i)[0] for i, e in enumerate(singles)]
    np.testing.assert_array_equal(obs, np.stack(s_obs))
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, n, venv.single_action_space.shape[0]))
    done, ended = np.zeros(n, bool), 0
    for k in range(steps):
        obs, rew, term, trunc, info = venv.step(actions[k].astype(np.float32))
        for i, e in enumerate(singles):
            if done[i]:  # NEXT_STEP autoreset: this step resets and ignores the action
                o, r, te, tr = e.reset()[0], 0.0, False, False
            else:
                o, r, te, tr, _ = e.step(actions[k, i].astype(np.float32))
            np.testing.assert_array_equal(obs[i], o, err_msg=f"env {i} step {k}")
            assert (rew[i], term[i], trunc[i]) == (r, te, tr)
            done[i] = te or tr
            ended += done[i]
    assert ended >= n  # every sub-env went through at least one autoreset


def test_sb3_vec_env_matches_dummy_vec_env():
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import DummyVecEnv

    from ukemi.envs.sb3 import UkemiSB3VecEnv

    env_id, n = "ukemi/InvertedPendulum-v0", 2
    ours = UkemiSB3VecEnv(env_id, n, max_episode_steps=8, seed=3)
    ref = DummyVecEnv([lambda: gym.make(env_id, max_episode_steps=8) for _ in range(n)])
    ref.seed(3)
    np.testing.assert_array_equal(ours.reset(), ref.reset())
    actions = np.random.default_rng(2).uniform(-3, 3, (20, n, 1)).astype(np.float32)
    saw_terminal = False
    for a in actions:
        o1, r1, d1, i1 = ours.step(a)
        o2, r2, d2, i2 = ref.step(a)
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(d1, d2)
        for x, y in zip(i1, i2, strict=True):
            assert x["TimeLimit.truncated"] == y["TimeLimit.truncated"]
            if "terminal_observation" in y:
                saw_terminal = True
                np.testing.assert_array_equal(x["terminal_observation"], y["terminal_observation"])
    assert saw_terminal


# -- agreement with gymnasium's MuJoCo envs ------------------------------------------------------
# Same MJCF, same qpos/qvel, same action, one env step. The engines differ (ukemi: variational
# integrator, constraint joints, hard contact; MuJoCo: semi-implicit Euler with armature and
# joint damping in generalized coordinates), so the bound is physical, not numerical.
_MUJOCO_CASES = {
    # env, action, bound on |Δobs|, bound on |Δreward|
    "InvertedPendulum": (np.array([1.0]), 0.05, 1e-12),
    "InvertedDoublePendulum": (np.array([0.5]), 0.05, 0.01),
    "Reacher": (np.array([0.5, -0.5]), 0.05, 0.01),
    "Hopper": (np.array([0.3, -0.2, 0.1]), 0.01, 0.01),
}


@pytest.mark.parametrize("name", sorted(_MUJOCO_CASES))
def test_first_step_agrees_with_mujoco(name):
    pytest.importorskip("mujoco")
    action, obs_tol, rew_tol = _MUJOCO_CASES[name]
    ref = gym.make(f"{name}-v5").unwrapped
    ours = gym.make(f"ukemi/{name}-v0").unwrapped
    ref.reset(seed=0)
    ours.reset(seed=0)
    np.testing.assert_array_equal(ref.init_qpos, ours.init_qpos)
    # our reset state (noise clipped into the joint limits, see ukemi.envs.base) in both
    qpos, qvel = ours.qpos.copy(), ours.qvel.copy()
    ref.set_state(qpos, qvel)
    if name == "Reacher":
        ours.goal = ref.goal
    o_ref, r_ref, t_ref, *_ = ref.step(action)
    o, r, t, *_ = ours.step(action.astype(np.float32))
    d_obs, d_rew = np.abs(o - o_ref), abs(r - r_ref)
    print(f"{name}: max |Δobs| = {d_obs.max():.2e} (entry {d_obs.argmax()}), |Δreward| = {d_rew:.2e}")
    if name == "InvertedDoublePendulum":
        d_obs = d_obs[:-1]  # qfrc_constraint: not provided by ukemi (0 in both here)
    assert d_obs.max() < obs_tol, f"{name}: observation differs by {d_obs.max():.3g}"
    assert d_rew < rew_tol, f"{name}: reward differs by {d_rew:.3g}"
    assert t == t_ref


def test_solver_failure_truncates_with_status():
    env = gym.make("ukemi/Hopper-v0", solver_options={"max_iter": 1})
    obs0, _ = env.reset(seed=0)
    with pytest.warns(SolverFailureWarning):
        obs, reward, term, trunc, info = env.step(np.zeros(3, np.float32))
    assert info["solver_status"] in ("max_iterations", "line_search_failed", "non_finite")
    assert trunc and not term and reward == 0.0
    np.testing.assert_array_equal(obs, obs0)  # the state stays at the last converged one
    # in a batch, only the failing row is affected and all rows report a status
    venv = UkemiVectorEnv("ukemi/Hopper-v0", 2, solver_options={"max_iter": 1},
                          warn_on_solver_failure=False)
    venv.reset(seed=0)
    _, _, _, trunc, info = venv.step(np.zeros((2, 3), np.float32))
    assert trunc.all() and list(info["solver_status"]) == [info["solver_status"][0]] * 2


def test_timestep_and_frame_skip_keywords():
    env = gym.make("ukemi/Hopper-v0", timestep=0.004, frame_skip=2).unwrapped
    assert env.model.timestep == 0.004 and env.dt == pytest.approx(0.008)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(3, np.float32))
    assert info["solver_status"] == "converged"


def _mean_return(model, env, episodes, seed):
    returns = []
    for k in range(episodes):
        obs, _ = env.reset(seed=seed + k)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, r, term, trunc, _ = env.step(action)
            total, done = total + r, term or trunc
        returns.append(total)
    return float(np.mean(returns))


def test_sb3_ppo_learns_inverted_pendulum():
    """A short seeded PPO run measurably improves the return (the full run is
    examples/sb3_train.py)."""
    pytest.importorskip("stable_baselines3")
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    env = gym.make("ukemi/InvertedPendulum-v0", max_episode_steps=100)
    model = PPO("MlpPolicy", env, seed=0, n_steps=512, batch_size=128, n_epochs=4,
                learning_rate=1e-3, device="cpu")
    eval_env = gym.make("ukemi/InvertedPendulum-v0", max_episode_steps=100)
    before = _mean_return(model, eval_env, 5, seed=100)
    model.learn(4096)
    after = _mean_return(model, eval_env, 5, seed=100)
    print(f"PPO InvertedPendulum mean return: before {before:.1f}, after {after:.1f}")
    assert after > before + 20
