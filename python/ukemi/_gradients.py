"""Implicit gradients of a step and of rollouts (Dojo §III-B, eq. 11).

The derivatives come from the implicit function theorem on the solver's own factored Newton
matrix. ``kappa_grad`` picks where they are taken: ``None`` is the exact derivative at the
simulated (hard-contact) solution; a positive value is the derivative of the *smoothed* step,
whose solution is the central-path point at that κ reached from the hard solution by Newton's
method (contact forces act across gaps of order κ/γ, stick/slip transitions are blended).
The next state returned alongside is always the hard one.

State tangents follow ``coordinates``: ``"minimal"`` is MuJoCo's ``mjd_transitionFD``
convention ``(dq, dv)`` of size 2·nv (ball quaternions perturbed in the child frame);
``"maximal"`` is ``(δp, δφ, δv, δω)`` per moving body (12 each).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import _ukemi
from ._convert import as_float_array
from .errors import InputError

#: default for ``kappa_grad``: the model's option (``model.with_options(kappa_grad=...)``)
MODEL_DEFAULT = object()
_COORDS = ("minimal", "maximal")
_WRT = ("state", "ctrl", "params")


def _check(model, state) -> None:
    if not isinstance(model, _ukemi.Model):
        raise TypeError(f"`model` must be a ukemi.Model, got {type(model).__name__}")
    if not isinstance(state, _ukemi.State):
        raise TypeError(f"`state` must be a ukemi.State, got {type(state).__name__}")


def resolve_kappa(model, kappa_grad):
    """``kappa_grad`` argument → float or None (validated)."""
    if kappa_grad is MODEL_DEFAULT:
        return model.kappa_grad
    if kappa_grad is None:
        return None
    try:
        k = float(kappa_grad)
    except (TypeError, ValueError):
        raise TypeError(f"`kappa_grad` must be a positive float or None, got {kappa_grad!r}") from None
    if not (math.isfinite(k) and k > 0.0):
        raise InputError(f"invalid input: `kappa_grad` = {kappa_grad!r}: must be finite and > 0 (or None)")
    return k


def _coords(coordinates: str) -> str:
    if coordinates not in _COORDS:
        raise ValueError(f"`coordinates` must be one of {_COORDS}, got {coordinates!r}")
    return coordinates


def tangent_dim(model, coordinates: str = "minimal") -> int:
    """Size of the state tangent: 2·nv (minimal) or 12·(nbody − 1) (maximal)."""
    return 2 * model.nv if _coords(coordinates) == "minimal" else 12 * (model.nbody - 1)


def _ctrl(model, ctrl):
    return np.zeros(model.nu) if ctrl is None else as_float_array("ctrl", ctrl, (model.nu,))


@dataclass(frozen=True)
class StepJacobians:
    """Result of :func:`step_jacobians`."""

    A: np.ndarray  #: (ny, ny) d(next state)/d(state); ny = 2·nv (minimal) or 12·(nbody−1)
    B: np.ndarray  #: (ny, nu) d(next state)/d(ctrl)
    C: np.ndarray  #: (ny, nparams) d(next state)/d(model.params)
    next_state: object  #: the (hard) next state; in minimal coordinates, of the state rebuilt from (qpos, qvel)
    info: object  #: StepInfo of the step
    central_info: object  #: StepInfo of the move to the central path (None if not smoothed)
    coordinates: str
    kappa_grad: float | None


def step_jacobians(model, state, ctrl=None, *, kappa_grad=MODEL_DEFAULT, coordinates="minimal",
                   wrt=_WRT) -> StepJacobians:
    """Jacobians of one step with respect to the state, the controls and ``model.params``.

    Args:
        model, state: as for :func:`ukemi.step`.
        ctrl: Controls (nu,); None means zeros.
        kappa_grad: Central-path parameter of the gradient (None: exact; default: the model's
            ``kappa_grad`` option, itself None unless set).
        coordinates: ``"minimal"`` (default, MuJoCo's convention) or ``"maximal"``.
        wrt: Subset of ``("state", "ctrl", "params")``; unselected blocks have no columns.

    Raises:
        ConvergenceError: the step (or the move to the central path) did not converge; no
            gradient exists there.
    """
    _check(model, state)
    bad = [w for w in wrt if w not in _WRT]
    if bad:
        raise ValueError(f"`wrt` entries must be among {_WRT}, got {bad!r}")
    k = resolve_kappa(model, kappa_grad)
    c = _coords(coordinates)
    a, b, cm, nxt, info, cinfo = _ukemi._step_jacobians(
        model, state, _ctrl(model, ctrl), k, c, "state" in wrt, "ctrl" in wrt, "params" in wrt)
    return StepJacobians(a, b, cm, nxt, info, cinfo, c, k)


@dataclass(frozen=True)
class RolloutJacobians:
    """Result of :func:`rollout_jacobians`."""

    A: np.ndarray  #: (T, ny, ny) d(x_{k+1})/d(x_k)
    B: np.ndarray  #: (T, ny, nu) d(x_{k+1})/d(u_k)
    C: np.ndarray  #: (T, ny, nparams) d(x_{k+1})/d(model.params)
    states: list  #: x_0..x_T (T + 1 ukemi.State)
    coordinates: str
    kappa_grad: float | None


def rollout_jacobians(model, state, ctrls, *, kappa_grad=MODEL_DEFAULT, coordinates="minimal",
                      wrt=_WRT) -> RolloutJacobians:
    """Roll out ``ctrls`` (T, nu) from ``state`` and return the Jacobians of every step: what
    iLQR/DDP and the Dojo paper's Table V workload need, in one call into Rust.

    Step k's Jacobians are :func:`step_jacobians` of ``states[k]`` with ``ctrls[k]`` (in
    minimal coordinates each state is rebuilt from ``(qpos, qvel)`` first, as there). With more
    than one thread (``ukemi.set_num_threads``; rayon's default is one per core) the steps are
    linearised on the other threads while the forward pass goes on, with the same results bit
    for bit.

    Raises:
        ConvergenceError: a step (or its move to the central path) did not converge; the
            message names the step.
    """
    _check(model, state)
    bad = [w for w in wrt if w not in _WRT]
    if bad:
        raise ValueError(f"`wrt` entries must be among {_WRT}, got {bad!r}")
    k = resolve_kappa(model, kappa_grad)
    c = _coords(coordinates)
    ctrls = as_float_array("ctrls", ctrls, (-1, model.nu))
    a, b, cm, states = _ukemi._rollout_jacobians(
        model, state, ctrls, k, c, "state" in wrt, "ctrl" in wrt, "params" in wrt)
    return RolloutJacobians(a, b, cm, states, c, k)


def step_vjp(model, state, ctrl, adjoint_next, *, kappa_grad=MODEL_DEFAULT, coordinates="minimal",
             params=True):
    """Adjoints ``(adj_state, adj_ctrl, adj_params)`` of one step given ``adjoint_next``
    (the gradient of a loss with respect to the next state, in tangent coordinates). One
    transposed back-substitution with the solver's factorisation; ``params=False`` skips the
    parameter adjoint (returned empty)."""
    _check(model, state)
    c = _coords(coordinates)
    adj = as_float_array("adjoint_next", adjoint_next, (tangent_dim(model, c),))
    return _ukemi._step_vjp(model, state, _ctrl(model, ctrl), adj, resolve_kappa(model, kappa_grad),
                            c, bool(params))


def step_jvp(model, state, ctrl, dstate, dctrl=None, dparams=None, *, kappa_grad=MODEL_DEFAULT,
             coordinates="minimal"):
    """Tangent of the next state for input tangents ``dstate`` (ny,), ``dctrl`` (nu,) and
    ``dparams`` (nparams,) (None: zero)."""
    _check(model, state)
    c = _coords(coordinates)
    dx = as_float_array("dstate", dstate, (tangent_dim(model, c),))
    du = np.zeros(model.nu) if dctrl is None else as_float_array("dctrl", dctrl, (model.nu,))
    dp = None if dparams is None else as_float_array("dparams", dparams, (len(model.params),))
    return _ukemi._step_jvp(model, state, _ctrl(model, ctrl), dx, du, dp,
                            resolve_kappa(model, kappa_grad), c)


def rollout_vjp(model, state, ctrls, adjoint_states, *, kappa_grad=MODEL_DEFAULT,
                coordinates="minimal", params=True):
    """Gradient of a loss on a whole rollout by one reverse sweep in Rust.

    With more than one thread (``ukemi.set_num_threads``; rayon's default is one per core)
    each step is linearised on the other threads while the forward pass goes on, so the call
    takes about as long as the forward rollout; on one thread each step is linearised when
    the sweep reaches it.

    Args:
        ctrls: (T, nu) controls.
        adjoint_states: (T + 1, ny) gradients of the loss with respect to each state x_0..x_T
            (tangent coordinates).

    Returns:
        (adj_state0 (ny,), adj_ctrls (T, nu), adj_params (nparams,)).
    """
    _check(model, state)
    c = _coords(coordinates)
    ctrls = as_float_array("ctrls", ctrls, (-1, model.nu))
    t = ctrls.shape[0]
    adj = as_float_array("adjoint_states", adjoint_states, (t + 1, tangent_dim(model, c)))
    return _ukemi._rollout_vjp(model, state, ctrls, adj, resolve_kappa(model, kappa_grad), c,
                               bool(params))
