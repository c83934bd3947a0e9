"""ukemi steps and rollouts as differentiable JAX functions.

``step`` and ``rollout`` are ``jax.custom_vjp`` functions: the forward pass and the backward
pass (the engine's implicit-gradient VJP at ``kappa_grad``) run in Rust through
``jax.pure_callback``, so they work under ``jax.jit``, ``jax.vmap`` (batched in Rust, in
parallel) and ``jax.grad``/``jax.vjp``, inside ``lax.scan`` too. Forward-mode (``jax.jvp``,
``jacfwd``) is not available through a custom VJP; use ``jax.jacrev``.

The state is flat: ``x = [qpos, qvel]`` (nq + nv, float64, ball/free quaternions as 4 numbers).
Importing this module enables ``jax_enable_x64``: the engine works in float64, and float32
round trips would spoil its 1e-10 tolerances.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import _flat
from ._gradients import resolve_kappa

jax.config.update("jax_enable_x64", True)

__all__ = ["rollout", "step"]


def _prep(model, x, u, params, kappa_grad):
    k = resolve_kappa(model, kappa_grad)
    x = jnp.asarray(x, jnp.float64)
    u = jnp.asarray(u if u is not None else jnp.zeros(model.nu), jnp.float64)
    p = None if params is None else jnp.asarray(params, jnp.float64)
    return k, x, u, p


def _lead(*shapes):
    return jnp.broadcast_shapes(*shapes)


@functools.lru_cache(maxsize=None)
def _step_fn(model, kappa, with_params):
    nx, nu, npar = _flat.sizes(model)

    def out_shape(x, u, p):
        leads = [x.shape[:-1], u.shape[:-1]] + ([p.shape[:-1]] if with_params else [])
        return jax.ShapeDtypeStruct(_lead(*leads) + (nx,), jnp.float64)

    def fwd_cb(x, u, p):
        return _flat.step(model, x, u, p if with_params else None)

    def call_fwd(x, u, p):
        return jax.pure_callback(fwd_cb, out_shape(x, u, p), x, u, p,
                                 vmap_method="broadcast_all")

    def bwd_cb(x, u, p, g):
        gx, gu, gp = _flat.step_vjp(model, x, u, p if with_params else None, g, kappa)
        return gx, gu, (gp if with_params else np.zeros(np.shape(p)))

    @jax.custom_vjp
    def f(x, u, p):
        return call_fwd(x, u, p)

    def f_fwd(x, u, p):
        return call_fwd(x, u, p), (x, u, p)

    def f_bwd(res, g):
        x, u, p = res
        shapes = (jax.ShapeDtypeStruct(x.shape, jnp.float64),
                  jax.ShapeDtypeStruct(u.shape, jnp.float64),
                  jax.ShapeDtypeStruct(p.shape, jnp.float64))
        return jax.pure_callback(bwd_cb, shapes, x, u, p, g, vmap_method="broadcast_all")

    f.defvjp(f_fwd, f_bwd)
    return f


@functools.lru_cache(maxsize=None)
def _rollout_fn(model, kappa, with_params):
    nx, nu, npar = _flat.sizes(model)

    def out_shape(x0, us, p):
        leads = [x0.shape[:-1], us.shape[:-2]] + ([p.shape[:-1]] if with_params else [])
        return jax.ShapeDtypeStruct(_lead(*leads) + (us.shape[-2] + 1, nx), jnp.float64)

    def fwd_cb(x0, us, p):
        return _flat.rollout(model, x0, us, p if with_params else None)

    def call_fwd(x0, us, p):
        return jax.pure_callback(fwd_cb, out_shape(x0, us, p), x0, us, p,
                                 vmap_method="broadcast_all")

    def bwd_cb(x0, us, p, g):
        gx, gu, gp = _flat.rollout_vjp(model, x0, us, p if with_params else None, g, kappa)
        return gx, gu, (gp if with_params else np.zeros(np.shape(p)))

    @jax.custom_vjp
    def f(x0, us, p):
        return call_fwd(x0, us, p)

    def f_fwd(x0, us, p):
        return call_fwd(x0, us, p), (x0, us, p)

    def f_bwd(res, g):
        x0, us, p = res
        shapes = (jax.ShapeDtypeStruct(x0.shape, jnp.float64),
                  jax.ShapeDtypeStruct(us.shape, jnp.float64),
                  jax.ShapeDtypeStruct(p.shape, jnp.float64))
        return jax.pure_callback(bwd_cb, shapes, x0, us, p, g, vmap_method="broadcast_all")

    f.defvjp(f_fwd, f_bwd)
    return f


def step(model, x, u=None, params=None, kappa_grad=3e-4):
    """One differentiable step of the flat state ``x`` (..., nq + nv) with controls
    ``u`` (..., nu) and optional parameters ``params`` (..., nparams) (``model.params`` layout).
    Gradients are the engine's implicit gradients at ``kappa_grad`` (None: exact).
    A step that fails to converge raises ``ukemi.ConvergenceError`` (through JAX's callback
    machinery, as an ``XlaRuntimeError`` under ``jit``)."""
    k, x, u, p = _prep(model, x, u, params, kappa_grad)
    with_params = p is not None
    if p is None:
        p = jnp.zeros((0,), jnp.float64)
    return _step_fn(model, k, with_params)(x, u, p)


def rollout(model, x0, us, params=None, kappa_grad=3e-4):
    """A differentiable rollout: ``x0`` (..., nq + nv), ``us`` (..., T, nu) → states
    (..., T + 1, nq + nv), computed in Rust in one call; the backward pass is the engine's
    reverse sweep (``ukemi.rollout_vjp``)."""
    k, x0, us, p = _prep(model, x0, us, params, kappa_grad)
    with_params = p is not None
    if p is None:
        p = jnp.zeros((0,), jnp.float64)
    return _rollout_fn(model, k, with_params)(x0, us, p)
