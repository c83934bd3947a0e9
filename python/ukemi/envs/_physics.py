"""The one physics call of the environments: ``frame_skip`` steps of a batch of flat states
``x = [qpos, qvel]`` in one Rust call (parallel over the batch, GIL released).

Single envs and the vector env both go through :func:`simulate`, so a vector env of N copies
produces bit-for-bit the numbers of N single envs. The solver warm start is carried across the
``frame_skip`` substeps of one env step and restarted at each env step (a flat state holds no
warm start), which costs iterations, never accuracy.
"""

from __future__ import annotations

import re

import numpy as np

from .. import _ukemi
from ..errors import ConvergenceError

_STATUS = re.compile(r"did not converge: (\w+)")


def _status_of(error: ConvergenceError) -> str:
    m = _STATUS.search(str(error))
    return m.group(1) if m else "not_converged"


def simulate(model, xs: np.ndarray, ctrls: np.ndarray, frame_skip: int) -> tuple[np.ndarray, list[str]]:
    """Advance every row of ``xs`` by ``frame_skip`` steps under constant controls.

    Args:
        model: ``ukemi.Model``.
        xs: Flat states, shape (B, nq + nv).
        ctrls: Controls, shape (B, nu), held for the ``frame_skip`` steps.
        frame_skip: Engine steps per env step.

    Returns:
        (xs_next (B, nq + nv), status per row). A row whose solve failed at any substep (or
        produced a non-finite state) keeps its input state and gets the solver's status name
        (``"max_iterations"``, ``"line_search_failed"``, ``"non_finite"``); other rows get
        ``"converged"``.
    """
    xs = np.ascontiguousarray(xs, dtype=np.float64)
    us = np.ascontiguousarray(np.repeat(np.asarray(ctrls, np.float64)[:, None, :], frame_skip, axis=1))
    try:
        out = _ukemi._flat_rollout(model, xs, us, None)[:, -1]
    except ConvergenceError as e:
        if len(xs) == 1:
            return xs.copy(), [_status_of(e)]
        # One failed row fails the batch call: redo the rows one by one to find which.
        rows = [simulate(model, xs[i : i + 1], ctrls[i : i + 1], frame_skip) for i in range(len(xs))]
        return np.concatenate([r[0] for r in rows]), [r[1][0] for r in rows]
    status = ["converged"] * len(xs)
    finite = np.isfinite(out).all(axis=1)
    if not finite.all():
        out = np.where(finite[:, None], out, xs)
        status = ["converged" if f else "non_finite" for f in finite]
    return np.ascontiguousarray(out), status
