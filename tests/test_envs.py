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
@pytest.mark.parametrize("env_id", ["ukemi/Hopper-v0", "ukemi/Reacher-v0", "ukemi/Ant-v0", "ukemi/Pendulum-v0",
                                    "ukemi/CartPole-v0", "ukemi/Humanoid-v0", "ukemi/BoxPush-v0",
                                    "ukemi/Quadruped-v0"])
def test_same_seed_same_trajectory(env_id):
    env_a, env_b = gym.make(env_id), gym.make(env_id)
    actions = np.random.default_rng(1).uniform(-1, 1, (15, env_a.action_space.shape[0]))
    a, b = _rollout(env_a, 7, actions), _rollout(env_b, 7, actions)
    assert len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    c = _rollout(env_a, 8, actions)
    assert not np.array_equal(a[0], c[0])
    # reset(seed=s) again on a used env reproduces the first trajectory
    assert all(np.array_equal(x, y) for x, y in zip(a, _rollout(env_a, 7, actions), strict=True))


# -- full-state stepping ---------------------------------------------------------------------------
def _env_trajectory(env, seed, actions):
    """Reset, then step ``actions``: the reset state, each step's ``[qpos, qvel]`` and info."""
    env.reset(seed=seed)
    start = env.model.make_state(env.qpos.copy(), env.qvel.copy())
    xs, infos = [], []
    for a in actions:
        *_, term, trunc, info = env.step(a)
        xs.append(env.state_vector())
        infos.append(info)
        assert not (term or trunc) and info["solver_status"] in ukemi.SUCCESS_STATUSES
    return start, np.array(xs), infos


@pytest.mark.parametrize("env_id, kwargs", [("ukemi/Hopper-v0", {}),  # contact, frame_skip 4
                                            ("ukemi/Ant-v0", {})])  # free joint, lands by step 12
def test_env_trajectory_is_the_rollout_of_expanded_controls(env_id, kwargs):
    env = gym.make(env_id, **kwargs).unwrapped
    k = env.frame_skip
    actions = np.random.default_rng(5).uniform(-1, 1, (12, env.action_space.shape[0])).astype(np.float32)
    start, xs, infos = _env_trajectory(env, 4, actions)
    traj = ukemi.rollout(env.model, start, np.repeat(actions.astype(np.float64), k, axis=0))
    ref = np.concatenate([traj.qpos, traj.qvel], axis=1)[k::k]
    err = np.abs(xs - ref).max()
    print(f"{env_id}: max |env - rollout| = {err:.1e} over {len(xs)} env steps")
    assert err <= 1e-12
    # the last step's contact forces are the rollout's last impulses / timestep
    impulse = np.asarray(traj.final_state.contact_impulse)
    np.testing.assert_allclose(infos[-1]["contact_forces"], impulse / env.model.timestep, rtol=0, atol=1e-9)
    assert infos[-1]["contact_forces"][:, 0].max() > 1.0  # in contact
    # the env state is not rebuilt from [qpos, qvel] between steps: that would move it by O(dt)
    s, rebuilt = start, []
    for a in actions:
        t = ukemi.rollout(env.model, s, np.repeat(a[None].astype(np.float64), k, axis=0))
        s = env.model.make_state(t.qpos[-1], t.qvel[-1])
        rebuilt.append(np.concatenate([t.qpos[-1], t.qvel[-1]]))
    assert np.abs(np.array(rebuilt) - ref).max() > 1e-6
    # a reset with the same seed reproduces the trajectory bit for bit
    start2, xs2, _ = _env_trajectory(env, 4, actions)
    assert start2.qpos.tobytes() == start.qpos.tobytes() and xs2.tobytes() == xs.tobytes()


def test_vector_env_rows_are_full_states_of_single_envs():
    env_id, n = "ukemi/Hopper-v0", 4
    venv = UkemiVectorEnv(env_id, n)
    singles = [gym.make(env_id).unwrapped for _ in range(n)]
    venv.reset(seed=20)
    for i, e in enumerate(singles):
        e.reset(seed=20 + i)
    actions = np.random.default_rng(6).uniform(-1, 1, (10, n, 3)).astype(np.float32)
    for a in actions:
        venv.step(a)
        for i, e in enumerate(singles):
            e.step(a[i])
    for i, e in enumerate(singles):
        sub = venv.envs[i]
        assert sub.state_vector().tobytes() == e.state_vector().tobytes()
        # the full states (midpoint velocities, warm start) agree, not only [qpos, qvel]
        for name in ("com_pos", "body_quat", "body_linvel", "body_angvel", "joint_impulse", "contact_impulse"):
            assert np.asarray(getattr(sub.state, name)).tobytes() == np.asarray(getattr(e.state, name)).tobytes(), name


def test_env_states_bad_input_raises_and_changes_nothing():
    states = ukemi._ukemi.EnvStates(ukemi.models.gymnasium("hopper"), 2)
    before = [states.qpos_qvel(i) for i in range(2)]
    with pytest.raises(ukemi.ShapeError, match="ctrls"):
        states.step(np.array([0, 1]), np.zeros((2, 2)), 4)
    with pytest.raises(ukemi.InputError, match=r"rows\[1\]"):
        states.step(np.array([0, 2]), np.zeros((2, 3)), 4)
    with pytest.raises(ukemi.InputError, match="ctrl"):
        states.step(np.array([0, 1]), np.array([[0.0, 0, 0], [0, np.nan, 0]]), 4)
    with pytest.raises(ukemi.InputError, match=">= 0"):
        states.step(np.array([-1, 0]), np.zeros((2, 3)), 4)
    with pytest.raises(ukemi.InputError, match="row"):
        states.state(5)
    assert all(np.array_equal(b, states.qpos_qvel(i)) for i, b in enumerate(before))


def test_copied_env_states_continue_identically():
    import copy

    model = ukemi.models.gymnasium("hopper")
    states = ukemi._ukemi.EnvStates(model, 2)
    states.reset(1, np.asarray(model.qpos0), np.full(model.nv, 0.1))
    rows, ctrls = np.array([0, 1]), np.array([[0.3, -0.2, 0.1], [0.5, 0.5, -0.5]])
    for _ in range(5):
        states.step(rows, ctrls, 4)
    twin = copy.deepcopy(states)
    for _ in range(5):
        assert states.step(rows, ctrls, 4)[0].tobytes() == twin.step(rows, ctrls, 4)[0].tobytes()
    assert np.asarray(states.state(1).com_pos).tobytes() == np.asarray(twin.state(1).com_pos).tobytes()


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
    assert info["solver_status"] in ukemi.SUCCESS_STATUSES


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


# -- classic control: Pendulum and CartPole --------------------------------------------------------
def test_pendulum_step_matches_gymnasium_pendulum():
    """One env step of ukemi/Pendulum-v0 against Pendulum-v1 from the same (θ, θ̇) and torque.

    Both are first-order steps of the same ODE (θ̈ = 3g/(2l) sin θ + 3u/(m l²)); ukemi moves
    the rod with the Cayley map, which turns it by 2·atan(hω/2) instead of hω, a difference of
    (hω)³/12. So |Δθ̇| <= c·h²·ω³/12 with ω the larger speed of the step (c = 3; measured
    max 1.9 over 500 states), and the reward — computed from the state before the step — is
    the same number.
    """
    ref, ours = gym.make("Pendulum-v1").unwrapped, gym.make("ukemi/Pendulum-v0").unwrapped
    h, rng = ours.dt, np.random.default_rng(0)
    assert h == ref.dt == 0.05
    for _ in range(200):
        th, thd, u = rng.uniform(-np.pi, np.pi), rng.uniform(-7, 7), rng.uniform(-2, 2)
        ref.state = np.array([th, thd])
        ours.set_state([th], [thd])
        o_ref, r_ref, *_ = ref.step(np.array([u], np.float32))
        o, r, *_ = ours.step(np.array([u], np.float32))
        omega = max(abs(thd), abs(float(o_ref[2])))
        assert abs(o[2] - o_ref[2]) <= 3 * h * h * omega**3 / 12 + 1e-5, (th, thd, u)
        assert abs(r - r_ref) <= 1e-6 * abs(r_ref) + 1e-6


def test_pendulum_trajectory_converges_to_gymnasium_at_first_order():
    """Over a fixed 0.5 s with a smooth torque, the ukemi and gymnasium trajectories differ by
    O(h): halving dt (both envs) halves the difference (measured ratios 2.1–2.4 over five
    seeds; max |Δobs| 0.005–0.28 at dt 0.05). The env steps a flat (qpos, qvel) state, so each
    step rebuilds the rod's COM velocity as the tangent ω × r at the current pose where the
    variational integrator carried the chord velocity: an O(hω) relative change per step.
    (Continued full-state rollouts, ``ukemi.rollout``, agree with gymnasium at O(h²).)"""
    def max_difference(h, seed):
        ref = gym.make("Pendulum-v1").unwrapped
        ref.dt = h
        ours = gym.make("ukemi/Pendulum-v0", timestep=h).unwrapped
        rng = np.random.default_rng(seed)
        th, thd = rng.uniform(-np.pi, np.pi), rng.uniform(-1, 1)
        ref.state = np.array([th, thd])
        ours.set_state([th], [thd])
        diff = 0.0
        for k in range(int(round(0.5 / h))):
            u = np.array([1.5 * np.sin(3 * k * h)], np.float32)
            diff = max(diff, np.abs(ours.step(u)[0] - ref.step(u)[0]).max())
        return diff

    for seed in range(3):
        d1, d2 = max_difference(0.05, seed), max_difference(0.025, seed)
        print(f"seed {seed}: max |Δobs| {d1:.2e} at dt 0.05, {d2:.2e} at dt 0.025")
        assert d1 < 0.35 and d2 < d1 / 1.8


def _expm(a):
    """Matrix exponential by scaling and squaring of a Taylor series (small matrices)."""
    s = max(0, int(np.ceil(np.log2(max(np.abs(a).sum(1).max(), 1e-300)))) + 1)
    a = a / 2**s
    out, term = np.eye(len(a)), np.eye(len(a))
    for k in range(1, 20):
        term = term @ a / k
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


def test_cartpole_follows_linearised_dynamics_near_upright():
    """From a 1 mrad tilt under a small constant push, ukemi/CartPole-v0 follows the exact
    solution of gymnasium's equations linearised at upright; ukemi is first order in dt, so the
    error halves with dt (measured 9.1% → 4.6% → 2.3% of max |θ| over 0.5 s)."""
    g, m_cart, m_pole, l = 9.8, 1.0, 0.1, 0.5
    total = m_cart + m_pole
    d = l * (4 / 3 - m_pole / total)
    # z = [x, ẋ, θ, θ̇]: θ̈ = (g θ − F/M) / d, ẍ = F/M − m_p l θ̈ / M
    a = np.array([[0, 1, 0, 0], [0, 0, -m_pole * l * g / (total * d), 0], [0, 0, 0, 1], [0, 0, g / d, 0]])
    b = np.array([0, 1 / total + m_pole * l / (total * total * d), 0, -1 / (total * d)])
    force, z0 = 0.02, np.array([0.0, 0.0, 1e-3, 0.0])

    def relative_error(h):
        env = gym.make("ukemi/CartPole-v0", timestep=h).unwrapped
        env.set_state(z0[[0, 2]], z0[[1, 3]])
        aug = np.zeros((5, 5))
        aug[:4, :4], aug[:4, 4] = a, b
        e = _expm(aug * h)
        z, err, scale = z0.copy(), 0.0, 0.0
        for _ in range(int(round(0.5 / h))):
            obs, reward, term, *_ = env.step(np.array([force / env.force_mag], np.float32))
            z = e[:4, :4] @ z + e[:4, 4] * force
            assert reward == 1.0 and not term
            err, scale = max(err, abs(obs[2] - z[2])), max(scale, abs(z[2]))
        return err / scale

    e1, e2 = relative_error(0.02), relative_error(0.01)
    print(f"CartPole vs linearised: {e1:.3f} at dt 0.02, {e2:.3f} at dt 0.01")
    assert e1 < 0.12 and 1.8 < e1 / e2 < 2.2


def test_cartpole_terminates_like_gymnasium():
    env = gym.make("ukemi/CartPole-v0")
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and np.all(np.abs(obs) <= 0.05)
    total, steps = 0.0, 0
    while True:  # push right: the pole falls left past 12° long before the cart reaches 2.4 m
        obs, r, term, trunc, _ = env.step(np.array([1.0], np.float32))
        total, steps = total + r, steps + 1
        if term or trunc:
            break
    assert term and obs[2] < -np.deg2rad(12) and abs(obs[0]) < 2.4
    assert total == steps  # reward 1 per step, the terminating step included


# -- Humanoid ----------------------------------------------------------------------------------------
def test_humanoid_observation_matches_mujoco_and_falls_like_v5():
    mujoco = pytest.importorskip("mujoco")
    ours = gym.make("ukemi/Humanoid-v0").unwrapped
    ref = gym.make("Humanoid-v5").unwrapped
    obs, _ = ours.reset(seed=0)
    assert obs.shape == ref.observation_space.shape == (348,)
    ref.reset(seed=0)
    ref.set_state(ours.qpos.copy(), ours.qvel.copy())
    mujoco.mj_forward(ref.model, ref.data)
    # qpos, qvel, cinert and cvel of the same state are MuJoCo's numbers; qfrc_actuator and
    # cfrc_ext are zero before the first step in both
    np.testing.assert_allclose(obs, ref._get_obs(), rtol=0, atol=1e-9)
    # zero action: it collapses and is terminated (z < 1) within a few steps of MuJoCo's
    steps = {}
    for name, env in (("ukemi", ours), ("mujoco", ref)):
        for k in range(80):
            _, _, term, trunc, _ = env.step(np.zeros(17, np.float32))
            if term or trunc:
                break
        steps[name] = (k, term)
    print(f"Humanoid zero-action termination step: {steps}")
    assert steps["ukemi"][1] and steps["mujoco"][1]
    assert abs(steps["ukemi"][0] - steps["mujoco"][0]) <= 5


def test_humanoid_qfrc_actuator_and_contact_wrench():
    env = gym.make("ukemi/Humanoid-v0").unwrapped
    env.reset(seed=0)
    action = np.linspace(-0.05, 0.05, 17).astype(np.float32)
    for _ in range(25):  # feet on the floor by then
        _, _, term, trunc, info = env.step(action)
        assert not (term or trunc) and info["solver_status"] in ukemi.SUCCESS_STATUSES
    qfrc = env._get_obs()[45 + 130 + 78 : 45 + 130 + 78 + 17]
    gear = np.asarray(env.model.actuator_gear)
    # humanoid.xml lists the abdomen motors y, z, x; MuJoCo's dofs are z, y, x
    assert sorted(np.round(qfrc, 9)) == sorted(np.round(gear * action.astype(np.float64), 9))
    from ukemi.envs.humanoid import com_quantities

    cfrc = com_quantities(env)["cfrc_ext"]
    # the floor pushes up, and only on bodies that touch it
    assert cfrc[:, 5].sum() > 0 and np.count_nonzero(np.abs(cfrc).sum(1) > 1e-6) < env.model.nbody


# -- contact forces in info ----------------------------------------------------------------------------
def test_contact_forces_carry_the_weight_and_lie_in_the_cone():
    env = gym.make("ukemi/BoxPush-v0").unwrapped
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(2, np.float32))  # the box rests on the floor
    f = info["contact_forces"]
    assert f.shape == (env.model.ncontact, 3)
    box = env._body_index["box"]
    weight = 0.5 * 9.81
    np.testing.assert_allclose(f[:, 0].sum(), weight, rtol=1e-6)  # only box-floor carry load
    np.testing.assert_allclose(env.body_contact_wrench[box, 3:], [0, 0, weight], atol=1e-6 * weight)
    # a random Hopper episode: normal forces >= 0, friction inside the cone |f_t| <= μ f_n
    hopper = gym.make("ukemi/Hopper-v0")
    hopper.reset(seed=1)
    hopper.action_space.seed(1)
    mu, loaded = 2.0, 0  # the pair's μ is the larger of the two geoms': 2.0 for the foot, else 0.9
    for _ in range(60):
        _, _, term, trunc, info = hopper.step(hopper.action_space.sample())
        f = info["contact_forces"]
        assert np.all(f[:, 0] >= -1e-6)
        assert np.all(np.hypot(f[:, 1], f[:, 2]) <= mu * f[:, 0] * (1 + 1e-6) + 1e-6)
        loaded += int(f[:, 0].max() > 1.0)
        if term or trunc:
            break
    assert loaded > 0
    assert gym.make("ukemi/Pendulum-v0").reset(seed=0) and \
        gym.make("ukemi/Pendulum-v0").unwrapped.contact_forces.shape == (0, 3)


def test_ant_cfrc_ext_carries_the_weight_like_mujoco():
    """Ant-v5's contact-force observation: at rest the per-body wrenches (torque about the
    ant's centre of mass c, force) sum to the weight at c in both engines. The poses differ
    (MuJoCo's soft joint limits and contacts let the legs splay further) and the split between
    the feet need not agree: four feet on a plane are statically indeterminate."""
    pytest.importorskip("mujoco")
    from ukemi.envs._com import subtree_com

    ours, ref = gym.make("ukemi/Ant-v0").unwrapped, gym.make("Ant-v5").unwrapped
    qpos = ours.init_qpos.copy()
    qpos[:2] = [1.0, 0.5]  # off the origin, so torques about c and about the origin differ
    for env in (ours, ref):
        env.reset(seed=0)
        env.set_state(qpos, np.zeros(14))
    for _ in range(60):
        ours.step(np.zeros(8, np.float32))
    for _ in range(500):
        ref.step(np.zeros(8))
    mass = float(np.sum(np.asarray(ours.model.body_mass)[1:]))
    assert mass == pytest.approx(float(ref.model.body_mass[1:].sum()), rel=1e-12)
    weight = mass * 9.81
    for name, cfrc, c in (("ukemi", ours.cfrc_ext, subtree_com(ours)),
                          ("mujoco", ref.data.cfrc_ext, ref.data.subtree_com[1])):
        total = cfrc.sum(0)
        print(f"{name}: c = {np.round(c, 4)}, total wrench {total}, "
              f"relative weight error {abs(total[5] - weight) / weight:.1e}")
        assert abs(total[5] - weight) <= 1e-6 * weight, name
        np.testing.assert_allclose(total[[0, 1, 2, 3, 4]], 0.0, atol=1e-6 * weight, err_msg=name)
        assert np.all(cfrc[:, 5] >= -1e-9) and np.count_nonzero(cfrc[:, 5] > 1e-3) >= 3, name
        assert c[0] == pytest.approx(1.0, abs=0.05) and c[1] == pytest.approx(0.5, abs=0.05)
    # observation and reward as v5's: clipped wrenches of bodies 1.., contact cost on all rows
    obs = ours._get_obs()
    assert obs.shape == ref._get_obs().shape == (105,)
    np.testing.assert_array_equal(obs[27:], np.clip(ours.cfrc_ext[1:], -1, 1).ravel())
    _, r, _, _, info = ours.step(np.zeros(8, np.float32))
    assert info["reward_contact"] == pytest.approx(-5e-4 * np.sum(np.clip(ours.cfrc_ext, -1, 1) ** 2), rel=1e-12)
    assert gym.make("ukemi/Ant-v0", include_cfrc_ext_in_observation=False).observation_space.shape == (27,)


# -- ukemi's own tasks -----------------------------------------------------------------------------------
def test_box_push_reward_and_pushing_moves_the_box_to_the_goal_side():
    env = gym.make("ukemi/BoxPush-v0").unwrapped
    _, info0 = env.reset(seed=2)
    r_goal, bearing = np.linalg.norm(env.goal), np.arctan2(env.goal[1], env.goal[0])
    assert 0.8 <= r_goal <= 1.1 and abs(bearing) <= np.pi / 6
    env.goal = np.array([1.15, 0.0])  # straight ahead, beyond the box
    start = env.box_xy()
    action = np.array([0.0, -1.0], np.float32)  # straighten the elbow: the fingertip moves +x
    for _ in range(20):
        _, r, term, trunc, info = env.step(action)
        d = np.linalg.norm(env.box_xy() - env.goal)
        assert r == pytest.approx(-d - 0.1 * float(np.sum(np.square(action))), abs=1e-12)
        assert not term
    assert env.box_xy()[0] > start[0] + 0.02 and info["distance"] < np.linalg.norm(start - env.goal)


def test_quadruped_stands_and_terminates_when_fallen():
    env = gym.make("ukemi/Quadruped-v0").unwrapped
    obs, _ = env.reset(seed=0)
    assert obs.shape == (35,) and env.is_healthy
    total, x_start = 0.0, env.qpos[0]
    for _ in range(25):  # zero action holds the stand pose
        _, r, term, trunc, info = env.step(np.zeros(12, np.float32))
        assert not term and info["solver_status"] in ukemi.SUCCESS_STATUSES
        total += r
    # healthy every step, no control cost; the forward terms telescope to displacement / dt
    assert total == pytest.approx(25.0 + (env.qpos[0] - x_start) / env.dt, abs=1e-9)
    assert abs(env.qpos[0] - x_start) < 0.1 and env.upright > 0.99
    qpos = env.qpos.copy()
    qpos[3:7] = [0.0, 1.0, 0.0, 0.0]  # upside down
    env.set_state(qpos, np.zeros(env.model.nv))
    _, _, term, *_ = env.step(np.zeros(12, np.float32))
    assert term and env.upright < 0


# -- differentiable task API -----------------------------------------------------------------------
@pytest.mark.filterwarnings("ignore::ukemi.envs.base.SolverFailureWarning")
@pytest.mark.parametrize("name", ["Pendulum", "CartPole", "Hopper", "Ant", "BoxPush", "Quadruped"])
def test_task_reward_equals_env_reward(name):
    jnp = pytest.importorskip("jax.numpy")
    torch = pytest.importorskip("torch")
    from ukemi.envs.differentiable import make_task

    # Ant's task reward has no contact cost (contact forces are not in the flat state)
    kwargs = {"contact_cost_weight": 0.0} if name == "Ant" else {}
    env = gym.make(f"ukemi/{name}-v0", **kwargs).unwrapped
    env.reset(seed=3)
    env.action_space.seed(3)
    goal = env.goal if name == "BoxPush" else None
    tj, tt = make_task(name, "jax", goal=goal), make_task(name, "torch", goal=goal)
    # one engine step per env step: the flat task's map is the env's from a fresh state
    env1 = gym.make(f"ukemi/{name}-v0", frame_skip=1, **kwargs).unwrapped
    tj1 = make_task(name, "jax", goal=goal, frame_skip=1)
    nq, dev = env.model.nq, 0.0
    for _ in range(3):
        x, a = env.state_vector(), 0.5 * env.action_space.sample()
        _, r, term, _, info = env.step(a)
        assert info["solver_status"] in ukemi.SUCCESS_STATUSES
        x1, u = env.state_vector(), np.asarray(a, np.float64)
        assert float(tj.reward(jnp.asarray(x), jnp.asarray(u), jnp.asarray(x1))) == pytest.approx(r, abs=1e-12)
        rt = tt.reward(torch.as_tensor(x), torch.as_tensor(u), torch.as_tensor(x1))
        assert float(rt) == pytest.approx(r, abs=1e-12)
        assert bool(tj.terminated(jnp.asarray(x1))) == term
        # The task's state is flat: every engine step rebuilds the maximal state from [qpos,
        # qvel] and restarts the solver, the env keeps its full state (midpoint velocities, warm
        # start). From a fresh state the first engine steps agree to the solver's tolerance;
        # over frame_skip steps they drift apart by O(dt).
        env1.set_state(x[:nq], x[nq:])
        env1.step(a)
        np.testing.assert_allclose(np.asarray(tj1.step(jnp.asarray(x), jnp.asarray(u))),
                                   env1.state_vector(), atol=1e-6)
        dev = max(dev, float(np.abs(np.asarray(tj.step(jnp.asarray(x), jnp.asarray(u))) - x1).max()))
    print(f"{name}: task.step vs env step (frame_skip {env.frame_skip}), max deviation {dev:.1e}")


def test_task_return_gradient_matches_finite_differences():
    jax = pytest.importorskip("jax")
    jnp = jax.numpy
    torch = pytest.importorskip("torch")
    from ukemi.envs.differentiable import make_task

    task = make_task("ukemi/Pendulum-v0", "jax")
    x0 = task.reset_state(jax.random.PRNGKey(0))
    assert x0.shape == (2,) and abs(float(x0[0])) <= np.pi and abs(float(x0[1])) <= 1

    def ret(us, x):
        total = 0.0
        for u in us:
            x1 = task.step(x, u)
            total, x = total + task.reward(x, u, x1), x1
        return total

    us = jnp.asarray(np.random.default_rng(0).uniform(-1.5, 1.5, (5, 1)))
    grad = np.asarray(jax.grad(ret)(us, x0))
    eps, fd = 1e-6, np.zeros_like(grad)
    for k in range(5):
        d = np.zeros((5, 1))
        d[k] = eps
        fd[k] = (float(ret(us + d, x0)) - float(ret(us - d, x0))) / (2 * eps)
    np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-7)
    # the torch task gives the same gradient
    tt = make_task("ukemi/Pendulum-v0", "torch")
    us_t = torch.tensor(np.asarray(us), requires_grad=True)
    x = torch.tensor(np.asarray(x0))
    total = 0.0
    for u in us_t:
        x1 = tt.step(x, u)
        total, x = total + tt.reward(x, u, x1), x1
    total.backward()
    np.testing.assert_allclose(us_t.grad.numpy(), grad, rtol=1e-9, atol=1e-12)
