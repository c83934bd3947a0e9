"""ukemi steps and rollouts as differentiable JAX functions.

``step`` and ``rollout`` are ``jax.custom_vjp`` functions: the forward pass and the backward
pass (the engine's implicit-gradient VJP at ``kappa_grad``) run in Rust, so they work under
``jax.jit``, ``jax.vmap`` (one call with the whole batch, run in parallel in Rust) and
``jax.grad``/``jax.vjp``, inside ``lax.scan`` too. Forward-mode (``jax.jvp``, ``jacfwd``) is not
available through a custom VJP; use ``jax.jacrev``.

Two backends compute the same numbers behind the same interface:

* ``"ffi"`` (primary): XLA FFI handlers written in Rust (``bindings/src/xla_ffi.rs``),
  registered with ``jax.ffi`` on import and called with ``jax.ffi.ffi_call``. No Python and no
  GIL on the call path; overhead per call is well under a microsecond inside ``lax.scan``.
  Engine errors (shape, input, non-convergence) surface as ``JaxRuntimeError`` whose message
  names the problem (e.g. ``ConvergenceError: ... did not converge ...``).
* ``"callback"`` (fallback): ``jax.pure_callback`` into the same Rust functions through numpy
  (a Python round trip per call). It works from any backend: arrays on a GPU are copied to the
  host and back.

By default (``set_backend("auto")``) the FFI path is used when the FFI targets registered and
JAX's default backend is the CPU, and the callback path otherwise. ``set_backend("ffi")`` or
``set_backend("callback")`` forces one; ``backend()`` tells which one a call would use now.
The choice is made when a function is traced, so ``jax.jit`` functions traced earlier keep
theirs.

The state is flat: ``x = [qpos, qvel]`` (nq + nv, ball/free quaternions as 4 numbers).
**float64 only**: importing this module enables ``jax_enable_x64`` (the engine's tolerances are
1e-10 and below; float32 round trips would spoil them). Arrays of another dtype (float32 from
code written without x64, integers) raise ``TypeError`` unless you pass ``convert=True``, which
upcasts them (and their gradients come back in float64). Python scalars and lists are taken as
float64.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import _flat, _ukemi
from ._gradients import resolve_kappa
from .errors import ShapeError

jax.config.update("jax_enable_x64", True)

__all__ = [
    "backend", "ffi_available", "rollout", "set_backend", "step", "step_jacobians",
    "step_with_status",
]

_TARGETS = ("ukemi_flat_step", "ukemi_flat_step_vjp", "ukemi_flat_rollout",
            "ukemi_flat_rollout_vjp", "ukemi_flat_step_status")


def _register_ffi():
    try:
        capsules, _version = _ukemi._xla_ffi_capsules()
        for name in _TARGETS:
            jax.ffi.register_ffi_target(name, capsules[name], platform="cpu", api_version=1)
        return None
    except Exception as e:  # noqa: BLE001 - any failure means: use the callback path
        return e


_FFI_ERROR = _register_ffi()
_BACKEND = "auto"


def ffi_available() -> bool:
    """Whether the XLA FFI targets registered (if not, ``ffi_error()`` says why)."""
    return _FFI_ERROR is None


def ffi_error():
    """The exception that stopped FFI registration, or None."""
    return _FFI_ERROR


def set_backend(name: str) -> None:
    """Choose ``"ffi"``, ``"callback"`` or ``"auto"`` (FFI when registered and JAX's default
    backend is the CPU, else callback) for calls traced from now on."""
    global _BACKEND
    if name not in ("ffi", "callback", "auto"):
        raise ValueError(f"backend must be 'ffi', 'callback' or 'auto', got {name!r}")
    if name == "ffi" and _FFI_ERROR is not None:
        raise RuntimeError(f"ukemi's XLA FFI targets are not registered: {_FFI_ERROR!r}")
    _BACKEND = name


def backend() -> str:
    """The backend a call traced now would use: ``"ffi"`` or ``"callback"``."""
    if _BACKEND != "auto":
        return _BACKEND
    if _FFI_ERROR is None and jax.default_backend() == "cpu":
        return "ffi"
    return "callback"


# ----------------------------------------------------------------------------------- inputs
def _f64(name, a, convert):
    """float64 array (jax arrays and tracers pass through; numpy stays numpy: the jitted
    kernel takes either, and eager calls skip a dispatch)."""
    dt = getattr(a, "dtype", None)
    if dt is None:
        return np.asarray(a, np.float64)
    if dt != np.float64:
        if not convert:
            raise TypeError(
                f"ukemi.jax: `{name}` has dtype {dt}; ukemi computes in float64. Pass float64 "
                f"arrays (ukemi.jax enables jax_enable_x64), or convert=True to upcast.")
        return jnp.asarray(a).astype(jnp.float64)
    return a


def _bcast(a, shape):
    if a.shape == shape:
        return a
    return jnp.broadcast_to(a, shape)


@functools.lru_cache(maxsize=64)
def _empty(lead):
    return np.zeros(lead + (0,), np.float64)


def _prep(model, x, u, params, kappa_grad, convert, names):
    if not jax.config.jax_enable_x64:
        raise RuntimeError("ukemi.jax needs jax_enable_x64 (it was disabled after import)")
    k = resolve_kappa(model, kappa_grad)
    x = _f64(names[0], x, convert)
    u = _f64(names[1], u, convert) if u is not None else np.zeros(model.nu)
    p = None if params is None else _f64("params", params, convert)
    return k, x, u, p


@functools.lru_cache(maxsize=None)
def _sizes(model):
    return _flat.sizes(model)


def _lead(leads):
    first = leads[0]
    if all(lead == first for lead in leads):
        return tuple(first)
    return tuple(np.broadcast_shapes(*leads))


def _check(name, a, tail):
    shape = a.shape
    if len(shape) < len(tail) or shape[len(shape) - len(tail):] != tuple(tail):
        want = ", ".join(str(t) for t in tail)
        raise ShapeError(f"shape of `{name}`: expected (..., {want}), got {shape}")


def _kappa_attr(k):
    return np.float64(-1.0 if k is None else k)


def _handle(model):
    return np.asarray(_ukemi._xla_model_handle(model), dtype=np.uint64)


def _f64s(*shapes):
    return tuple(jax.ShapeDtypeStruct(s, jnp.float64) for s in shapes)


# ------------------------------------------------------------------------------ custom VJPs
def _differentiable(call_fwd, call_bwd):
    """``jit(f)`` with ``f(x, u, p) = call_fwd(x, u, p)`` and the VJP ``call_bwd(x, u, p, g)``.
    The forward pass of a differentiated call asks the engine to keep its solved steps
    (``keep=True``) for ``call_bwd`` with the same inputs, which then linearises them instead
    of solving them again."""

    @jax.custom_vjp
    def f(x, u, p):
        return call_fwd(x, u, p)

    def f_fwd(x, u, p):
        return call_fwd(x, u, p, keep=True), (x, u, p)

    def f_bwd(res, g):
        return tuple(call_bwd(*res, g))

    f.defvjp(f_fwd, f_bwd)
    return jax.jit(f)


@functools.lru_cache(maxsize=None)
def _step_fn(model, kappa, with_params, how):
    """``f(x, u, p)`` with equal leading axes on x (…, nx), u (…, nu), p (…, np or 0)."""
    if how == "ffi":
        h = _handle(model)

        def call_fwd(x, u, p, keep=False):
            return jax.ffi.ffi_call("ukemi_flat_step", _f64s(x.shape)[0],
                                    vmap_method="broadcast_all")(
                h, x, u, p, with_params=np.int32(with_params), keep=np.int32(keep))

        def call_bwd(x, u, p, g):
            return jax.ffi.ffi_call("ukemi_flat_step_vjp", _f64s(x.shape, u.shape, p.shape),
                                    vmap_method="broadcast_all")(
                h, x, u, p, g, with_params=np.int32(with_params), kappa_grad=_kappa_attr(kappa))
    else:
        def fwd_cb(x, u, p, keep=False):
            return _flat.step(model, x, u, p if with_params else None, keep)

        def bwd_cb(x, u, p, g):
            gx, gu, gp = _flat.step_vjp(model, x, u, p if with_params else None, g, kappa)
            return gx, gu, (gp if with_params else np.zeros(np.shape(p)))

        def call_fwd(x, u, p, keep=False):
            return jax.pure_callback(functools.partial(fwd_cb, keep=keep), _f64s(x.shape)[0],
                                     x, u, p, vmap_method="broadcast_all")

        def call_bwd(x, u, p, g):
            return jax.pure_callback(bwd_cb, _f64s(x.shape, u.shape, p.shape), x, u, p, g,
                                     vmap_method="broadcast_all")

    return _differentiable(call_fwd, call_bwd)


@functools.lru_cache(maxsize=None)
def _rollout_fn(model, kappa, with_params, how):
    """``f(x0, us, p)`` with equal leading axes on x0 (…, nx), us (…, T, nu), p (…, np or 0)."""
    nx = model.nq + model.nv

    def out_shape(x0, us):
        return jax.ShapeDtypeStruct(x0.shape[:-1] + (us.shape[-2] + 1, nx), jnp.float64)

    if how == "ffi":
        h = _handle(model)

        def call_fwd(x0, us, p, keep=False):
            return jax.ffi.ffi_call("ukemi_flat_rollout", out_shape(x0, us),
                                    vmap_method="broadcast_all")(
                h, x0, us, p, with_params=np.int32(with_params), keep=np.int32(keep))

        def call_bwd(x0, us, p, g):
            return jax.ffi.ffi_call("ukemi_flat_rollout_vjp", _f64s(x0.shape, us.shape, p.shape),
                                    vmap_method="broadcast_all")(
                h, x0, us, p, g, with_params=np.int32(with_params), kappa_grad=_kappa_attr(kappa))
    else:
        def fwd_cb(x0, us, p, keep=False):
            return _flat.rollout(model, x0, us, p if with_params else None, keep)

        def bwd_cb(x0, us, p, g):
            gx, gu, gp = _flat.rollout_vjp(model, x0, us, p if with_params else None, g, kappa)
            return gx, gu, (gp if with_params else np.zeros(np.shape(p)))

        def call_fwd(x0, us, p, keep=False):
            return jax.pure_callback(functools.partial(fwd_cb, keep=keep), out_shape(x0, us),
                                     x0, us, p, vmap_method="broadcast_all")

        def call_bwd(x0, us, p, g):
            return jax.pure_callback(bwd_cb, _f64s(x0.shape, us.shape, p.shape), x0, us, p, g,
                                     vmap_method="broadcast_all")

    return _differentiable(call_fwd, call_bwd)


# ---------------------------------------------------------------------------------- public
def step(model, x, u=None, params=None, kappa_grad=3e-4, *, convert=False):
    """One differentiable step of the flat state ``x`` (..., nq + nv) with controls
    ``u`` (..., nu) and optional parameters ``params`` (..., nparams) (``model.params`` layout);
    leading axes broadcast. Gradients are the engine's implicit gradients at ``kappa_grad``
    (None: exact). Non-float64 arrays raise ``TypeError`` unless ``convert=True``.
    A step that fails to converge raises an error naming it ("did not converge"): a
    ``JaxRuntimeError`` on the FFI backend (eagerly and under ``jit``), or through JAX's
    callback machinery on the callback backend."""
    k, x, u, p = _prep(model, x, u, params, kappa_grad, convert, ("x", "u"))
    nx, nu, npar = _sizes(model)
    _check("x", x, (nx,))
    _check("u", u, (nu,))
    leads = [x.shape[:-1], u.shape[:-1]]
    if p is not None:
        _check("params", p, (npar,))
        leads.append(p.shape[:-1])
    lead = _lead(leads)
    x, u = _bcast(x, lead + (nx,)), _bcast(u, lead + (nu,))
    with_params = p is not None
    p = _bcast(p, lead + (npar,)) if with_params else _empty(lead)
    return _step_fn(model, k, with_params, backend())(x, u, p)


def rollout(model, x0, us, params=None, kappa_grad=3e-4, *, convert=False):
    """A differentiable rollout: ``x0`` (..., nq + nv), ``us`` (..., T, nu) → states
    (..., T + 1, nq + nv), computed in Rust in one call; the backward pass is the engine's
    reverse sweep (``ukemi.rollout_vjp``). Same dtype rules and errors as :func:`step`."""
    k, x0, us, p = _prep(model, x0, us, params, kappa_grad, convert, ("x0", "us"))
    nx, nu, npar = _sizes(model)
    _check("x0", x0, (nx,))
    if us.ndim < 2 or us.shape[-1] != nu:
        raise ShapeError(f"shape of `us`: expected (..., T, {nu}), got {us.shape}")
    t = us.shape[-2]
    leads = [x0.shape[:-1], us.shape[:-2]]
    if p is not None:
        _check("params", p, (npar,))
        leads.append(p.shape[:-1])
    lead = _lead(leads)
    x0, us = _bcast(x0, lead + (nx,)), _bcast(us, lead + (t, nu))
    with_params = p is not None
    p = _bcast(p, lead + (npar,)) if with_params else _empty(lead)
    return _rollout_fn(model, k, with_params, backend())(x0, us, p)


def step_jacobians(model, x, u=None, params=None, kappa_grad=3e-4, *, convert=False):
    """Forward-mode companion of :func:`step` for trajectory optimisation: the Jacobians of one
    step in raw flat coordinates, ``(A, B)`` with ``A = ∂x⁺/∂x`` (..., nx, nx) and
    ``B = ∂x⁺/∂u`` (..., nx, nu), plus ``C = ∂x⁺/∂params`` when ``params`` is given — all from
    one linearisation in the engine (no per-column passes). Works eagerly, under ``jit`` and
    ``vmap`` (host callback); not itself differentiable."""
    k, x, u, p = _prep(model, x, u, params, kappa_grad, convert, ("x", "u"))
    nx, nu, npar = _sizes(model)
    _check("x", x, (nx,))
    _check("u", u, (nu,))
    leads = [x.shape[:-1], u.shape[:-1]] + ([p.shape[:-1]] if p is not None else [])
    lead = _lead(leads)
    with_params = p is not None
    pp = p if with_params else np.zeros((0,))
    out = _f64s(lead + (nx, nx), lead + (nx, nu), lead + (nx, npar if with_params else 0))

    def cb(x, u, pp):
        return _flat.step_jacobians(model, x, u, pp if with_params else None, k, with_params)

    a, b, c = jax.pure_callback(cb, out, x, u, pp, vmap_method="broadcast_all")
    return (a, b, c) if with_params else (a, b)


def _status_np(model, x, u, p):
    """Callback-backend fallback of the status step: a Python loop over the batch."""
    from . import _simulate

    nx, nu, _ = _sizes(model)
    lead = x.shape[:-1]
    xs, us = np.reshape(x, (-1, nx)), np.reshape(u, (-1, nu))
    ps = None if p is None or p.shape[-1] == 0 else np.reshape(p, (xs.shape[0], -1))
    out, st = np.zeros_like(xs), np.zeros(xs.shape[0], np.int32)
    names = list(_ukemi.STATUS_NAMES)
    for i in range(xs.shape[0]):
        m = model if ps is None else model.with_params(ps[i])
        s = m.make_state(qpos=xs[i, :m.nq], qvel=xs[i, m.nq:])
        n, info = _simulate.step(m, s, us[i], on_failure="return")
        out[i] = np.concatenate([n.qpos, n.qvel])
        st[i] = names.index(info.status)
    return out.reshape(lead + (nx,)), st.reshape(lead)


@functools.lru_cache(maxsize=None)
def _status_fn(model, kappa, with_params, how):
    if how == "ffi":
        h = _handle(model)

        def call_fwd(x, u, p):
            out = (jax.ShapeDtypeStruct(x.shape, jnp.float64),
                   jax.ShapeDtypeStruct(x.shape[:-1], jnp.int32))
            return jax.ffi.ffi_call("ukemi_flat_step_status", out, vmap_method="broadcast_all")(
                h, x, u, p, with_params=np.int32(with_params))
    else:
        def call_fwd(x, u, p):
            out = (jax.ShapeDtypeStruct(x.shape, jnp.float64),
                   jax.ShapeDtypeStruct(x.shape[:-1], jnp.int32))
            return jax.pure_callback(
                lambda x, u, p: _status_np(model, x, u, p if with_params else None), out,
                x, u, p, vmap_method="broadcast_all")
    bwd = _step_fn(model, kappa, with_params, how)

    @jax.custom_vjp
    def f(x, u, p):
        return call_fwd(x, u, p)

    def f_fwd(x, u, p):
        return call_fwd(x, u, p), (x, u, p)

    def f_bwd(res, g):
        # the status output is an integer: its cotangent is ignored
        _, vjp = jax.vjp(bwd, *res)
        return vjp(g[0])

    f.defvjp(f_fwd, f_bwd)
    return jax.jit(f)


def step_with_status(model, x, u=None, params=None, kappa_grad=3e-4, *, convert=False):
    """:func:`step` that reports instead of failing: returns ``(x_next, status)`` with
    ``status`` (...,) int32 in ``ukemi.STATUS_NAMES`` order (0 = converged, 1 = acceptable:
    both valid states; 2-4 = failures; 5 = pyramid_friction: a valid state taken with
    pyramid friction cones after the exact cones failed, with no gradient). A step that failed
    returns its last iterate with its status, so a jitted program can mask or reset it
    (``status > 1`` masks every step without a valid gradient). ``x_next`` is differentiable like :func:`step` (the backward pass of a failed
    step raises, as there is no valid gradient there)."""
    k, x, u, p = _prep(model, x, u, params, kappa_grad, convert, ("x", "u"))
    nx, nu, npar = _sizes(model)
    _check("x", x, (nx,))
    _check("u", u, (nu,))
    leads = [x.shape[:-1], u.shape[:-1]] + ([p.shape[:-1]] if p is not None else [])
    lead = _lead(leads)
    x, u = _bcast(x, lead + (nx,)), _bcast(u, lead + (nu,))
    with_params = p is not None
    p = _bcast(p, lead + (npar,)) if with_params else _empty(lead)
    return _status_fn(model, k, with_params, backend())(x, u, p)
