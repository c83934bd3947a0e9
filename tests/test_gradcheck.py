"""torch.autograd.gradcheck and jax check_grads on ukemi.torch / ukemi.jax steps and rollouts
for a pendulum, a cartpole, a box sliding on the floor, gymnasium's hopper standing on the
floor, a cube resting on a box on its edge crossings and a capsule bridging two boxes on the
crossings of its segment with their edges, with respect to state, controls and parameters (the contact scenes in a fixed active set,
where the hard step is smooth, so the exact gradient, kappa_grad=None, must match finite
differences)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import ukemi

torch = pytest.importorskip("torch")
import ukemi.torch as ut  # noqa: E402


def tight(m):
    return m.with_options(rtol=1e-14, max_iter=100)


def pendulum():
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_body("bob", mass=1.0, inertia=(1e-3, 1e-3, 1e-3), pos=(0, 0, -0.5))
    b.add_joint("hinge", kind="revolute", parent="world", child="bob", axis=(0, 1, 0),
                parent_anchor=(0, 0, 0), child_anchor=(0, 0, 0.5), damping=0.1)
    b.add_actuator("motor", joint="hinge", gear=2.0)
    return tight(b.compile()), np.array([0.4, -0.8])


def cartpole():
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_body("cart", mass=1.0, inertia=(0.01, 0.01, 0.01), pos=(0, 0, 0))
    b.add_body("pole", mass=0.2, inertia=(0.004, 0.004, 1e-4), pos=(0, 0, 0.3))
    b.add_joint("slider", kind="prismatic", parent="world", child="cart", axis=(1, 0, 0))
    b.add_joint("hinge", kind="revolute", parent="cart", child="pole", axis=(0, 1, 0),
                parent_anchor=(0, 0, 0), child_anchor=(0, 0, -0.3))
    b.add_actuator("push", joint="slider", gear=5.0)
    return tight(b.compile()), np.array([0.1, 0.2, 0.3, -0.5])


def settled(b, nsteps):
    """The compiled (tight) model of ``b`` and its state after ``nsteps`` unactuated steps."""
    m = tight(b.compile())
    s = m.make_state()
    for _ in range(nsteps):
        s, _ = ukemi.step(m, s, np.zeros(m.nu))
    return m, s


def sliding_box():
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("floor", body="world", shape="plane", friction=0.3)
    b.add_body("box", mass=1.0, inertia=(1 / 600, 1 / 600, 1 / 600), pos=(0, 0, 0.05))
    b.add_joint("free", kind="floating", parent="world", child="box")
    b.add_geom("box", body="box", shape="box", size=(0.05, 0.05, 0.05), friction=0.3)
    b.add_actuator("push", joint="free", gear=1.0)
    m, s = settled(b, 20)
    x = np.concatenate([s.qpos, [1.0, 0.2, 0.0, 0.0, 0.0, 0.0]])  # sliding at ~1 m/s
    return m, x


def hopper():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = tight(ukemi.Model.from_xml_path(ukemi.gymnasium_asset_path("hopper")))
    s = m.make_state()
    for _ in range(30):  # stand on the floor
        s, _ = ukemi.step(m, s, np.zeros(m.nu))
    return m, np.concatenate([s.qpos, s.qvel])


def turned_cube():
    """A cube resting on a box's top turned 30° about the vertical: every corner lies beyond
    the other's face, so the eight crossings of their edges hold it (box_edges.rs)."""
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("table", body="world", shape="box", size=(0.1, 0.1, 0.1), pos=(0, 0, 0.1))
    c, s = np.cos(np.pi / 12), np.sin(np.pi / 12)
    b.add_body("cube", mass=1.0, inertia=(1 / 150, 1 / 150, 1 / 150), pos=(0.01, 0, 0.3005),
               quat=(c, 0, 0, s))
    b.add_joint("free", kind="floating", parent="world", child="cube")
    b.add_geom("cube", body="cube", shape="box", size=(0.1, 0.1, 0.1), friction=0.5)
    b.add_actuator("push", joint="free", gear=1.0)
    m, s = settled(b, 30)
    return m, np.concatenate([s.qpos, s.qvel])


def capsule_bridge():
    """A capsule lying across two boxes with a gap between them, held only where its segment
    crosses their top edges (box_edges.rs, capsule crossings)."""
    b = ukemi.ModelBuilder(timestep=0.01)
    for k, y in enumerate((0.2, -0.2)):
        b.add_geom(f"block{k}", body="world", shape="box", size=(0.1, 0.1, 0.1), pos=(0, y, 0.1))
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    b.add_body("bar", mass=1.0, inertia=(0.04, 0.04, 2e-4), pos=(0.02, 0, 0.2205), quat=(c, s, 0, 0))
    b.add_joint("free", kind="floating", parent="world", child="bar")
    b.add_geom("bar", body="bar", shape="capsule", size=(0.02, 0.35), friction=0.5)
    b.add_actuator("push", joint="free", gear=1.0)
    m, s = settled(b, 30)
    return m, np.concatenate([s.qpos, s.qvel])


SCENES = {"pendulum": pendulum, "cartpole": cartpole, "sliding_box": sliding_box, "hopper": hopper,
          "turned_cube": turned_cube, "capsule_bridge": capsule_bridge}


@pytest.mark.parametrize("name", list(SCENES))
def test_gradcheck_step_state_ctrl_params(name):
    m, x0 = SCENES[name]()
    names = list(m.param_names)
    pick = [i for i, n in enumerate(names) if n.startswith(("body_mass", "gravity[z]", "geom_friction"))]
    base = torch.tensor(m.params)
    sel = torch.tensor(pick)

    def f(x, u, psub):
        p = base.index_put((sel,), psub)
        return ut.step(m, x, u, params=p, kappa_grad=None)

    x = torch.tensor(x0, requires_grad=True)
    u = torch.full((m.nu,), 0.1, dtype=torch.float64, requires_grad=True)
    psub = base[sel].clone().requires_grad_(True)
    assert torch.autograd.gradcheck(f, (x, u, psub), eps=1e-6, atol=1e-5, rtol=1e-4)


@pytest.mark.parametrize("name", ["pendulum", "sliding_box"])
def test_gradcheck_rollout(name):
    m, x0 = SCENES[name]()
    x = torch.tensor(x0, requires_grad=True)
    us = torch.full((5, m.nu), 0.1, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda x, us: ut.rollout(m, x, us, kappa_grad=None), (x, us),
                                    eps=1e-6, atol=1e-5, rtol=1e-4)


def test_float32_is_a_clear_error():
    m, x0 = pendulum()
    with pytest.raises(TypeError, match="float64"):
        ut.step(m, torch.tensor(x0, dtype=torch.float32), torch.zeros(1, dtype=torch.float32))


def test_batch_of_64_equals_single_calls_and_threads_are_settable():
    m, x0 = cartpole()
    rng = np.random.default_rng(0)
    xs = torch.tensor(x0 + 0.1 * rng.normal(size=(64, x0.size)))
    u = torch.tensor([0.3], dtype=torch.float64)
    f = lambda x: (ut.step(m, x, u) ** 2).sum()
    g = torch.func.vmap(torch.func.grad(f))(xs)
    for i in range(0, 64, 9):
        torch.testing.assert_close(g[i], torch.func.grad(f)(xs[i]))
    n = ukemi.get_num_threads()
    ukemi.set_num_threads(1)
    try:
        assert ukemi.get_num_threads() == 1
        torch.testing.assert_close(torch.func.vmap(torch.func.grad(f))(xs), g)
    finally:
        ukemi.set_num_threads(0)
    assert ukemi.get_num_threads() == n


@pytest.mark.parametrize("name", list(SCENES))
def test_jax_check_grads_step_and_rollout(name):
    """The same scenes through ukemi.jax (XLA FFI backend): reverse-mode check_grads with respect
    to state, controls and the selected parameters, for a step and a short rollout."""
    jax = pytest.importorskip("jax")
    from jax.test_util import check_grads

    import ukemi.jax as uj

    m, x0 = SCENES[name]()
    names = list(m.param_names)
    pick = np.array([i for i, n in enumerate(names)
                     if n.startswith(("body_mass", "gravity[z]", "geom_friction"))])
    base = jax.numpy.asarray(m.params)
    full = lambda q: base.at[pick].set(q)
    x = jax.numpy.asarray(x0)
    u = jax.numpy.full((m.nu,), 0.1)
    q = base[pick]
    check_grads(lambda x, u, q: uj.step(m, x, u, params=full(q), kappa_grad=None), (x, u, q),
                order=1, modes=["rev"], eps=1e-5, atol=1e-4, rtol=1e-4)
    us = jax.numpy.full((3, m.nu), 0.1)
    check_grads(lambda x, us: uj.rollout(m, x, us, kappa_grad=None), (x, us),
                order=1, modes=["rev"], eps=1e-5, atol=1e-4, rtol=1e-4)


@pytest.mark.parametrize("name", ["pendulum", "sliding_box", "hopper"])
def test_raw_step_jacobians_equal_reverse_mode_jacobians(name):
    """The forward-mode op (one engine linearisation, raw flat coordinates incl. quaternion
    normalisation) equals jax.jacrev of the differentiable step, and torch's equals jax's."""
    jax = pytest.importorskip("jax")
    import ukemi.jax as uj

    m, x0 = SCENES[name]()
    x = jax.numpy.asarray(x0)
    u = jax.numpy.full((m.nu,), 0.1)
    a, b = uj.step_jacobians(m, x, u, kappa_grad=1e-6)
    ra, rb = jax.jacrev(lambda x, u: uj.step(m, x, u, kappa_grad=1e-6), argnums=(0, 1))(x, u)
    np.testing.assert_allclose(a, ra, rtol=1e-9, atol=1e-11)
    np.testing.assert_allclose(b, rb, rtol=1e-9, atol=1e-11)
    ta, tb = ut.step_jacobians(m, torch.tensor(x0), torch.full((m.nu,), 0.1, dtype=torch.float64),
                               kappa_grad=1e-6)
    np.testing.assert_allclose(ta.numpy(), a, rtol=0, atol=0)
    np.testing.assert_allclose(tb.numpy(), b, rtol=0, atol=0)
    # batched under vmap
    xs = jax.numpy.stack([x, x])
    av, _ = jax.vmap(lambda x: uj.step_jacobians(m, x, u, kappa_grad=1e-6))(xs)
    np.testing.assert_allclose(av[1], a, rtol=0, atol=1e-14)


def test_torch_library_opcheck_on_the_custom_ops():
    """torch.library.opcheck: schema, fake-tensor (meta) kernels, autograd registration and
    vmap rules of the ukemi custom ops are consistent."""
    from ukemi import torch as utm

    m, x0 = SCENES["cartpole"]()
    key = utm._key(m)
    x = torch.tensor(x0)
    u = torch.tensor([0.1], dtype=torch.float64)
    p = torch.zeros(0, dtype=torch.float64)
    torch.library.opcheck(utm._step_op, (key, x, u, p, False))
    g = torch.ones_like(x)
    torch.library.opcheck(utm._step_vjp_op, (key, -1.0, x, u, p, g, False))
    us = torch.full((3, 1), 0.1, dtype=torch.float64)
    torch.library.opcheck(utm._rollout_op, (key, x, us, p, False))


def test_torch_func_jacrev_equals_the_engine_jacobians():
    m, x0 = SCENES["sliding_box"]()
    x = torch.tensor(x0)
    u = torch.full((m.nu,), 0.1, dtype=torch.float64)
    ja, jb = torch.func.jacrev(lambda x, u: ut.step(m, x, u, kappa_grad=1e-6), argnums=(0, 1))(x, u)
    a, b = ut.step_jacobians(m, x, u, kappa_grad=1e-6)
    torch.testing.assert_close(ja, a, rtol=1e-9, atol=1e-11)
    torch.testing.assert_close(jb, b, rtol=1e-9, atol=1e-11)
