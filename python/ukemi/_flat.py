"""Batched flat-state kernels shared by the JAX and torch layers (numpy in, numpy out).

A flat state is ``x = [qpos, qvel]`` (nq + nv). Leading axes of ``x``, ``u`` and ``params``
broadcast against each other; the batch runs in parallel in Rust with the GIL released.
"""

from __future__ import annotations

import numpy as np

from . import _ukemi
from .errors import ShapeError


def sizes(model):
    return model.nq + model.nv, model.nu, len(model.params)


def _lead(name, a, n):
    if a.shape[-1:] != (n,):
        raise ShapeError(f"shape of `{name}`: last axis must be {n}, got {a.shape}")
    return a.shape[:-1]


def _count(lead) -> int:
    return int(np.prod(lead, dtype=np.int64))


def _flatten(a, lead, n):
    # explicit batch size: reshape(-1, 0) is ambiguous when n == 0 (no controls)
    return np.ascontiguousarray(np.broadcast_to(a, lead + (n,)).reshape(_count(lead), n),
                                dtype=np.float64)


def unbroadcast(g, shape):
    """Sum a broadcast gradient back to ``shape``."""
    g = np.asarray(g)
    while g.ndim > len(shape):
        g = g.sum(axis=0)
    for i, s in enumerate(shape):
        if s == 1 and g.shape[i] != 1:
            g = g.sum(axis=i, keepdims=True)
    return g.reshape(shape)


def step(model, x, u, p, keep=False):
    """Steps; ``keep`` keeps each solved step in Rust for the ``step_vjp`` with the same inputs
    that differentiation calls next (it then does not solve the step again)."""
    nx, nu, np_ = sizes(model)
    x, u = np.asarray(x, np.float64), np.asarray(u, np.float64)
    shapes = [_lead("x", x, nx), _lead("u", u, nu)]
    if p is not None:
        p = np.asarray(p, np.float64)
        shapes.append(_lead("params", p, np_))
    lead = np.broadcast_shapes(*shapes)
    P = None if p is None else _flatten(p, lead, np_)
    out = _ukemi._flat_step(model, _flatten(x, lead, nx), _flatten(u, lead, nu), P, keep)
    return out.reshape(lead + (nx,))


def step_vjp(model, x, u, p, g, kappa_grad):
    nx, nu, np_ = sizes(model)
    x, u, g = (np.asarray(a, np.float64) for a in (x, u, g))
    shapes = [_lead("x", x, nx), _lead("u", u, nu), _lead("cotangent", g, nx)]
    if p is not None:
        p = np.asarray(p, np.float64)
        shapes.append(_lead("params", p, np_))
    lead = np.broadcast_shapes(*shapes)
    P = None if p is None else _flatten(p, lead, np_)
    gx, gu, gp = _ukemi._flat_step_vjp(model, _flatten(x, lead, nx), _flatten(u, lead, nu),
                                       _flatten(g, lead, nx), kappa_grad, P, p is not None)
    gx = unbroadcast(gx.reshape(lead + (nx,)), x.shape)
    gu = unbroadcast(gu.reshape(lead + (nu,)), u.shape)
    gp = None if p is None else unbroadcast(gp.reshape(lead + (np_,)), p.shape)
    return gx, gu, gp


def rollout(model, x0, us, p, keep=False):
    """Rollouts; ``keep`` keeps the forward pass in Rust for the ``rollout_vjp`` with the same
    inputs that differentiation calls next (it then solves no step again)."""
    nx, nu, np_ = sizes(model)
    x0, us = np.asarray(x0, np.float64), np.asarray(us, np.float64)
    if us.ndim < 2 or us.shape[-1] != nu:
        raise ShapeError(f"shape of `us`: expected (..., T, {nu}), got {us.shape}")
    t = us.shape[-2]
    shapes = [_lead("x0", x0, nx), us.shape[:-2]]
    if p is not None:
        p = np.asarray(p, np.float64)
        shapes.append(_lead("params", p, np_))
    lead = np.broadcast_shapes(*shapes)
    U = np.ascontiguousarray(np.broadcast_to(us, lead + (t, nu)).reshape(_count(lead), t, nu))
    P = None if p is None else _flatten(p, lead, np_)
    out = _ukemi._flat_rollout(model, _flatten(x0, lead, nx), U, P, keep)
    return out.reshape(lead + (t + 1, nx))


def rollout_vjp(model, x0, us, p, g, kappa_grad):
    nx, nu, np_ = sizes(model)
    x0, us, g = (np.asarray(a, np.float64) for a in (x0, us, g))
    t = us.shape[-2]
    shapes = [_lead("x0", x0, nx), us.shape[:-2], g.shape[:-2]]
    if p is not None:
        p = np.asarray(p, np.float64)
        shapes.append(_lead("params", p, np_))
    lead = np.broadcast_shapes(*shapes)
    U = np.ascontiguousarray(np.broadcast_to(us, lead + (t, nu)).reshape(_count(lead), t, nu))
    G = np.ascontiguousarray(np.broadcast_to(g, lead + (t + 1, nx)).reshape(_count(lead), t + 1, nx))
    P = None if p is None else _flatten(p, lead, np_)
    gx, gu, gp = _ukemi._flat_rollout_vjp(model, _flatten(x0, lead, nx), U, G, kappa_grad, P,
                                          p is not None)
    gx = unbroadcast(gx.reshape(lead + (nx,)), x0.shape)
    gu = unbroadcast(gu.reshape(lead + (t, nu)), us.shape)
    gp = None if p is None else unbroadcast(gp.reshape(lead + (np_,)), p.shape)
    return gx, gu, gp


def step_jacobians(model, x, u, p, kappa_grad, with_params):
    """Raw flat Jacobians ``(∂x⁺/∂x (…, nx, nx), ∂x⁺/∂u (…, nx, nu), ∂x⁺/∂θ (…, nx, np))``."""
    nx, nu, np_ = sizes(model)
    x, u = np.asarray(x, np.float64), np.asarray(u, np.float64)
    shapes = [_lead("x", x, nx), _lead("u", u, nu)]
    if p is not None:
        p = np.asarray(p, np.float64)
        shapes.append(_lead("params", p, np_))
    lead = np.broadcast_shapes(*shapes)
    P = None if p is None else _flatten(p, lead, np_)
    a, b, c = _ukemi._flat_step_jacobians(model, _flatten(x, lead, nx), _flatten(u, lead, nu),
                                          kappa_grad, P, with_params)
    npc = np_ if with_params else 0
    return (a.reshape(lead + (nx, nx)), b.reshape(lead + (nx, nu)), c.reshape(lead + (nx, npc)))
