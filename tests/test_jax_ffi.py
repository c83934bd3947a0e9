"""ukemi.jax on its XLA FFI backend (Rust handlers registered with jax.ffi): same numbers as
the pure_callback fallback, jit/vmap/scan, check_grads, and errors that name the problem."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

import ukemi

jax = pytest.importorskip("jax")
import jax.numpy as jnp  # noqa: E402
from jax.test_util import check_grads  # noqa: E402

import ukemi.jax as ujax  # noqa: E402
from conftest import arm, ball_on_floor, pendulum, x0_of  # noqa: E402


@contextlib.contextmanager
def backend(name):
    ujax.set_backend(name)
    try:
        yield
    finally:
        ujax.set_backend("auto")


def sliding_ball_state(m, vx=0.5):
    return np.concatenate([m.make_state().qpos, [vx, 0.0, -0.3, 0, 0, 0]])


def raw(target, out, *args, **attrs):
    """Call a target directly (bypassing the Python checks) under jit."""
    call = jax.ffi.ffi_call(target, out, vmap_method="broadcast_all")
    return jax.jit(lambda *a: call(*a, **attrs))(*args)


def test_ffi_is_the_default_backend_on_cpu():
    assert ujax.ffi_available(), ujax.ffi_error()
    assert jax.default_backend() == "cpu"
    assert ujax.backend() == "ffi"
    with backend("callback"):
        assert ujax.backend() == "callback"
    with pytest.raises(ValueError):
        ujax.set_backend("gpu")


# ------------------------------------------------------------------ FFI == callback, exactly
CASES = {
    "arm": (arm, lambda m: x0_of(m), lambda m: np.array([0.3, -0.2]), None),
    "ball": (ball_on_floor, sliding_ball_state, lambda m: np.array([0.4]), 1e-4),
}


def _both(fn):
    with backend("ffi"):
        a = jax.tree.map(np.asarray, fn())
    with backend("callback"):
        b = jax.tree.map(np.asarray, fn())
    return a, b


@pytest.mark.parametrize("case", CASES)
def test_ffi_and_callback_agree_exactly(case):
    make, x_of, u_of, kappa = CASES[case]
    m = make()
    x, u, p = jnp.asarray(x_of(m)), jnp.asarray(u_of(m)), jnp.asarray(m.params)
    us = jnp.asarray(np.stack([u * (1 + 0.1 * k) for k in range(5)]))
    wx = jnp.linspace(-1, 1, x.size)
    wr = jnp.linspace(-1, 1, 6 * x.size).reshape(6, x.size)

    def fwd():
        return (ujax.step(m, x, u), ujax.step(m, x, u, params=p), ujax.rollout(m, x, us),
                ujax.rollout(m, x, us, params=p))

    def grads():
        ls = lambda x, u, p: jnp.sum(wx * ujax.step(m, x, u, params=p, kappa_grad=kappa))
        lr = lambda x, us, p: jnp.sum(wr * ujax.rollout(m, x, us, params=p, kappa_grad=kappa))
        lr0 = lambda x, us: jnp.sum(wr * ujax.rollout(m, x, us, kappa_grad=kappa))
        return (jax.grad(ls, argnums=(0, 1, 2))(x, u, p),
                jax.grad(lr, argnums=(0, 1, 2))(x, us, p),
                jax.grad(lr0, argnums=(0, 1))(x, us))

    for a, b in (_both(fwd), _both(grads)):
        for ai, bi in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
            np.testing.assert_array_equal(ai, bi)
            assert np.all(np.isfinite(ai))
    gp = _both(grads)[0][0][2]
    assert np.any(gp != 0)


def test_ffi_broadcasting_and_convert():
    m = arm()
    x = x0_of(m)
    us = np.array([[0.3, -0.2], [0.1, 0.0], [0.0, 0.5]])
    out = ujax.step(m, x, us)  # x broadcasts against a batch of controls
    assert out.shape == (3, x.size)
    for i in range(3):
        np.testing.assert_array_equal(out[i], ujax.step(m, x, us[i]))
    g = jax.grad(lambda x: jnp.sum(ujax.step(m, x, us) ** 2))(jnp.asarray(x))
    g_loop = sum(jax.grad(lambda x: jnp.sum(ujax.step(m, x, u) ** 2))(jnp.asarray(x)) for u in us)
    np.testing.assert_allclose(g, g_loop, rtol=1e-13, atol=1e-13)
    # float32 only with convert=True (and then upcast: same numbers as the float64 call)
    x32 = x.astype(np.float32)
    with pytest.raises(TypeError, match="float32"):
        ujax.step(m, x32, us[0])
    with pytest.raises(TypeError, match="`u`"):
        ujax.step(m, x, us[0].astype(np.float32))
    with pytest.raises(TypeError, match="float32"):
        jax.jit(lambda x: ujax.step(m, x, us[0]))(jnp.asarray(x32))
    y = ujax.step(m, x32, us[0], convert=True)
    assert y.dtype == jnp.float64
    np.testing.assert_array_equal(y, ujax.step(m, x32.astype(np.float64), us[0]))


# ------------------------------------------------------------------------- jit / vmap / scan
def test_jit_vmap_grad_over_64_initial_states_equals_a_python_loop():
    m = ball_on_floor()
    rng = np.random.default_rng(3)
    base = sliding_ball_state(m)
    xs = np.tile(base, (64, 1))
    xs[:, 7:] += 0.3 * rng.normal(size=(64, 6))
    xs[:, 2] += 0.02 * rng.uniform(size=64)  # some in contact, some just above the floor
    us = jnp.asarray(np.full((3, 1), 0.4))
    w = jnp.linspace(-1, 1, 4 * 13).reshape(4, 13)

    def loss(x):
        return jnp.sum(w * ujax.rollout(m, x, us, kappa_grad=1e-4)) + \
            jnp.sum(ujax.step(m, x, us[0], kappa_grad=1e-4) ** 2)

    g = jax.jit(jax.vmap(jax.grad(loss)))(jnp.asarray(xs))
    assert g.shape == xs.shape
    grad1 = jax.grad(loss)
    loop = np.stack([np.asarray(grad1(jnp.asarray(x))) for x in xs])
    np.testing.assert_allclose(g, loop, rtol=1e-12, atol=1e-12)
    with backend("callback"):
        gc = jax.jit(jax.vmap(jax.grad(loss)))(jnp.asarray(xs))
    np.testing.assert_array_equal(g, gc)


def test_nested_vmap_and_params_batch():
    m = arm()
    x = x0_of(m)
    p = np.asarray(m.params)
    ps = np.stack([p * (1 + 0.01 * k) for k in range(4)])
    us = np.stack([np.array([0.1 * k, 0.2]) for k in range(3)])
    f = lambda p, u: ujax.step(m, x, u, params=p)
    nested = jax.jit(jax.vmap(jax.vmap(f, in_axes=(None, 0)), in_axes=(0, None)))(ps, us)
    assert nested.shape == (4, 3, x.size)
    for i in range(4):
        for j in range(3):
            np.testing.assert_array_equal(nested[i, j], f(ps[i], us[j]))


def test_lax_scan_matches_rollout():
    m = ball_on_floor()
    x = jnp.asarray(sliding_ball_state(m))
    us = jnp.asarray(np.linspace(0.2, 0.6, 6)[:, None])

    def scan_rollout(x, us):
        def body(x, u):
            x = ujax.step(m, x, u, kappa_grad=1e-4)
            return x, x
        return jax.lax.scan(body, x, us)[1]

    xs = jax.jit(scan_rollout)(x, us)
    ref = ujax.rollout(m, x, us, kappa_grad=1e-4)[1:]
    # a flat step restarts the contact solve from the neutral point, the rollout warm-starts
    np.testing.assert_allclose(xs, ref, rtol=0, atol=1e-9)
    w = jnp.linspace(-1, 1, ref.size).reshape(ref.shape)
    g_scan = jax.jit(jax.grad(lambda us: jnp.sum(w * scan_rollout(x, us))))(us)
    g_roll = jax.grad(lambda us: jnp.sum(w * ujax.rollout(m, x, us, kappa_grad=1e-4)[1:]))(us)
    np.testing.assert_allclose(g_scan, g_roll, rtol=1e-6, atol=1e-9)


# ---------------------------------------------------------------------------- check_grads
def test_check_grads_step_and_rollout():
    m = arm()
    x, u = jnp.asarray(x0_of(m)), jnp.asarray([0.3, -0.2])
    # parameters that stay valid under finite-difference perturbations (masses, inertia
    # diagonals, elbow damping, gravity); zero stiffnesses would turn negative
    names = list(m.param_names)
    idx = np.array([names.index(n) for n in (
        "body_mass[base]", "body_mass[arm]", "body_inertia[arm][yy]", "joint_damping[elbow][0]",
        "gravity[x]", "gravity[z]")])
    p0 = jnp.asarray(m.params)
    full = lambda q: p0.at[idx].set(q)
    q = p0[idx]
    # eps 1e-5: check_grads' default 1e-4 is 0.5% of the arm's inertia 0.02, and the central
    # difference's own truncation error (~eps^2) then exceeds its 1e-5 tolerance
    eps = 1e-5
    check_grads(lambda x, u, q: ujax.step(m, x, u, params=full(q), kappa_grad=None), (x, u, q),
                order=1, modes=["rev"], eps=eps)
    us = jnp.asarray(np.stack([[0.3, -0.2], [0.0, 0.1], [-0.2, 0.3], [0.1, 0.1]]))
    check_grads(lambda x, us, q: ujax.rollout(m, x, us, params=full(q), kappa_grad=None),
                (x, us, q), order=1, modes=["rev"], eps=eps)
    pm = pendulum()
    check_grads(lambda x, u: ujax.step(pm, x, u, kappa_grad=None),
                (jnp.asarray([0.4, -0.3]), jnp.asarray([0.2])), order=1, modes=["rev"], eps=eps)


# --------------------------------------------------------------------------------- errors
def stuck_ball():
    """A ball pressed into the floor, solved with one interior-point iteration."""
    m = ball_on_floor().with_options(max_iter=1, endgame_iter=0)
    x = np.concatenate([m.make_state().qpos, [0.5, 0.0, -2.0, 0, 0, 0]])
    x[2] = 0.09
    return m, jnp.asarray(x), jnp.asarray([0.4])


def test_non_convergence_is_an_error_naming_it():
    m, x, u = stuck_ball()
    with pytest.raises(Exception, match="did not converge"):
        jax.jit(lambda x: ujax.step(m, x, u))(x).block_until_ready()
    with pytest.raises(Exception, match="did not converge"):
        np.asarray(ujax.step(m, x, u))
    with pytest.raises(Exception, match="did not converge"):
        us = jnp.tile(u, (3, 1))
        jax.jit(lambda x: ujax.rollout(m, x, us))(x).block_until_ready()
    # both elements fail; which one rayon reports first is not specified
    with pytest.raises(Exception, match=r"batch element \d\) did not converge"):
        xs = jnp.stack([x, x])
        jax.jit(jax.vmap(lambda x: ujax.step(m, x, u)))(xs).block_until_ready()
    # the process survives; with enough iterations the same step converges
    ok = ujax.step(ball_on_floor(), x, u)
    assert np.all(np.isfinite(ok))


def test_bad_shapes_raise_shape_errors():
    m = arm()
    x = jnp.asarray(x0_of(m))
    with pytest.raises(ukemi.ShapeError, match="`x`"):
        jax.jit(lambda x: ujax.step(m, x, jnp.zeros(2)))(x[:-1])
    with pytest.raises(ukemi.ShapeError, match="`u`"):
        ujax.step(m, x, jnp.zeros(3))
    with pytest.raises(ukemi.ShapeError, match="`us`"):
        ujax.rollout(m, x, jnp.zeros(2))
    with pytest.raises(ukemi.ShapeError, match="`params`"):
        ujax.step(m, x, jnp.zeros(2), params=jnp.zeros(1))


def test_handler_checks_its_inputs_under_jit():
    """The Rust handlers validate what they receive (for callers of the raw targets)."""
    m = arm()
    h = np.asarray(ukemi._ukemi._xla_model_handle(m), np.uint64)
    x, u, p = x0_of(m), np.zeros(2), np.zeros((0,))
    out = jax.ShapeDtypeStruct(x.shape, jnp.float64)
    np.testing.assert_array_equal(raw("ukemi_flat_step", out, h, x, u, p, with_params=np.int32(0)),
                                  ujax.step(m, x, u))
    with pytest.raises(Exception, match=r"`x` has dtype float32"):
        raw("ukemi_flat_step", out, h, x.astype(np.float32), u, p, with_params=np.int32(0))
    with pytest.raises(Exception, match=r"ShapeError: shape of `u`"):
        raw("ukemi_flat_step", out, h, x, np.zeros(3), p, with_params=np.int32(0))
    with pytest.raises(Exception, match=r"ShapeError: shape of `x`"):
        raw("ukemi_flat_step", jax.ShapeDtypeStruct((4,), jnp.float64), h, x[:4], u, p,
            with_params=np.int32(0))
    with pytest.raises(Exception, match="unknown ukemi model handle"):
        raw("ukemi_flat_step", out, np.asarray(12345, np.uint64), x, u, p,
            with_params=np.int32(0))
    with pytest.raises(Exception, match="missing attribute `with_params`"):
        raw("ukemi_flat_step", out, h, x, u, p)
    with pytest.raises(Exception, match="ShapeError: shape of `params`"):
        raw("ukemi_flat_step", out, h, x, u, p, with_params=np.int32(1))


def test_step_with_status_reports_failures_as_an_output_under_jit():
    """Non-convergence as data: the status output flags the failed batch element, the others
    are the normal steps, and gradients of converged elements flow."""
    m = ball_on_floor()
    bad = m.with_options(max_iter=1, endgame_iter=0)
    x_ok = sliding_ball_state(m)
    x_hit = np.concatenate([m.make_state().qpos, [0.0, 0.0, -3.0, 0, 0, 0]])
    xs = jnp.asarray(np.stack([x_ok, x_hit]))
    u = jnp.zeros((2, m.nu))
    for name in ("ffi", "callback"):
        with backend(name):
            xn, st = jax.jit(lambda x, u: ujax.step_with_status(bad, x, u))(xs, u)
            assert st.dtype == jnp.int32 and st.shape == (2,)
            assert int(st[1]) != 0  # the impact cannot converge in one iteration
            assert np.all(np.isfinite(np.asarray(xn)))
            xn_good, st_good = ujax.step_with_status(m, xs, u)
            np.testing.assert_array_equal(np.asarray(st_good), [0, 0])
            np.testing.assert_allclose(xn_good, ujax.step(m, xs, u), rtol=0, atol=1e-12)
            g = jax.grad(lambda x: ujax.step_with_status(m, x, u[0])[0].sum())(xs[0])
            np.testing.assert_allclose(g, jax.grad(lambda x: ujax.step(m, x, u[0]).sum())(xs[0]),
                                       rtol=1e-12, atol=1e-12)
