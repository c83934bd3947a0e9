"""``ukemi.ModelBuilder``: build a model from Python. Validation happens in the engine."""

from __future__ import annotations

import numpy as np

from . import _ukemi
from ._convert import as_float_array, as_scalar, as_vector
from .errors import ShapeError, UnsupportedError

JOINT_KINDS: tuple[str, ...] = tuple(_ukemi.JOINT_KINDS)


def _inertia(name: str, value) -> list[float]:
    arr = as_float_array(name, value)
    if arr.shape == (3,):
        return np.diag(arr).ravel().tolist()
    if arr.shape == (3, 3):
        return arr.ravel().tolist()
    raise ShapeError(f"shape of `{name}`: expected (3,) principal moments or (3, 3), got {arr.shape}")


def _per_dof(name: str, value) -> list[float]:
    arr = as_float_array(name, value)
    if arr.ndim > 1:
        raise ShapeError(f"shape of `{name}`: expected a scalar or one value per free dof, got {arr.shape}")
    return arr.ravel().tolist()


class ModelBuilder:
    """Collects bodies, joints and actuators, then compiles an immutable :class:`ukemi.Model`.

    Args:
        timestep: Time step (s).
        gravity: Gravity, world frame (m/s²), shape (3,).

    Example:
        >>> b = ModelBuilder(timestep=0.01)
        >>> b.add_body("link", mass=1.0, inertia=(0.1, 0.1, 0.01), pos=(0, 0, 1))
        >>> b.add_joint("hinge", kind="revolute", parent="world", child="link", axis=(0, 1, 0),
        ...             parent_anchor=(0, 0, 1.5), child_anchor=(0, 0, 0.5))
        >>> model = b.compile()
    """

    def __init__(self, timestep: float = 0.01, gravity=(0.0, 0.0, -9.81)):
        self._b = _ukemi._ModelBuilder(as_scalar("timestep", timestep), as_vector("gravity", gravity, 3))

    def add_body(self, name: str, mass: float, inertia, pos=(0.0, 0.0, 0.0), quat=(1.0, 0.0, 0.0, 0.0),
                 com=(0.0, 0.0, 0.0)) -> None:
        """Add a rigid body.

        Args:
            name: Unique name.
            mass: Mass (kg), > 0.
            inertia: Principal moments (3,) or full inertia (3, 3) about the COM, body frame (kg·m²).
            pos: Body frame origin at the reference configuration, world (m).
            quat: Body orientation (w, x, y, z) at the reference configuration, unit norm.
            com: Centre of mass in the body frame (m).

        Raises:
            TypeError, ShapeError, InputError: malformed arguments (validated again at compile).
        """
        self._b.add_body(str(name), as_scalar("mass", mass), _inertia("inertia", inertia),
                         as_vector("pos", pos, 3), as_vector("quat", quat, 4), as_vector("com", com, 3))

    def add_joint(self, name: str, kind: str, parent: str, child: str, axis=(0.0, 0.0, 1.0),
                  parent_anchor=(0.0, 0.0, 0.0), child_anchor=(0.0, 0.0, 0.0), stiffness=0.0,
                  damping=0.0, spring_ref=None, range=None, loop: bool = False) -> None:
        """Add a joint between ``parent`` (or ``"world"``) and ``child``.

        Args:
            name: Unique name.
            kind: One of ``ukemi.JOINT_KINDS`` (``"revolute"``, ``"prismatic"``, ``"spherical"``,
                ``"floating"``, ... ; aliases ``hinge``, ``slide``, ``ball``, ``free``, ``weld``,
                ``universal``).
            parent, child: Body names.
            axis: Joint axis in the child body frame (3,).
            parent_anchor: Anchor in the parent body frame (m).
            child_anchor: Anchor in the child body frame (m).
            stiffness: Spring stiffness, scalar or one per free dof (N/m, N·m/rad).
            damping: Damping, scalar or one per free dof (N·s/m, N·m·s/rad).
            spring_ref: Spring rest position in the joint's qpos units (default: reference pose).
            range: Joint limits per free dof (arrives with the contact solver; raises for now).
            loop: The joint closes a kinematic loop (not part of the spanning tree, no qpos).
        """
        if not isinstance(kind, str):
            raise TypeError(f"`kind` must be a string, got {type(kind).__name__}")
        ref = None if spring_ref is None else as_float_array("spring_ref", spring_ref, (-1,)).tolist()
        rng = None
        if range is not None:
            rng = [tuple(r) for r in as_float_array("range", np.atleast_2d(range), (-1, 2)).tolist()]
        self._b.add_joint(str(name), kind, str(parent), str(child), as_vector("axis", axis, 3),
                          as_vector("parent_anchor", parent_anchor, 3),
                          as_vector("child_anchor", child_anchor, 3),
                          _per_dof("stiffness", stiffness), _per_dof("damping", damping), ref, rng,
                          bool(loop))

    def add_actuator(self, name: str, joint: str, gear: float = 1.0, ctrlrange=None,
                     dof: int = 0) -> None:
        """Add a motor: generalized force ``gear * clamp(ctrl, ctrlrange)`` on free dof ``dof``.

        Args:
            name: Unique name.
            joint: Joint name.
            gear: Gear ratio.
            ctrlrange: ``(lower, upper)`` clamp of the control, or None.
            dof: Which free dof of the joint (0-based, in its qvel order).
        """
        rng = None if ctrlrange is None else tuple(as_vector("ctrlrange", ctrlrange, 2))
        if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or dof < 0:
            raise TypeError(f"`dof` must be a non-negative integer, got {dof!r}")
        self._b.add_actuator(str(name), str(joint), int(dof), as_scalar("gear", gear), rng)

    def add_geom(self, name: str, body: str, shape: str, size, **kwargs) -> None:
        """Collision geometry. Contact arrives with the interior-point contact solver (issue #3)."""
        raise UnsupportedError(
            f"unsupported: geom[{name}]: collision geometry and contact are not available yet"
        )

    def compile(self):
        """Validate and compile.

        Returns:
            ukemi.Model

        Raises:
            ModelError: a field is invalid; the message names it and its value.
            UnsupportedError: a feature that is not available.
        """
        return self._b.compile()
