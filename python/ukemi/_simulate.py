"""Functional stepping API: ``step`` and ``rollout`` (MuJoCo/MJX style ``f(model, state, ...)``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _ukemi
from ._convert import as_float_array
from .errors import ConvergenceError

STATUS_NAMES: tuple[str, ...] = tuple(_ukemi.STATUS_NAMES)
#: statuses whose state is valid: "converged", "acceptable" (the solve stalled on round-off
#: within the options' acceptable_rtol / acceptable_kappa_tol), and "pyramid_friction" (every
#: attempt with the exact friction cones failed and the step converged with each cone replaced
#: by its inscribed four-sided pyramid: no penetration, forces inside the Coulomb cones; not
#: differentiable, see the ``pyramid_fallback`` option)
SUCCESS_STATUSES: tuple[str, ...] = ("converged", "acceptable", "pyramid_friction")
SUCCESS = SUCCESS_STATUSES
_ON_FAILURE = ("raise", "return")


def _check_on_failure(on_failure: str) -> None:
    if on_failure not in _ON_FAILURE:
        raise ValueError(f"`on_failure` must be one of {_ON_FAILURE}, got {on_failure!r}")


def _check_types(model, state) -> None:
    if not isinstance(model, _ukemi.Model):
        raise TypeError(f"`model` must be a ukemi.Model, got {type(model).__name__}")
    if not isinstance(state, _ukemi.State):
        raise TypeError(f"`state` must be a ukemi.State, got {type(state).__name__}")


def step(model, state, ctrl=None, *, qfrc_applied=None, xfrc_applied=None, on_failure="raise"):
    """Advance one time step. The input ``state`` is left unchanged.

    Args:
        model: ``ukemi.Model``.
        state: ``ukemi.State`` made by ``model.make_state()``.
        ctrl: Controls, shape (nu,); None means zeros.
        qfrc_applied: Generalized forces on the dofs, shape (nv,) (N or N·m).
        xfrc_applied: World wrenches ``[force, torque]`` at each body's COM, shape (nbody, 6).
        on_failure: ``"raise"`` (default) raises ``ConvergenceError`` if the solve did not
            converge; ``"return"`` returns the last iterate with the status in ``info``.

    Returns:
        (next_state, info): ``info.status``, ``info.iterations``, ``info.residual``,
        ``info.complementarity``, ``info.subdivisions`` (1, or the n equal sub-steps of
        timestep / n a step took after its whole-step solve failed).

    Raises:
        TypeError, ShapeError, InputError, ModelMismatchError: bad arguments.
        ConvergenceError: the solve failed and ``on_failure="raise"``.
    """
    _check_types(model, state)
    _check_on_failure(on_failure)
    ctrl = np.zeros(model.nu) if ctrl is None else as_float_array("ctrl", ctrl, (model.nu,))
    qfrc = None if qfrc_applied is None else as_float_array("qfrc_applied", qfrc_applied, (model.nv,))
    xfrc = None if xfrc_applied is None else as_float_array("xfrc_applied", xfrc_applied, (model.nbody, 6))
    next_state, info = _ukemi._step(model, state, ctrl, qfrc, xfrc)
    if on_failure == "raise" and info.status not in SUCCESS:
        raise ConvergenceError(
            f"step at t = {state.time:.6g} did not converge: {info.status} after "
            f"{info.iterations} iterations, residual {info.residual:.3e}",
            info=info, state=next_state)
    return next_state, info


def step_smoothed(model, state, ctrl=None, *, kappa):
    """The smoothed step: the next state on the central path at ``kappa`` (each contact pair
    within reach at ``b ∘ c = kappa w e``, ``w`` tapering from 1 at touching to ~0 before the
    reach, so the map is continuous where a candidate comes within reach; each joint and
    tendon limit pair the hard step activated likewise, tapered with its slack; the others
    without impulse), the map whose derivatives ``kappa_grad=kappa`` gives.

    Args:
        model, state, ctrl: as for :func:`step`.
        kappa: central-path parameter, > 0.

    Returns:
        (next_state, info): ``info`` reports the central-path solve.

    Raises:
        ValueError: ``kappa`` not finite and > 0.
        ConvergenceError: the hard step or the central-path solve failed.
    """
    _check_types(model, state)
    kappa = float(kappa)
    if not (np.isfinite(kappa) and kappa > 0):
        raise ValueError(f"kappa must be finite and > 0, got {kappa}")
    ctrl = np.zeros(model.nu) if ctrl is None else as_float_array("ctrl", ctrl, (model.nu,))
    return _ukemi._step_smoothed(model, state, ctrl, kappa)


def solver_trace(model, state, ctrl=None, *, condition=False):
    """Take one step and record every interior-point iteration (convergence studies, debugging).

    Args:
        model, state, ctrl: as for :func:`step`.
        condition: also compute the 2-norm condition number of the Newton matrix at each
            iteration, on the rows the solve factors (contact candidates left out of the
            step are not among them), by a dense SVD of those rows.

    Returns:
        (next_state, info, trace): ``trace`` is a dict of per-iteration arrays: ``attempt``
        (0 = first solve, then each retry counting up: the first attempt widened gently, cold
        retries, wider activations, re-solves after a missed contact), ``residual``
        and ``complementarity`` (the violations before the iteration), ``mu`` (mean
        complementarity), ``kappa`` (centring target), ``alpha_aff``, ``alpha`` (accepted step,
        0 = line search failed), ``corrector`` (Mehrotra's direction accepted), ``condition``
        (NaN unless requested). Never raises on non-convergence: read ``info.status``.
    """
    _check_types(model, state)
    ctrl = np.zeros(model.nu) if ctrl is None else as_float_array("ctrl", ctrl, (model.nu,))
    return _ukemi._solver_trace(model, state, ctrl, bool(condition))


@dataclass(frozen=True)
class Trajectory:
    """Result of :func:`rollout`. Arrays have a leading time axis of length T + 1 (states) or T
    (per-step reports); a rollout stopped by a failure is shorter."""

    qpos: np.ndarray  #: (T+1, nq)
    qvel: np.ndarray  #: (T+1, nv)
    time: np.ndarray  #: (T+1,)
    body_pos: np.ndarray  #: (T+1, nbody, 3) body frame origins, world
    body_quat: np.ndarray  #: (T+1, nbody, 4) (w, x, y, z)
    min_distance: np.ndarray  #: (T+1,) least signed distance over contact candidates (inf if none)
    status: np.ndarray  #: (T,) status names
    iterations: np.ndarray  #: (T,)
    residual: np.ndarray  #: (T,)
    final_state: object  #: ukemi.State after the last step
    #: (T,) equal sub-steps each step took (1; n > 1 when the whole step's solve failed and n
    #: sub-steps of timestep / n succeeded, see ``Model.with_options(max_subdivisions=...)``)
    subdivisions: np.ndarray | None = None
    #: (T+1,) discrete total energy of each simulated state (J, as ``State.energy()``). Use this,
    #: not ``model.make_state(qpos=..., qvel=...).energy()``: a state rebuilt from minimal
    #: coordinates loses the O(h) part of the midpoint velocities that the joints' motion
    #: subspaces do not span (measured: 8% of a fast 3-link chain's energy, scene 39 of
    #: ``tests/stress``), so it is not the state the simulation holds.
    energy: np.ndarray | None = None

    @property
    def converged(self) -> bool:
        """Whether every step's state is valid (status in ``SUCCESS_STATUSES``)."""
        return bool(np.all(np.isin(self.status, SUCCESS)))


def signed_distances(model, state) -> np.ndarray:
    """Signed distance of every contact candidate (m, negative = penetration), (ncontact,).

    Candidates are listed by ``model.contact_pairs``.
    """
    _check_types(model, state)
    return _ukemi.signed_distances(model, state)


def rollout(model, state, ctrls=None, *, nsteps=None, on_failure="raise") -> Trajectory:
    """Simulate ``T`` steps in Rust with the GIL released.

    Args:
        model: ``ukemi.Model``.
        state: Initial ``ukemi.State`` (unchanged).
        ctrls: Controls, shape (T, nu). Omit it and pass ``nsteps=T`` for zero controls.
        nsteps: Number of steps when ``ctrls`` is None.
        on_failure: ``"raise"`` stops at the first failed step and raises ``ConvergenceError``
            (with ``step_index``); ``"return"`` keeps going and reports statuses.

    Returns:
        Trajectory

    Raises:
        TypeError, ShapeError, InputError: bad arguments. ConvergenceError: see ``on_failure``.
    """
    _check_types(model, state)
    _check_on_failure(on_failure)
    if ctrls is None:
        if nsteps is None:
            raise TypeError("rollout needs `ctrls` of shape (T, nu) or `nsteps`")
        if isinstance(nsteps, bool) or not isinstance(nsteps, (int, np.integer)) or nsteps < 0:
            raise TypeError(f"`nsteps` must be a non-negative integer, got {nsteps!r}")
        ctrls = np.zeros((int(nsteps), model.nu))
    else:
        ctrls = as_float_array("ctrls", ctrls, (-1, model.nu))
        if nsteps is not None and nsteps != ctrls.shape[0]:
            raise ValueError(f"`nsteps` = {nsteps} disagrees with ctrls.shape[0] = {ctrls.shape[0]}")
    arrays, final = _ukemi._rollout(model, state, ctrls, on_failure == "raise")
    status = np.asarray(STATUS_NAMES, dtype=object)[arrays["status"]].astype(str)
    traj = Trajectory(arrays["qpos"], arrays["qvel"], arrays["time"], arrays["body_pos"],
                      arrays["body_quat"], arrays["min_distance"], status, arrays["iterations"], arrays["residual"], final,
                      arrays["subdivisions"], arrays["energy"])
    if on_failure == "raise" and not traj.converged:
        k = int(np.argmax(~np.isin(status, SUCCESS)))
        raise ConvergenceError(
            f"rollout step {k} (t = {traj.time[k]:.6g}) did not converge: {status[k]}, "
            f"residual {traj.residual[k]:.3e}", state=final, step_index=k)
    return traj
