"""Implicit gradients from Python: finite differences, MuJoCo's transition derivatives, the
box-push experiment of the Dojo paper (Fig. 4), and the error contract."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import ukemi
from conftest import beside_mujoco
from ukemi import _flat


def pendulum(h=0.01, damping=0.0, length=1.0):
    b = ukemi.ModelBuilder(timestep=h)
    b.add_body("bob", mass=1.0, inertia=(1e-3, 1e-3, 1e-3), pos=(0, 0, -length))
    b.add_joint("hinge", kind="revolute", parent="world", child="bob", axis=(0, 1, 0),
                parent_anchor=(0, 0, 0), child_anchor=(0, 0, length), damping=damping)
    b.add_actuator("motor", joint="hinge", gear=1.0)
    return b.compile()


def tight(model):
    return model.with_options(rtol=1e-14, max_iter=100)


def box_on_floor(mu=0.5, h=0.01):
    b = ukemi.ModelBuilder(timestep=h)
    b.add_geom("floor", body="world", shape="plane", friction=mu)
    b.add_body("box", mass=1.0, inertia=(1 / 600, 1 / 600, 1 / 600), pos=(0, 0, 0.05))
    b.add_joint("free", kind="floating", parent="world", child="box")
    b.add_geom("box", body="box", shape="box", size=(0.05, 0.05, 0.05), friction=mu)
    b.add_actuator("push", joint="free", gear=1.0)
    return b.compile()


def settle(model, steps=30):
    s = model.make_state()
    for _ in range(steps):
        s, _ = ukemi.step(model, s, np.zeros(model.nu))
    return s


def fd_A_B(model, state, ctrl, eps=1e-6):
    """Central differences of the minimal step map (qpos, qvel) -> (qpos, qvel) (hinge only)."""
    q0, v0 = state.qpos, state.qvel
    nv = model.nv

    def f(q, v, u):
        s = model.make_state(qpos=q, qvel=v)
        n, _ = ukemi.step(model, s, u)
        return np.concatenate([n.qpos, n.qvel])

    A = np.zeros((2 * nv, 2 * nv))
    for i in range(2 * nv):
        d = np.zeros(2 * nv)
        d[i] = eps
        A[:, i] = (f(q0 + d[:nv], v0 + d[nv:], ctrl) - f(q0 - d[:nv], v0 - d[nv:], ctrl)) / (2 * eps)
    B = np.zeros((2 * nv, model.nu))
    for i in range(model.nu):
        du = np.zeros(model.nu)
        du[i] = eps
        B[:, i] = (f(q0, v0, ctrl + du) - f(q0, v0, ctrl - du)) / (2 * eps)
    return A, B


def test_step_jacobians_match_finite_differences_of_step():
    m = tight(pendulum(damping=0.2))
    s = m.make_state(qpos=[0.7], qvel=[-1.1])
    jac = ukemi.step_jacobians(m, s, [0.4])
    A, B = fd_A_B(m, s, np.array([0.4]))
    assert jac.A.shape == (2, 2) and jac.B.shape == (2, 1) and jac.C.shape == (2, len(m.params))
    np.testing.assert_allclose(jac.A, A, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(jac.B, B, rtol=1e-6, atol=1e-10)
    # the gravity column: d(next)/d(g_z) by rebuilding the model with other params
    names = list(m.param_names)
    k = names.index("gravity[z]")
    p = m.params
    dp = np.zeros_like(p)
    dp[k] = 1e-5
    nxt = lambda mm: (lambda n: np.concatenate([n.qpos, n.qvel]))(ukemi.step(mm, s, [0.4])[0])
    fd = (nxt(m.with_params(p + dp)) - nxt(m.with_params(p - dp))) / 2e-5
    np.testing.assert_allclose(jac.C[:, k], fd, rtol=1e-6, atol=1e-10)


def test_products_equal_jacobian_products():
    m = tight(pendulum(damping=0.1))
    s = m.make_state(qpos=[0.2], qvel=[0.5])
    jac = ukemi.step_jacobians(m, s, [0.1])
    a = np.array([0.3, -1.2])
    gx, gu, gp = ukemi.step_vjp(m, s, [0.1], a)
    np.testing.assert_allclose(gx, jac.A.T @ a, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(gu, jac.B.T @ a, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(gp, jac.C.T @ a, rtol=1e-10, atol=1e-14)
    t = np.array([0.7, -0.1])
    np.testing.assert_allclose(ukemi.step_jvp(m, s, [0.1], t, [0.5]), jac.A @ t + jac.B @ [0.5],
                               rtol=1e-10, atol=1e-14)
    # rollout VJP = chained transposes. The reverse sweep re-solves each step from its stored
    # state, so linearisation points agree to the solver tolerance, not bit for bit: the
    # finite-difference partials then agree to ~1e-10 relative (1e-8 asserted; the engine test
    # `rollout_vjp_equals_chained_jacobian_transposes` checks identical points to 1e-10).
    T = 5
    ctrls = np.linspace(-1, 1, T)[:, None]
    adj = np.random.default_rng(0).normal(size=(T + 1, 2))
    g0, gus, gps = ukemi.rollout_vjp(m, s, ctrls, adj)
    states = [s]
    jacs = []
    for k in range(T):
        j = ukemi.step_jacobians(m, states[-1], ctrls[k])
        jacs.append(j)
        states.append(j.next_state)
    lam = adj[T]
    gp_ref = np.zeros(len(m.params))
    for k in reversed(range(T)):
        np.testing.assert_allclose(gus[k], jacs[k].B.T @ lam, rtol=1e-8, atol=1e-12)
        gp_ref += jacs[k].C.T @ lam
        lam = jacs[k].A.T @ lam + adj[k]
    np.testing.assert_allclose(g0, lam, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(gps, gp_ref, rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("kappa", [None, 1e-4])
def test_rollout_jacobians_are_the_chained_step_jacobians(kappa):
    # a box pushed on the floor: it sticks, slides and stops again along the rollout
    m = box_on_floor()
    s = settle(m)
    T = 12
    ctrls = 8.0 * np.sin(0.3 * np.arange(T))[:, None]
    try:
        r = ukemi.rollout_jacobians(m, s, ctrls, kappa_grad=kappa)
        ukemi.set_num_threads(1)  # the sequential path: each step linearised in turn
        r1 = ukemi.rollout_jacobians(m, s, ctrls, kappa_grad=kappa)
    finally:
        ukemi.set_num_threads(0)
    assert r.A.shape == (T, 12, 12) and r.B.shape == (T, 12, 1)
    assert r.C.shape == (T, 12, len(m.params)) and len(r.states) == T + 1
    for x, y in [(r.A, r1.A), (r.B, r1.B), (r.C, r1.C)]:
        assert np.array_equal(x, y)  # the same bits on one thread or two
    speeds = []
    for k in range(T):
        j = ukemi.step_jacobians(m, r.states[k], ctrls[k], kappa_grad=kappa)
        for x, y in [(r.A[k], j.A), (r.B[k], j.B), (r.C[k], j.C)]:
            np.testing.assert_allclose(x, y, rtol=1e-12, atol=1e-12 * np.abs(y).max())
        np.testing.assert_array_equal(r.states[k + 1].qpos, j.next_state.qpos)
        speeds.append(abs(r.states[k + 1].qvel[0]))
    assert min(speeds) < 1e-6 and max(speeds) > 1e-2  # sticks and slides
    with pytest.raises(ukemi.ShapeError, match="ctrls"):
        ukemi.rollout_jacobians(m, s, np.zeros((T, 2)))
    with pytest.raises(ValueError, match="wrt"):
        ukemi.rollout_jacobians(m, s, ctrls, wrt=("state", "torque"))
    bad = m.with_options(max_iter=1, endgame_iter=0, max_subdivisions=1)
    with pytest.raises(ukemi.ConvergenceError, match=r"step \d+"):
        ukemi.rollout_jacobians(bad, s, 30.0 + ctrls)


def test_pendulum_jacobians_agree_with_mujoco_transition_fd():
    mujoco = pytest.importorskip("mujoco")
    xml = """<mujoco><option timestep="{h}" integrator="Euler"/>
      <worldbody><body name="bob" pos="0 0 -1">
        <joint name="hinge" type="hinge" axis="0 1 0" pos="0 0 1"/>
        <inertial pos="0 0 0" mass="1" diaginertia="1e-3 1e-3 1e-3"/>
      </body></worldbody>
      <actuator><motor joint="hinge" gear="1"/></actuator></mujoco>"""
    errs = []
    for h in (4e-3, 2e-3, 1e-3):
        mj = mujoco.MjModel.from_xml_string(xml.format(h=h))
        d = mujoco.MjData(mj)
        d.qpos[:] = [0.6]
        d.qvel[:] = [0.8]
        d.ctrl[:] = [0.3]
        A = np.zeros((2, 2))
        B = np.zeros((2, 1))
        mujoco.mjd_transitionFD(mj, d, 1e-7, 1, A, B, None, None)
        # the same MJCF text, loaded by ukemi
        m = tight(ukemi.Model.from_xml_string(xml.format(h=h)))
        assert m.timestep == h
        jac = ukemi.step_jacobians(m, m.make_state(qpos=[0.6], qvel=[0.8]), [0.3])
        # both are I + h (...) + O(h²): compare the O(h) parts
        errs.append(np.abs(jac.A - A).max() / np.abs(A - np.eye(2)).max())
        np.testing.assert_allclose(jac.B, B, rtol=0.05, atol=1e-9)
    print("relative A difference ukemi vs MuJoCo per dt (4e-3, 2e-3, 1e-3):", errs)
    assert errs[-1] < 0.02
    assert errs[0] / errs[-1] > 3.0  # the integrators' difference shrinks with the step


def test_box_push_gradient_is_smoothed_by_kappa():
    """Dojo Fig. 4: displacement of a resting 1 kg box vs push force; the kink at the
    friction threshold μ m g is smoothed for large κ and sharp for small κ."""
    mu, h = 0.5, 0.01
    m = tight(box_on_floor(mu, h))
    s = settle(m)
    threshold = mu * 9.81

    def grad(force, kappa):
        jac = ukemi.step_jacobians(m, s, [force], kappa_grad=kappa, wrt=("ctrl",))
        return jac.B[0, 0]  # d(Δx tangent)/dF

    hard = h * h / 1.0  # d(x⁺)/dF when sliding: h² / m
    # far from the kink, the small-κ gradient is the hard subgradient
    assert abs(grad(2.0, 1e-8)) < 1e-3 * hard
    assert grad(9.0, 1e-8) == pytest.approx(hard, rel=1e-3)
    # at the kink the large-κ gradient is in between (smooth), the small-κ one is not
    # (κ is in impulse × distance units: the resting corners carry γ ≈ 0.025 N·s each, so
    # κ = 1e-4 lets contact act across ~4 mm: strongly smoothed)
    mid_smooth = grad(threshold, 1e-4)
    assert 0.05 * hard < mid_smooth < 0.95 * hard
    sharp = [grad(threshold - 2.9, k) for k in (1e-4, 1e-6, 1e-8)]
    assert sharp[0] > sharp[1] > sharp[2] >= -1e-9  # sharpens as κ shrinks


def test_gradient_at_failed_step_raises_convergence_error():
    m = box_on_floor()
    s = settle(m)
    bad = m.with_options(max_iter=1, endgame_iter=0)
    with pytest.raises(ukemi.ConvergenceError, match="did not converge"):
        ukemi.step_jacobians(bad, s, [30.0], kappa_grad=1e-4)


def test_bad_gradient_arguments_name_the_field():
    m = pendulum()
    s = m.make_state()
    with pytest.raises(ukemi.ShapeError, match="adjoint_next"):
        ukemi.step_vjp(m, s, [0.0], [1.0, 2.0, 3.0])
    with pytest.raises(ukemi.InputError, match="kappa_grad"):
        ukemi.step_jacobians(m, s, [0.0], kappa_grad=-1.0)
    with pytest.raises(ValueError, match="coordinates"):
        ukemi.step_jacobians(m, s, [0.0], coordinates="polar")
    with pytest.raises(ukemi.ShapeError, match="params"):
        m.with_params([1.0])
    p = m.params
    p[0] = -2.0
    with pytest.raises(ukemi.InputError, match=r"body_mass\[bob\]"):
        m.with_params(p)


def test_params_round_trip_and_model_default_kappa():
    m = pendulum()
    assert len(m.params) == len(m.param_names)
    m2 = m.with_params(m.params * 1.0)
    np.testing.assert_array_equal(m2.params, m.params)
    assert m.kappa_grad is None
    assert m.with_options(kappa_grad=1e-3).kappa_grad == 1e-3
    assert m.with_options(kappa_grad=1e-3).with_options(kappa_grad=0).kappa_grad is None


def test_damping_set_by_with_params_from_zero_gives_exact_jacobians():
    """A joint between two moving bodies compiled without damping, then damped through
    `with_params` (system identification does this): its damper couples the two bodies in the
    Newton matrix, so the step converges as fast as the model compiled with that damping and
    its Jacobians equal central differences of the step (the block was left out before: 24
    iterations instead of 3, and A off by 0.26)."""
    def chain(damping):
        b = ukemi.ModelBuilder(timestep=0.01)
        b.add_body("a", mass=1.0, inertia=(1e-2, 1e-2, 1e-2), pos=(0, 0, -0.5))
        b.add_joint("h1", kind="revolute", parent="world", child="a", axis=(0, 1, 0),
                    parent_anchor=(0, 0, 0), child_anchor=(0, 0, 0.5))
        b.add_body("b", mass=1.0, inertia=(1e-2, 1e-2, 1e-2), pos=(0, 0, -1.5))
        b.add_joint("h2", kind="revolute", parent="a", child="b", axis=(0, 1, 0),
                    parent_anchor=(0, 0, -0.5), child_anchor=(0, 0, 0.5), damping=damping)
        b.add_actuator("m", joint="h2", gear=1.0)
        return tight(b.compile())

    undamped = chain(0.0)
    p = np.array(undamped.params)
    p[undamped.param_names.index("joint_damping[h2][0]")] = 5.0
    ctrl = np.array([0.5])
    iterations = []
    for m in (undamped.with_params(p), chain(5.0)):
        s = m.make_state(qpos=[0.3, -0.4], qvel=[1.0, -2.0])
        jac = ukemi.step_jacobians(m, s, ctrl, wrt=("state", "ctrl"))
        A, B = fd_A_B(m, s, ctrl)
        np.testing.assert_allclose(jac.A, A, atol=1e-6)
        np.testing.assert_allclose(jac.B, B, atol=1e-6)
        iterations.append(ukemi.step(m, s, ctrl)[1].iterations)
    assert iterations[0] == iterations[1]


def test_floating_humanoid_in_the_air_jacobians_match_finite_differences():
    """gymnasium's humanoid (3-hinge composite hips/abdomen, 2-hinge shoulders) lifted 1 m into
    the air: A and B equal central differences of the engine's own step to 1e-6."""
    path = ukemi.gymnasium_asset_path("humanoid")
    with pytest.warns(UserWarning):
        m = ukemi.Model.from_xml_path(path)
    m = tight(m)
    rng = np.random.default_rng(3)
    s0 = m.make_state()
    q = np.array(s0.qpos)
    q[2] += 1.0  # free root lifted: no contact is near
    q[7:] += 0.1 * rng.normal(size=m.nq - 7)
    v = 0.3 * rng.normal(size=m.nv)
    s = m.make_state(qpos=q, qvel=v)
    u = 0.2 * rng.normal(size=m.nu)
    jac = ukemi.step_jacobians(m, s, u, wrt=("state", "ctrl"))
    nv = m.nv

    # directional finite differences along random tangents (all 2nv columns would be slow in CI)
    base = ukemi.step(m, s, u)[0]
    for trial in range(3):
        dx = rng.normal(size=2 * nv)
        du = rng.normal(size=m.nu)
        eps = 1e-6
        outs = []
        for sign in (1.0, -1.0):
            sp = _perturbed_state(m, s, sign * eps * dx)
            n = ukemi.step(m, sp, u + sign * eps * du)[0]
            outs.append(_tangent_difference(m, base, n))
        fd = (outs[0] - outs[1]) / (2 * eps)
        pred = jac.A @ dx + jac.B @ du
        np.testing.assert_allclose(pred, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def _quat_mul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _free_root(model):
    """The humanoid's only quaternion is its free root: qpos[3:7], tangent dq[3:6]."""
    return 3


def _perturbed_state(model, state, d):
    nv = model.nv
    q = np.array(state.qpos)
    dq, dv = d[:nv], d[nv:]
    a = _free_root(model)
    q[:a] += dq[:a]
    phi = dq[a:a + 3]
    ang = np.linalg.norm(phi)
    e = np.array([1.0, 0, 0, 0]) if ang == 0 else np.concatenate([[np.cos(ang / 2)], np.sin(ang / 2) * phi / ang])
    q[a:a + 4] = _quat_mul(q[a:a + 4], e)
    q[a + 4:] += dq[a + 3:]
    return model.make_state(qpos=q, qvel=np.array(state.qvel) + dv)


def _tangent_difference(model, base, other):
    nv = model.nv
    q0, q1 = np.array(base.qpos), np.array(other.qpos)
    a = _free_root(model)
    out = np.zeros(2 * nv)
    out[:a] = q1[:a] - q0[:a]
    c = _quat_mul(q0[a:a + 4] * np.array([1, -1, -1, -1]), q1[a:a + 4])
    if c[0] < 0:
        c = -c
    s = np.linalg.norm(c[1:])
    out[a:a + 3] = 2 * np.arctan2(s, c[0]) * c[1:] / s if s > 0 else 2 * c[1:]
    out[a + 3:nv] = q1[a + 4:] - q0[a + 4:]
    out[nv:] = np.array(other.qvel) - np.array(base.qvel)
    return out


def test_batched_kernels_reject_mismatched_batches_by_name():
    """The raw batched kernels (what the JAX/torch layers call) name the bad argument instead of
    reaching a panic."""
    m = pendulum()
    n = m.nq + m.nv
    with pytest.raises(ukemi.ShapeError, match="us"):
        ukemi._ukemi._flat_step(m, np.zeros((3, n)), np.zeros((2, m.nu)))
    with pytest.raises(ukemi.ShapeError, match="adj"):
        ukemi._ukemi._flat_step_vjp(m, np.zeros((2, n)), np.zeros((2, m.nu)), np.zeros((1, n)), None)
    with pytest.raises(ukemi.ShapeError, match="adj"):
        ukemi._ukemi._flat_rollout_vjp(m, np.zeros((1, n)), np.zeros((1, 4, m.nu)),
                                       np.zeros((1, 3, n)), None)


@pytest.mark.parametrize("name", ["hopper", "humanoid"])
def test_smoothed_jacobians_do_not_depend_on_the_central_path_start(name):
    """The central-path point at kappa_grad is unique: starting its solve from the hard solution
    (the default) or from the neutral point (central_warm_start=False) gives the same A and B on
    gymnasium's hopper and humanoid at dt = 0.01 (on the floor, random controls), and the start
    from the hard solution needs fewer iterations. Tolerance 5e-8 relative: with both centred
    residuals at 1e-15 the humanoid's A, B still differ by up to 1.7e-8 (the partials are
    central differences, ~1e-9, through a Newton matrix conditioned by kappa)."""
    with pytest.warns(UserWarning):
        m = ukemi.Model.from_xml_path(ukemi.gymnasium_asset_path(name))
    m = m.with_options(timestep=0.01, rtol=1e-12, max_iter=100)
    rng = np.random.default_rng(5)
    lo, hi = m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1]
    s = m.make_state()
    for k in range(12):
        u = lo + (hi - lo) * rng.random(m.nu)
        if k % 4 == 3:
            for kappa in (1e-4, 3e-4, 1e-6):
                jw = ukemi.step_jacobians(m, s, u, wrt=("state", "ctrl"), kappa_grad=kappa)
                neutral = m.with_options(central_warm_start=False)
                jn = ukemi.step_jacobians(neutral, s, u, wrt=("state", "ctrl"), kappa_grad=kappa)
                for x, y in ((jw.A, jn.A), (jw.B, jn.B)):
                    scale = max(1.0, np.abs(y).max())
                    assert np.abs(x - y).max() / scale < 5e-8, (name, k, kappa)
                assert jw.central_info.iterations < jn.central_info.iterations, (name, k, kappa)
        s, _ = ukemi.step(m, s, u)


A1 = Path(__file__).resolve().parents[2] / "shared" / "models" / "a1.xml"


@pytest.mark.skipif(not A1.exists(), reason="needs ../shared/models/a1.xml")
def test_a_kept_step_linearises_as_a_fresh_solve_on_the_a1():
    """The VJP of a step whose solve was kept (what JAX and torch do under differentiation)
    equals that of solving the step again, on 52 random-control steps of the shared A1: some
    steps activate missed candidates, and steps 46 and 50 re-freeze a hip cylinder's rim point
    after the solve (measured with an instrumented build), whose gap the gradients then measure
    with the re-frozen point and whose contact frame with the first (before: 53% apart)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = ukemi.Model.from_xml_path(str(A1)).with_options(timestep=0.01)
    s = m.make_state(key=m.keyframe_names[0]) if m.keyframe_names else m.make_state()
    x = np.concatenate([s.qpos, s.qvel])
    r = np.array(m.actuator_ctrlrange)
    us = r[:, 0] + (r[:, 1] - r[:, 0]) * np.random.default_rng(0).random((52, m.nu))
    g = np.ones_like(x)
    hits = ukemi._ukemi._kept_rollouts()[0]
    for k, u in enumerate(us):
        fresh = _flat.step_vjp(m, x, u, None, g, None)
        x_next = _flat.step(m, x, u, None, True)
        kept = _flat.step_vjp(m, x, u, None, g, None)
        for a, b in zip(fresh[:2], kept[:2]):
            np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9 * np.abs(a).max(),
                                       err_msg=f"step {k}")
        x = x_next
    assert ukemi._ukemi._kept_rollouts()[0] == hits + len(us)


def test_exact_jacobians_through_a_joint_limit_pressed_hard():
    """The gymnasium ant under Table V's random controls (seed 0): at its states 0 and 3 a hip
    presses its limit with γ ≈ 54 N·m·s at a slack of ~1e-14, and the exact Jacobians
    (kappa_grad=None) failed: the factorisation came out singular (gradients::SLACK_FLOOR). They
    now exist and match central differences of the hard step, B = ∂(qpos⁺, qvel⁺)/∂u."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = ukemi.Model.from_xml_path(ukemi.gymnasium_asset_path("ant")).with_options(timestep=0.01)
    r = np.asarray(m.actuator_ctrlrange)
    ctrls = r[:, 0] + (r[:, 1] - r[:, 0]) * np.random.default_rng(0).random((4, m.nu))
    tr = ukemi.rollout(m, m.make_state(), ctrls)
    nq = m.nq

    def flat_step(x, u):
        n, _ = ukemi.step(m, m.make_state(qpos=x[:nq], qvel=x[nq:]), u)
        return np.concatenate([n.qpos, n.qvel])

    for k in (0, 3):
        x = np.concatenate([tr.qpos[k], tr.qvel[k]])
        s = m.make_state(qpos=tr.qpos[k], qvel=tr.qvel[k])
        B = np.asarray(ukemi.step_jacobians(m, s, ctrls[k], wrt=("state", "ctrl"),
                                            kappa_grad=None).B)
        eps = 1e-6
        fd = np.zeros((2 * m.nv, m.nu))
        for i in range(m.nu):
            du = np.zeros(m.nu)
            du[i] = eps
            xp, xm = flat_step(x, ctrls[k] + du), flat_step(x, ctrls[k] - du)
            # the velocity rows (the position rows' quaternion differences need the tangent map)
            fd[m.nv:, i] = (xp[nq:] - xm[nq:]) / (2 * eps)
        err = np.abs(B[m.nv:] - fd[m.nv:]).max() / np.abs(fd[m.nv:]).max()
        assert err < 1e-6, (k, err)


@pytest.mark.parametrize("speed", [0.0, 0.4])
def test_smoothed_step_is_continuous_where_a_contact_comes_within_reach(speed):
    """A ball above the floor at gaps just inside and just outside the step's reach
    (``activation_margin + h (2 u + h |g|)``): the smoothed step at kappa moves by far less than
    the ``kappa / (gap m)`` a contact untapered would add as it joins (README: κ-smoothing)."""
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("floor", body="world", shape="plane", friction=0.5)
    b.add_body("ball", mass=1.0, inertia=(4e-3, 4e-3, 4e-3), pos=(0, 0, 0.2))
    b.add_joint("free", kind="floating", parent="world", child="ball")
    b.add_geom("ball", body="ball", shape="sphere", size=(0.1,), friction=0.5)
    m = tight(b.compile())
    kappa, h = 1e-4, 0.01
    reach = m.options["activation_margin"] + h * (2 * speed + h * 9.81)

    def next_qvel(gap):
        s = m.make_state(qpos=[0, 0, 0.1 + gap, 1, 0, 0, 0], qvel=[0.2, 0, -speed, 0, 0.5, 0])
        n, _ = ukemi.step_smoothed(m, s, kappa=kappa)
        return n.qvel

    def across(k, d=1e-9):
        return next_qvel(reach + k * d) - next_qvel(reach - k * d)

    # (the map's own slope cancels between the two spans; a jump does not)
    jump = np.abs(across(1.0) - across(3.0) / 3.0).max()
    assert jump < 1e-4 * kappa / reach


SERVO_ARM = """<mujoco><option timestep="0.01" gravity="0 0 -9.81"/>
  <default><joint type="hinge" axis="0 1 0" armature="0.01"/></default>
  <worldbody><body name="upper" pos="0 0 0">
    <joint name="shoulder"/><geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/>
    <body name="fore" pos="0.3 0 0"><joint name="elbow"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="0.5"/></body>
  </body></worldbody>
  <tendon><fixed name="sum"><joint joint="shoulder" coef="0.5"/><joint joint="elbow" coef="1"/></fixed></tendon>
  <actuator><position joint="shoulder" kp="200" kv="40" {range}/>
    <position joint="elbow" kp="100" kv="20" {range}/>{tendon}</actuator></mujoco>"""


@pytest.mark.parametrize("forcerange, tendon", [(None, False), (4.0, False), (None, True)])
def test_servo_arm_is_stable_and_its_jacobians_match_finite_differences(forcerange, tendon):
    """A two-link arm on position servos whose velocity gains would need h kv / I < 2 if taken
    explicitly (here ~20 at h = 0.01): taken implicitly (`actuation::split_force`) it settles
    where gravity and the servos balance, along MuJoCo's `implicitfast` trajectory on the same
    MJCF, and its Jacobians equal central differences of the step, inside the servos' force
    range and (forcerange 4 N·m) with a servo's force clamped, and with a third servo on a
    fixed tendon over both joints (its damping couples the two links' bodies)."""
    rng_attr = "" if forcerange is None else f'forcelimited="true" forcerange="-{forcerange} {forcerange}"'
    xml = SERVO_ARM.format(range=rng_attr,
                           tendon='<position tendon="sum" kp="60" kv="15"/>' if tendon else "")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = tight(ukemi.Model.from_xml_string(xml))
    target = np.array([0.4, -0.6, 0.0][:m.nu])
    mujoco = pytest.importorskip("mujoco")
    mj = mujoco.MjModel.from_xml_string(xml)
    mj.opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    s, _, worst = beside_mujoco(m, m.make_state(), mj, [target] * 400)
    # (measured: 2.2e-4 rad at most; the integrators differ at first order)
    assert worst < 1e-3
    assert np.abs(s.qvel).max() < 1e-7
    # the shoulder's servo force 200 (0.12 - 0.1) - 40 · 0.05 = 2 N·m, the elbow's -48 N·m
    # (clamped at 4 N·m)
    s = m.make_state(qpos=[0.1, 0.3], qvel=[0.05, -0.1])
    ctrl = np.array([0.12, -0.2, 0.3][:m.nu])
    jac = ukemi.step_jacobians(m, s, ctrl, wrt=("state", "ctrl"))
    A, B = fd_A_B(m, s, ctrl)
    np.testing.assert_allclose(jac.A, A, atol=1e-6 * max(1.0, np.abs(A).max()))
    np.testing.assert_allclose(jac.B, B, atol=1e-6 * max(1.0, np.abs(B).max()))


SYSID_ARM = """<mujoco><option timestep="0.01"/><worldbody><body pos="0 0 1">
  <joint name="j" type="hinge" axis="0 0 1" frictionloss="{f}" damping="{d}" armature="{a}"/>
  <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.05" mass="1" contype="0" conaffinity="0"/>
  </body></worldbody><actuator><motor name="m" joint="j" gear="{g}" ctrlrange="-6 6"/></actuator>
  </mujoco>"""


def test_system_identification_of_armature_damping_dry_friction_and_gear():
    """Joint armature and dry friction (`frictionloss`) are parameters (`joint_armature`,
    `joint_frictionloss`) beside damping, and so is an actuator's gear (`actuator_gear`):
    their columns of `C` equal central differences of the step, and Gauss-Newton on one-step
    predictions of a recorded trajectory (random pushes, then none: the arm turning in a
    horizontal plane slides, slows and sticks) recovers all four from a wrong guess."""
    truth = ukemi.Model.from_xml_string(SYSID_ARM.format(f=0.6, d=0.3, a=0.02, g=1.5))
    names = list(truth.param_names)
    keys = [names.index(n) for n in
            ("joint_armature[j][0]", "joint_damping[j][0]", "joint_frictionloss[j][0]",
             "actuator_gear[m]")]
    np.testing.assert_allclose(truth.params[keys], [0.02, 0.3, 0.6, 1.5])
    rng = np.random.default_rng(5)
    ctrls = np.concatenate([np.concatenate([np.full((5, 1), u), np.zeros((30, 1))])
                            for u in rng.uniform(-4, 4, 4)])
    # recorded as a sensor sees it: (qpos, qvel) each step, the minimal step map F(x, u) that
    # minimal-coordinate Jacobians differentiate (each start rebuilt from its coordinates)
    states = [truth.make_state(qpos=[0.2], qvel=[0.0])]
    for u in ctrls:
        n = ukemi.step(truth, states[-1], u)[0]
        states.append(truth.make_state(qpos=n.qpos, qvel=n.qvel))
    data = np.array([np.concatenate([s.qpos, s.qvel]) for s in states])
    sticking = np.sum(np.abs(data[1:, 1]) < 1e-6)
    assert 0 < sticking < len(ctrls), sticking  # both regimes are in the data

    # the columns against central differences of the step, at a sliding state
    p0 = truth.params
    s, u = states[3], ctrls[3]
    assert abs(s.qvel[0]) > 0.1
    jac = ukemi.step_jacobians(tight(truth), s, u, wrt=("params",), kappa_grad=None)
    for k in keys:
        dp = np.zeros_like(p0)
        dp[k] = 1e-6
        nxt = [ukemi.step(tight(truth.with_params(p0 + sg * dp)), s, u)[0] for sg in (1, -1)]
        fd = (np.concatenate([nxt[0].qpos, nxt[0].qvel])
              - np.concatenate([nxt[1].qpos, nxt[1].qvel])) / 2e-6
        np.testing.assert_allclose(jac.C[:, k], fd, rtol=1e-5, atol=1e-8, err_msg=names[k])

    # Levenberg-Marquardt from a wrong guess, one-step predictions of the recorded states
    # (gear and armature both scale a push's acceleration: nearly collinear columns, on which
    # plain Gauss-Newton overshoots)
    def linearise(theta):
        p = p0.copy()
        p[keys] = theta
        m = truth.with_params(p)
        res, rows = [], []
        for k, u in enumerate(ctrls):
            j = ukemi.step_jacobians(m, states[k], u, wrt=("params",), kappa_grad=None)
            n = j.next_state
            res.append(np.concatenate([n.qpos, n.qvel]) - data[k + 1])
            rows.append(j.C[:, keys])
        return np.concatenate(res), np.concatenate(rows)

    theta, lam = np.array([0.05, 0.1, 0.2, 1.0]), 1e-3
    r, J = linearise(theta)
    for _ in range(60):
        H = J.T @ J
        trial = theta - np.linalg.solve(H + lam * np.diag(np.diag(H)), J.T @ r)
        # armature, damping >= 0, dry friction > 0
        trial = np.maximum(trial, [0.0, 0.0, 1e-3, -np.inf])
        rt, Jt = linearise(trial)
        if rt @ rt < r @ r:
            theta, r, J, lam = trial, rt, Jt, lam / 3
        else:
            lam *= 4
        if r @ r < 1e-24:
            break
    print(f"\nidentified armature, damping, frictionloss, gear {theta}"
          " (truth 0.02, 0.3, 0.6, 1.5)")
    np.testing.assert_allclose(theta, [0.02, 0.3, 0.6, 1.5], rtol=1e-5)
    # dry friction compiled in stays in: zero is refused, naming the parameter
    p = p0.copy()
    p[keys[2]] = 0.0
    with pytest.raises(ukemi.InputError, match=r"joint_frictionloss\[j\]\[0\]"):
        truth.with_params(p)
