"""The one physics call of the environments: ``frame_skip`` steps of a batch of flat states
``x = [qpos, qvel]`` in one Rust call (parallel over the batch, GIL released).

Single envs and the vector env both go through :func:`simulate`, so a vector env of N copies
produces bit-for-bit the numbers of N single envs. The solver warm start is carried across the
``frame_skip`` substeps of one env step and restarted at each env step (a flat state holds no
warm start), which costs iterations, never accuracy.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import _ukemi

#: solver status names by code (``ukemi.STATUS_NAMES``)
STATUS = tuple(_ukemi.STATUS_NAMES)


class Physics(NamedTuple):
    """Result of :func:`simulate` for a batch of B states."""

    x: np.ndarray  #: flat states after the env step (B, nq + nv); the input row where a solve failed
    status: list[str]  #: solver status per row ("converged", "max_iterations", ...)
    contact_force: np.ndarray  #: (B, ncontact, 3) last substep's force per contact candidate (N)
    body_wrench: np.ndarray  #: (B, nbody, 6) contact wrench per body: torque about the origin, force


def simulate(model, xs: np.ndarray, ctrls: np.ndarray, frame_skip: int) -> Physics:
    """Advance every row of ``xs`` by ``frame_skip`` steps under constant controls.

    Args:
        model: ``ukemi.Model``.
        xs: Flat states, shape (B, nq + nv).
        ctrls: Controls, shape (B, nu), held for the ``frame_skip`` steps.
        frame_skip: Engine steps per env step.

    Returns:
        :class:`Physics`. A row whose solve failed at any substep (or produced a non-finite
        state) keeps its input state, zero forces and the solver's status name
        (``"max_iterations"``, ``"line_search_failed"``, ``"non_finite"``).

    Contact forces are the last substep's impulses divided by the time step, in each
    candidate's contact frame (normal, tangent 1, tangent 2) at the substep's initial
    configuration; the body wrenches are the same forces summed per body in the world frame.
    """
    xs = np.ascontiguousarray(xs, dtype=np.float64)
    us = np.ascontiguousarray(ctrls, dtype=np.float64)
    x, codes, force, wrench = _ukemi._env_step(model, xs, us, int(frame_skip))
    return Physics(x, [STATUS[c] for c in codes], force, wrench)
