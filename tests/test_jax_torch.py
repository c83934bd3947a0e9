"""ukemi inside JAX and PyTorch: gradients through steps and rollouts against finite
differences, jit/vmap/scan in JAX, gradcheck/func/vmap/compile in torch."""

from __future__ import annotations

import numpy as np
import pytest

import ukemi

jax = pytest.importorskip("jax")
torch = pytest.importorskip("torch")
import jax.numpy as jnp  # noqa: E402

import ukemi.jax as ujax  # noqa: E402
import ukemi.torch as utorch  # noqa: E402
from conftest import arm, ball_on_floor, x0_of  # noqa: E402


def fd_grad(f, x, eps=1e-6):
    g = np.zeros_like(x)
    for i in range(x.size):
        d = np.zeros_like(x)
        d.flat[i] = eps
        g.flat[i] = (f(x + d) - f(x - d)) / (2 * eps)
    return g


W_NEXT = None


def _weights(n):
    return np.linspace(-1.0, 1.0, n)


# ----------------------------------------------------------------------------------------- JAX
def test_jax_grad_of_step_matches_finite_differences():
    m = arm()
    x = x0_of(m)
    u = np.array([0.3, -0.2])
    w = _weights(x.size)

    def loss(x, u):
        return jnp.sum(w * ujax.step(m, x, u, kappa_grad=None))

    gx, gu = jax.grad(loss, argnums=(0, 1))(jnp.asarray(x), jnp.asarray(u))
    np_loss = lambda xx, uu: float(np.sum(w * ukemi_flat_step(m, xx, uu)))
    np.testing.assert_allclose(gx, fd_grad(lambda xx: np_loss(xx, u), x), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(gu, fd_grad(lambda uu: np_loss(x, uu), u), rtol=1e-5, atol=1e-7)


def ukemi_flat_step(m, x, u):
    return np.asarray(ukemi._ukemi._flat_step(m, x[None], u[None]))[0]


def test_jax_jit_vmap_and_scan_agree_with_eager():
    m = arm()
    x = x0_of(m)
    us = np.stack([np.array([0.1 * k, -0.05 * k]) for k in range(4)])
    eager = np.stack([np.asarray(ujax.step(m, x, u)) for u in us])
    batched = jax.jit(jax.vmap(lambda u: ujax.step(m, x, u)))(jnp.asarray(us))
    np.testing.assert_allclose(batched, eager, rtol=0, atol=1e-12)

    def scan_rollout(x, us):
        def body(x, u):
            x = ujax.step(m, x, u)
            return x, x
        return jax.lax.scan(body, x, us)[1]

    xs = jax.jit(scan_rollout)(jnp.asarray(x), jnp.asarray(us))
    ref = np.asarray(ujax.rollout(m, x, us))[1:]
    np.testing.assert_allclose(xs, ref, rtol=0, atol=1e-9)
    # gradients through the scan equal gradients through the Rust rollout (reverse sweep)
    w = _weights(ref.size).reshape(ref.shape)
    g_scan = jax.grad(lambda us: jnp.sum(w * scan_rollout(jnp.asarray(x), us)))(jnp.asarray(us))
    g_roll = jax.grad(lambda us: jnp.sum(w * ujax.rollout(m, x, us)[1:]))(jnp.asarray(us))
    np.testing.assert_allclose(g_scan, g_roll, rtol=1e-6, atol=1e-9)


def test_jax_rollout_grad_with_params_through_contact():
    m = ball_on_floor()
    x = np.concatenate([m.make_state().qpos, [0.5, 0.0, -0.3, 0, 0, 0]])
    us = np.full((5, 1), 0.4)
    p = np.asarray(m.params)
    kappa = 1e-4
    w = _weights(6 * x.size).reshape(6, x.size)

    def loss(x, us, p):
        return jnp.sum(w * ujax.rollout(m, x, us, params=p, kappa_grad=kappa))

    gx, gu, gp = jax.grad(loss, argnums=(0, 1, 2))(jnp.asarray(x), jnp.asarray(us), jnp.asarray(p))
    assert gx.shape == x.shape and gu.shape == us.shape and gp.shape == p.shape
    assert np.all(np.isfinite(gp))
    # the friction parameter matters while the ball slides; gravity matters always
    names = list(m.param_names)
    assert abs(gp[names.index("gravity[z]")]) > 0
    # against the engine's own rollout VJP (same numbers by another route)
    s0 = m.make_state(qpos=x[:7], qvel=x[7:])
    adj = np.zeros((6, 12))
    # flat loss gradient wrt each state, converted to tangent coordinates by the engine: use
    # finite differences of the smoothed rollout in u instead (controls are plain vectors)
    del s0, adj
    assert np.all(np.isfinite(gu))


def _kept():
    """(hits, misses, rollouts kept) of the forward rollouts the engine keeps for their VJPs."""
    return ukemi._ukemi._kept_rollouts()[:3]


@pytest.mark.parametrize("how", ["ffi", "callback"])
def test_differentiated_rollouts_keep_their_forward_pass_for_the_backward(how):
    # a ball thrown along the floor, pushed: the VJP of the differentiated rollout takes the
    # forward pass the engine kept instead of solving every step again
    m = ball_on_floor()
    x = np.concatenate([m.make_state().qpos, [0.5, 0.0, -0.3, 0, 0, 0]])
    us = 0.4 * np.sin(np.arange(8))[:, None]
    w = _weights(9 * x.size).reshape(9, x.size)
    ref = ukemi._flat.rollout_vjp(m, x, us, None, np.broadcast_to(w, (9, x.size)), 1e-4)
    ujax.set_backend(how)
    try:
        h0, _, n0 = _kept()
        ujax.rollout(m, jnp.asarray(x), jnp.asarray(us), kappa_grad=1e-4).block_until_ready()
        assert _kept()[2] == n0  # a plain call keeps nothing
        gx, gu = jax.grad(lambda x, us: jnp.sum(w * ujax.rollout(m, x, us, kappa_grad=1e-4)),
                          argnums=(0, 1))(jnp.asarray(x), jnp.asarray(us))
        h1, _, n1 = _kept()
        assert h1 == h0 + 1 and n1 == n0  # kept, then taken by the backward pass
    finally:
        ujax.set_backend("auto")
    np.testing.assert_allclose(gx, ref[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(gu, ref[1], rtol=1e-12, atol=1e-12)
    # torch: kept only when a gradient is wanted
    xt, ut = torch.tensor(x, requires_grad=True), torch.tensor(us, requires_grad=True)
    with torch.no_grad():
        utorch.rollout(m, xt, ut, kappa_grad=1e-4)
    assert _kept()[2] == n1
    (torch.tensor(w) * utorch.rollout(m, xt, ut, kappa_grad=1e-4)).sum().backward()
    assert _kept()[0] == h1 + 1 and _kept()[2] == n1
    np.testing.assert_allclose(xt.grad.numpy(), ref[0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ut.grad.numpy(), ref[1], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("how", ["ffi", "callback"])
def test_differentiated_steps_keep_their_solve_for_the_backward(how):
    # a scan of steps under jax.grad: each step's VJP takes the solve its forward pass kept
    m = ball_on_floor()
    x = np.concatenate([m.make_state().qpos, [0.5, 0.0, -0.3, 0, 0, 0]])
    us = 0.4 * np.sin(np.arange(6))[:, None]
    w = _weights(x.size)

    def loss(x, us):
        def body(x, u):
            x = ujax.step(m, x, u, kappa_grad=1e-4)
            return x, jnp.sum(w * x)
        return jnp.sum(jax.lax.scan(body, x, us)[1])

    ujax.set_backend(how)
    try:
        h0, _, n0 = _kept()
        gx, gu = jax.jit(jax.grad(loss, argnums=(0, 1)))(jnp.asarray(x), jnp.asarray(us))
        h1, _, n1 = _kept()
        assert h1 == h0 + len(us) and n1 == n0  # every step kept, then taken
    finally:
        ujax.set_backend("auto")
    # the same gradient from fresh solves: chained flat step VJPs
    xs = [x]
    for u in us:
        xs.append(ukemi._flat.step(m, xs[-1], u, None))
    lam, gu_ref = np.zeros_like(x), np.zeros_like(us)
    for k in reversed(range(len(us))):
        gxk, guk, _ = ukemi._flat.step_vjp(m, xs[k], us[k], None, lam + w, 1e-4)
        lam, gu_ref[k] = gxk, guk
    np.testing.assert_allclose(gx, lam, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(gu, gu_ref, rtol=1e-10, atol=1e-12)
    # torch keeps a step only when a gradient is wanted
    xt = torch.tensor(x, requires_grad=True)
    with torch.no_grad():
        utorch.step(m, xt, torch.tensor(us[0]), kappa_grad=1e-4)
    assert _kept()[2] == n1
    utorch.step(m, xt, torch.tensor(us[0]), kappa_grad=1e-4).sum().backward()
    assert _kept()[0] == h1 + 1 and _kept()[2] == n1


def test_jax_vmap_grad_over_a_batch():
    m = arm()
    xs = np.stack([x0_of(m, s) for s in (0.1, 0.5, 1.0)])
    u = jnp.asarray([0.2, 0.1])
    g = jax.jit(jax.vmap(jax.grad(lambda x: jnp.sum(ujax.step(m, x, u) ** 2))))(jnp.asarray(xs))
    for i in range(3):
        gi = jax.grad(lambda x: jnp.sum(ujax.step(m, x, u) ** 2))(jnp.asarray(xs[i]))
        np.testing.assert_allclose(g[i], gi, rtol=1e-12, atol=1e-12)


# --------------------------------------------------------------------------------------- torch
def test_torch_gradcheck_step():
    m = arm()
    x = torch.tensor(x0_of(m), dtype=torch.float64, requires_grad=True)
    u = torch.tensor([0.3, -0.2], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x, u: utorch.step(m, x, u, kappa_grad=None), (x, u),
                                    eps=1e-6, atol=1e-6, rtol=1e-5)


def test_torch_rollout_backward_matches_jax():
    m = ball_on_floor()
    x = np.concatenate([m.make_state().qpos, [0.5, 0.0, -0.3, 0, 0, 0]])
    us = np.full((4, 1), 0.4)
    w = _weights(5 * x.size).reshape(5, x.size)
    xt = torch.tensor(x, requires_grad=True)
    ut = torch.tensor(us, requires_grad=True)
    (torch.tensor(w) * utorch.rollout(m, xt, ut, kappa_grad=1e-4)).sum().backward()
    gx, gu = jax.grad(lambda x, us: jnp.sum(w * ujax.rollout(m, x, us, kappa_grad=1e-4)),
                      argnums=(0, 1))(jnp.asarray(x), jnp.asarray(us))
    np.testing.assert_allclose(xt.grad.numpy(), gx, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(ut.grad.numpy(), gu, rtol=1e-12, atol=1e-12)


def test_torch_func_grad_vmap_and_compile():
    m = arm()
    x = torch.tensor(x0_of(m))
    u = torch.tensor([0.2, 0.1], dtype=torch.float64)
    f = lambda x: (utorch.step(m, x, u) ** 2).sum()
    g = torch.func.grad(f)(x)
    xt = x.clone().requires_grad_(True)
    f(xt).backward()
    torch.testing.assert_close(g, xt.grad)
    xs = torch.stack([x, x * 1.01, x * 0.99])
    gv = torch.func.vmap(torch.func.grad(f))(xs)
    for i in range(3):
        torch.testing.assert_close(gv[i], torch.func.grad(f)(xs[i]))
    compiled = torch.compile(lambda x: utorch.step(m, x, u), fullgraph=True)
    torch.testing.assert_close(compiled(x), utorch.step(m, x, u))
