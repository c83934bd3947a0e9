"""The one physics call of the environments: ``frame_skip`` steps of some rows of a batch of
full engine states (``ukemi._ukemi.EnvStates``) in one Rust call (parallel, GIL released).

The full state persists between env steps: the variational integrator's midpoint velocities
and the solver's warm start, so an env's trajectory is exactly ``ukemi.rollout``'s under the
frame_skip-expanded controls. Single envs (one row) and the vector env (one row per sub-env)
both go through :func:`step_rows`, so a vector env of N copies produces bit-for-bit the numbers
of N single envs.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import _ukemi

#: solver status names by code (``ukemi.STATUS_NAMES``)
STATUS = tuple(_ukemi.STATUS_NAMES)


class Physics(NamedTuple):
    """Result of :func:`step_rows` for R stepped rows."""

    x: np.ndarray  #: ``[qpos, qvel]`` after the env step (R, nq + nv); the input where a solve failed
    status: list[str]  #: solver status per row ("converged", "acceptable", "max_iterations", ...)
    contact_force: np.ndarray  #: (R, ncontact, 3) last substep's force per contact candidate (N)
    body_wrench: np.ndarray  #: (R, nbody, 6) contact wrench per body: torque about the origin, force


def step_rows(states, rows, ctrls: np.ndarray, frame_skip: int) -> Physics:
    """Advance the rows ``rows`` of ``states`` in place by ``frame_skip`` steps under constant
    controls.

    Args:
        states: ``ukemi._ukemi.EnvStates``.
        rows: Row indices (R,), distinct.
        ctrls: Controls, shape (R, nu), held for the ``frame_skip`` steps.
        frame_skip: Engine steps per env step.

    Returns:
        :class:`Physics`. A row whose solve failed at any substep (or produced a non-finite
        state) is left at its input state, with zero forces and the solver's status name
        (``"max_iterations"``, ``"line_search_failed"``, ``"non_finite"``).

    Contact forces are the last substep's impulses divided by the time step, in each
    candidate's contact frame (normal, tangent 1, tangent 2) at the substep's initial
    configuration; the body wrenches are the same forces summed per body in the world frame.
    """
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    us = np.ascontiguousarray(ctrls, dtype=np.float64)
    x, codes, force, wrench = states.step(rows, us, int(frame_skip))
    return Physics(x, [STATUS[c] for c in codes], force, wrench)
