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


def _quat_z_to(n: np.ndarray) -> list[float]:
    """Unit quaternion (w, x, y, z) rotating +z onto the direction ``n``."""
    norm = float(np.linalg.norm(n))
    if norm == 0.0:
        raise ValueError("`normal` must be non-zero")
    n = n / norm
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.dot(z, n))
    if c < -1.0 + 1e-12:
        return [0.0, 1.0, 0.0, 0.0]
    axis = np.cross(z, n)
    q = np.array([1.0 + c, *axis])
    return (q / np.linalg.norm(q)).tolist()


def _bits(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= value < 2**32:
        raise TypeError(f"`{name}` must be an integer bitmask in [0, 2**32), got {value!r}")
    return int(value)


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
                 com=(0.0, 0.0, 0.0), gravcomp: float = 0.0) -> None:
        """Add a rigid body.

        Args:
            name: Unique name.
            mass: Mass (kg), > 0.
            inertia: Principal moments (3,) or full inertia (3, 3) about the COM, body frame (kg·m²).
            pos: Body frame origin at the reference configuration, world (m).
            quat: Body orientation (w, x, y, z) at the reference configuration, unit norm.
            com: Centre of mass in the body frame (m).
            gravcomp: Gravity compensation (MuJoCo's ``gravcomp``): the share of the body's
                weight cancelled by an upward force at its COM (1 floats it).

        Raises:
            TypeError, ShapeError, InputError: malformed arguments (validated again at compile).
        """
        self._b.add_body(str(name), as_scalar("mass", mass), _inertia("inertia", inertia),
                         as_vector("pos", pos, 3), as_vector("quat", quat, 4), as_vector("com", com, 3),
                         as_scalar("gravcomp", gravcomp))

    def add_joint(self, name: str, kind: str, parent: str, child: str, axis=(0.0, 0.0, 1.0),
                  parent_anchor=(0.0, 0.0, 0.0), child_anchor=(0.0, 0.0, 0.0), stiffness=0.0,
                  damping=0.0, spring_ref=None, range=None, loop: bool = False,
                  frictionloss=0.0) -> None:
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
            range: Limits ``(lower, upper)`` (m or rad): one pair for a one-dof joint or one per
                free dof. Solved as inequality constraints by the interior-point method.
            loop: The joint closes a kinematic loop (not part of the spanning tree, no qpos).
            frictionloss: Dry friction, scalar or one per free dof (N or N·m; MuJoCo's
                ``frictionloss``): the joint resists motion with up to this force, and holds
                still under any smaller load (a complementarity problem of the interior-point
                solve, no creep).
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
                          bool(loop), _per_dof("frictionloss", frictionloss))

    def add_actuator(self, name: str, joint: str, gear: float = 1.0, ctrlrange=None,
                     dof: int = 0, kp: float = 0.0, kv: float = 0.0, forcerange=None,
                     actuatorfrcrange=None) -> None:
        """Add an actuator on free dof ``dof`` of ``joint``: a motor, generalized force
        ``gear * F`` with ``F = clamp(ctrl, ctrlrange)``; with ``kp``, a position servo
        ``F = kp (u - gear q) - kv gear q̇`` (MuJoCo's ``<position>``); with ``kv`` alone, a
        velocity servo ``F = kv (u - gear q̇)`` (``<velocity>``). ``F`` is clamped to
        ``forcerange``, then the generalized force ``gear * F`` to ``actuatorfrcrange`` (MuJoCo's
        joint attribute, here for the one actuator on the dof). A servo's velocity gain acts at
        the step's next velocity while ``F`` is inside its ranges (as MuJoCo's ``implicitfast`` integrator takes it), so stiff servos
        stay stable at large time steps.

        Args:
            name: Unique name.
            joint: Joint name.
            gear: Gear ratio.
            ctrlrange: ``(lower, upper)`` clamp of the control, or None.
            dof: Which free dof of the joint (0-based, in its qvel order).
            kp: Position gain (N·m or N per unit of ``gear q``), >= 0; 0: none.
            kv: Velocity gain, >= 0; 0: none.
            forcerange: ``(lower, upper)`` clamp of the scalar force ``F``, or None.
            actuatorfrcrange: ``(lower, upper)`` clamp of the generalized force ``gear * F`` on
                the dof (N·m or N), applied after ``forcerange``, or None.
        """
        rng = None if ctrlrange is None else tuple(as_vector("ctrlrange", ctrlrange, 2))
        frange = None if forcerange is None else tuple(as_vector("forcerange", forcerange, 2))
        jrange = (None if actuatorfrcrange is None
                  else tuple(as_vector("actuatorfrcrange", actuatorfrcrange, 2)))
        if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or dof < 0:
            raise TypeError(f"`dof` must be a non-negative integer, got {dof!r}")
        gains = {"kp": as_scalar("kp", kp), "kv": as_scalar("kv", kv)}
        for key, value in gains.items():
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"`{key}` must be finite and >= 0, got {value!r}")
        self._b.add_actuator(str(name), str(joint), int(dof), as_scalar("gear", gear), rng,
                             gains["kp"], gains["kv"], frange, jrange)

    def add_geom(self, name: str, body: str, shape: str, size=(), pos=(0.0, 0.0, 0.0),
                 quat=(1.0, 0.0, 0.0, 0.0), friction: float = 0.5, contact: str | None = "nonlinear",
                 normal=None, contype: int = 1, conaffinity: int = 1, vertices=None) -> None:
        """Add a collision geometry to ``body`` (``"world"`` for static geometry).

        Args:
            name: Unique name.
            body: Body name.
            shape: ``"plane"``, ``"sphere"``, ``"capsule"``, ``"box"``, ``"cylinder"``,
                ``"ellipsoid"``, ``"mesh"`` or ``"point"``.
            size: MuJoCo's sizes: sphere (radius,), capsule and cylinder (radius, half-length
                along the geom z axis), box (three half-extents), ellipsoid (three radii); plane
                and point take none.
            pos: Geom origin in the body frame (m). For a plane: a point on it.
            quat: Geom orientation in the body frame (w, x, y, z). A plane's normal is its +z.
            normal: Plane only: the unit normal in the body frame (sets ``quat``).
            friction: Coulomb coefficient; a pair uses the larger of its two geoms' (MuJoCo).
            contact: ``"nonlinear"`` (exact cone), ``"linear"`` (4-sided pyramid), ``"impact"``
                (frictionless) or None (never collides). A pair is frictionless if either geom
                says ``"impact"`` or its friction is 0, else linear if either says ``"linear"``.
            contype, conaffinity: MuJoCo's collision bitmasks.
            vertices: Mesh only: (N, 3) points in the geom frame (m); the geom is their convex
                hull (as MuJoCo collides a mesh), touching other shapes at the hull's vertices.
        """
        if not isinstance(shape, str):
            raise TypeError(f"`shape` must be a string, got {type(shape).__name__}")
        if contact is not None and not isinstance(contact, str):
            raise TypeError(f"`contact` must be a string or None, got {type(contact).__name__}")
        if normal is not None:
            if shape != "plane":
                raise ValueError(f"geom[{name}]: `normal` applies to planes only, not {shape!r}")
            quat = _quat_z_to(as_float_array("normal", normal, (3,)))
        size_list = as_float_array("size", size).ravel().tolist()
        if (vertices is None) == (shape == "mesh"):
            raise ValueError(f"geom[{name}]: `vertices` are given for a mesh and only for a mesh "
                             f"(shape {shape!r})")
        points = None if vertices is None else as_float_array("vertices", vertices, (-1, 3))
        self._b.add_geom(str(name), str(body), shape, size_list, as_vector("pos", pos, 3),
                         as_vector("quat", quat, 4), as_scalar("friction", friction), contact,
                         _bits("contype", contype), _bits("conaffinity", conaffinity),
                         None if points is None else points.tolist())

    def add_tendon_limit(self, name: str, terms, range) -> None:
        """Limit a fixed tendon (MuJoCo's limited ``<tendon><fixed>``): ``lo <= Σ coef·q <= hi``.

        Solved as a hard inequality in the same interior-point step as contacts and joint limits;
        the tendon impulse acts on each term's coordinate as ``coef · impulse``.

        Args:
            name: Unique name.
            terms: ``[(joint, coef), ...]`` or ``[(joint, coef, dof), ...]``: a hinge or slide
                coordinate (``dof``, default 0, a free dof of the joint in its qvel order; not a
                ball quaternion) and its coefficient. At least one coef must be non-zero.
            range: ``(lo, hi)`` of the length ``Σ coef·q`` (m or rad), ``lo < hi``.
        """
        parsed = _tendon_terms(f"tendon_limit[{name}]", terms)
        lo, hi = as_vector(f"tendon_limit[{name}].range", range, 2)
        self._b.add_tendon_limit(str(name), parsed, (lo, hi))

    def add_passive_tendon(self, name: str, terms, stiffness: float = 0.0, damping: float = 0.0,
                           springlength=None, frictionloss: float = 0.0) -> None:
        """A spring, a damper and dry friction on a fixed tendon's length ``L = Σ coef·q``
        (MuJoCo's ``<tendon><fixed stiffness damping springlength frictionloss>``): the tendon
        force ``-stiffness (L - springlength) - damping L̇`` plus a friction force of at most
        ``frictionloss`` against ``L̇`` acts on each term's coordinate as ``coef ·`` the force;
        the spring at the current configuration, the damper at the next velocities (implicit,
        like a joint damper), the friction as the joints' (``state.tendon_friction_impulse``).

        Args:
            name: Unique name.
            terms: ``[(joint, coef), ...]`` or ``[(joint, coef, dof), ...]`` over hinge or slide
                coordinates (as in :meth:`add_tendon_limit`).
            stiffness, damping: >= 0.
            springlength: Rest length (m or rad); None: the length at the joints' spring rest
                positions (MuJoCo's default).
            frictionloss: Dry friction (>= 0).
        """
        parsed = _tendon_terms(f"passive_tendon[{name}]", terms)
        rest = None if springlength is None else as_scalar(f"passive_tendon[{name}].springlength",
                                                           springlength)
        self._b.add_passive_tendon(str(name), parsed, as_scalar("stiffness", stiffness),
                                   as_scalar("damping", damping), rest,
                                   as_scalar("frictionloss", frictionloss))

    def add_pair(self, geom_a: str, geom_b: str, friction: float = 1.0,
                 contact: str = "nonlinear") -> None:
        """Collide two geoms explicitly (MuJoCo's ``<contact><pair>``): whatever their bitmasks,
        bodies and exclusions say, with this friction and contact model in place of the pair
        those rules would make.

        Args:
            geom_a, geom_b: Geom names (on different bodies).
            friction: Coulomb coefficient (>= 0).
            contact: ``"nonlinear"`` (exact cone), ``"linear"`` (4-sided pyramid) or
                ``"impact"`` (frictionless).
        """
        if not isinstance(contact, str):
            raise TypeError(f"`contact` must be a string, got {type(contact).__name__}")
        self._b.add_pair(str(geom_a), str(geom_b), as_scalar("friction", friction), contact)

    def add_exclude(self, body_a: str, body_b: str) -> None:
        """Never collide the geoms of these two bodies (MuJoCo's ``contact/exclude``)."""
        self._b.add_exclude(str(body_a), str(body_b))

    def compile(self):
        """Validate and compile.

        Returns:
            ukemi.Model

        Raises:
            ModelError: a field is invalid; the message names it and its value.
            UnsupportedError: a feature that is not available.
        """
        return self._b.compile()


def _tendon_terms(field: str, terms) -> list:
    """``[(joint, dof, coef), ...]`` of ``[(joint, coef[, dof]), ...]``, validated."""
    if isinstance(terms, (str, bytes)) or not hasattr(terms, "__iter__"):
        raise TypeError(f"{field}.terms must be a list of (joint, coef[, dof]), got {terms!r}")
    parsed = []
    for i, term in enumerate(terms):
        if isinstance(term, (str, bytes)) or not hasattr(term, "__len__") or len(term) not in (2, 3):
            raise TypeError(f"{field}.terms[{i}] must be (joint, coef) or (joint, coef, dof), got {term!r}")
        joint, coef, *rest = term
        dof = rest[0] if rest else 0
        if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or dof < 0:
            raise TypeError(f"{field}.terms[{i}] dof must be a non-negative integer, got {dof!r}")
        parsed.append((str(joint), int(dof), as_scalar(f"{field}.terms[{i}].coef", coef)))
    return parsed
