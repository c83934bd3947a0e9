"""Seeded generator of random scenes on a floor: loose bodies, or a mechanism of 1-3 links
joined by random joint kinds (all 16 of ``ukemi.JOINT_KINDS``, hinge/slide/ball/universal
drawn most often) with random axes and anchors, limits on some joints and, when asked, dry
friction on about half of them (drawn from a second stream: a scene with friction is
otherwise the scene without)."""

from __future__ import annotations

import numpy as np

import ukemi

from ._overlap import Polytope
from ._util import add_free, floor_builder

SHAPES = ("sphere", "box", "capsule", "cylinder", "ellipsoid")
# the shapes of the scenes below (kept as they were measured; ellipsoids collide only with
# planes): cylinders meet the others in `random_pile`
PAIRWISE = ("sphere", "box", "capsule")
PILE = ("sphere", "box", "capsule", "cylinder", "cylinder")
COMMON_KINDS = ("revolute", "prismatic", "spherical", "orbital")  # hinge, slide, ball, universal
LINK_SPACING = 0.35  # m between link centres: only adjacent (excluded) links can overlap


def inertia(shape: str, size, mass: float):
    """Principal inertia of a solid of that shape (approximate for capsule/cylinder)."""
    if shape == "sphere":
        return (0.4 * mass * size[0] ** 2,) * 3
    if shape in ("box", "ellipsoid"):
        a, b, c = (2 * s for s in size) if shape == "box" else size
        k = 1 / 12 if shape == "box" else 1 / 5
        return (k * mass * (b * b + c * c), k * mass * (a * a + c * c), k * mass * (a * a + b * b))
    r, half = size
    ixx = mass * (3 * r * r + (2 * half) ** 2) / 12
    return (ixx, ixx, 0.5 * mass * r * r)


def _size(rng, shape: str, hi: float = 0.2):
    if shape == "sphere":
        return (float(rng.uniform(0.03, hi)),)
    if shape in ("box", "ellipsoid"):
        return tuple(float(x) for x in rng.uniform(0.03, hi, 3))
    return (float(rng.uniform(0.03, hi / 2)), float(rng.uniform(0.03, hi)))


def _unit(rng) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _quat(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def _rotate_inv(quat: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(quat)ᵀ v for a unit quaternion (w, x, y, z)."""
    w, u = quat[0], -quat[1:]
    return v + 2 * w * np.cross(u, v) + 2 * np.cross(u, np.cross(u, v))


def kind_dofs(kind: str) -> tuple[int, int]:
    """(free translations, free rotations) of a joint kind (JOINT_KINDS is ordered by both)."""
    i = ukemi.JOINT_KINDS.index(kind)
    return i % 4, i // 4


def _limits(rng, kind: str):
    """Random limits around the reference pose, or None (balls take none)."""
    ntrans, nrot = kind_dofs(kind)
    if nrot == 3 or ntrans + nrot == 0 or rng.random() > 0.4:
        return None
    spans = [0.3] * ntrans + [1.0] * nrot  # m, rad
    return [(-float(rng.uniform(0.05, s)), float(rng.uniform(0.05, s))) for s in spans]


def _loose_bodies(rng, b) -> str:
    nbody = int(rng.integers(1, 4))
    for i in range(nbody):
        shapes = SHAPES if nbody == 1 else PAIRWISE
        shape = shapes[int(rng.integers(len(shapes)))]
        size = _size(rng, shape)
        mass = float(np.exp(rng.uniform(np.log(0.1), np.log(10.0))))
        pos = (float(rng.uniform(-1, 1)), float(rng.uniform(-1, 1)), 0.5 + 0.6 * i)
        add_free(b, f"b{i}", shape, size, mass, inertia(shape, size, mass), pos,
                 tuple(_quat(rng)), friction=float(rng.uniform(0.2, 1.0)))
    return f"{nbody} loose bod{'y' if nbody == 1 else 'ies'}"


def _kind(rng) -> str:
    pool = COMMON_KINDS if rng.random() < 0.5 else ukemi.JOINT_KINDS
    return pool[int(rng.integers(len(pool)))]


def _mechanism(rng, b, rub=None) -> str:
    """A chain of 1-3 links; the first hangs from the world by a random joint (or floats)."""
    nlink = int(rng.integers(1, 4))
    direction = _unit(rng)
    centres = [np.zeros(3) + i * LINK_SPACING * direction for i in range(nlink)]
    lift = 0.3 - min(c[2] for c in centres) + float(rng.uniform(0.0, 0.6))
    xy = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), lift])
    centres = [c + xy for c in centres]
    quats = [_quat(rng) for _ in range(nlink)]
    kinds = []
    for i, (pos, quat) in enumerate(zip(centres, quats, strict=True)):
        shape = PAIRWISE[int(rng.integers(len(PAIRWISE)))]
        size = _size(rng, shape, hi=0.1)
        mass = float(np.exp(rng.uniform(np.log(0.2), np.log(5.0))))
        name = f"l{i}"
        b.add_body(name, mass, inertia(shape, size, mass), pos=tuple(pos), quat=tuple(quat))
        b.add_geom(name, name, shape, size=size, friction=float(rng.uniform(0.2, 1.0)))
        if i == 0:
            kind = "floating" if rng.random() < 0.25 else _kind(rng)
            anchor = pos + 0.2 * _unit(rng)  # world point the joint holds
            parent, parent_anchor = "world", anchor
        else:
            kind = _kind(rng)
            anchor = 0.5 * (centres[i - 1] + pos) + rng.uniform(-0.05, 0.05, 3)
            parent = f"l{i - 1}"
            parent_anchor = _rotate_inv(quats[i - 1], anchor - centres[i - 1])
            b.add_exclude(parent, name)  # MuJoCo's parent-child rule
        # dry friction up to the torque of the link's weight at 0.2 m (or its weight, sliding)
        friction = 0.0
        if rub is not None and kind != "floating" and rub.random() < 0.5:
            friction = float(rub.uniform(0.0, 2.0)) * mass * 9.81 * 0.2
        b.add_joint(f"j{i}", kind, parent, name, axis=tuple(_unit(rng)),
                    parent_anchor=tuple(parent_anchor),
                    child_anchor=tuple(_rotate_inv(quat, anchor - pos)),
                    range=_limits(rng, kind), frictionloss=friction)
        kinds.append(kind + (" with friction" if friction else ""))
    return f"{nlink}-link chain ({', '.join(kinds)})"


def random_scene(seed: int, joint_friction: bool = False, excludes=()):
    """(model, description) of scene ``seed``: 40% loose bodies, 60% a jointed mechanism (with
    ``joint_friction``, dry friction on about half of its joints); ``excludes``: pairs of body
    names that do not collide."""
    rng = np.random.default_rng(seed)
    b = floor_builder(friction=float(rng.uniform(0.2, 1.0)))
    rub = np.random.default_rng([seed, 1]) if joint_friction else None
    desc = _loose_bodies(rng, b) if rng.random() < 0.4 else _mechanism(rng, b, rub)
    for pair in excludes:
        b.add_exclude(*pair)
    return b.compile(), desc


def random_box_pile(seed: int):
    """(model, description) of box pile ``seed``: 3-6 free boxes of random sizes, masses and
    orientations dropped one above the other within a 0.3 m square, so that they land on each
    other corner, edge or face first (the box pairs' corners and edge crossings)."""
    m, desc, _ = box_pile_with_solids(seed)
    return m, desc


def box_pile_with_solids(seed: int):
    """:func:`random_box_pile` and its boxes as ``_overlap.Polytope`` s."""
    rng = np.random.default_rng([seed, 3])
    solids = []
    b = floor_builder(friction=float(rng.uniform(0.2, 1.0)))
    nbody = int(rng.integers(3, 7))
    for i in range(nbody):
        size = _size(rng, "box", hi=0.12)
        mass = float(np.exp(rng.uniform(np.log(0.2), np.log(5.0))))
        pos = (float(rng.uniform(-0.15, 0.15)), float(rng.uniform(-0.15, 0.15)), 0.3 + 0.3 * i)
        add_free(b, f"b{i}", "box", size, mass, inertia("box", size, mass), pos,
                 tuple(_quat(rng)), friction=float(rng.uniform(0.2, 1.0)))
        solids.append(Polytope.box(i + 1, size))
    return b.compile(), f"pile of {nbody} boxes", solids


def random_hull_pile(seed: int):
    """(model, description) of hull pile ``seed``: 3-5 free meshes (the convex hulls of 6-10
    random points, a few centimetres across) dropped one above the other, so that they land on
    each other vertex, edge or face first (the hull pairs' vertices and edge crossings)."""
    m, desc, _ = hull_pile_with_solids(seed)
    return m, desc


def hull_pile_with_solids(seed: int):
    """:func:`random_hull_pile` and its hulls as ``_overlap.Polytope`` s."""
    rng = np.random.default_rng([seed, 4])
    solids = []
    b = floor_builder(friction=float(rng.uniform(0.2, 1.0)))
    nbody = int(rng.integers(3, 6))
    for i in range(nbody):
        points = rng.normal(size=(int(rng.integers(6, 11)), 3)) * rng.uniform(0.03, 0.08, 3)
        reach = float(np.abs(points).max())
        b.add_body(f"b{i}", 1.0, (0.4 * reach * reach,) * 3,
                   pos=(float(rng.uniform(-0.1, 0.1)), float(rng.uniform(-0.1, 0.1)),
                        0.3 + 0.4 * i), quat=tuple(_quat(rng)))
        b.add_joint(f"b{i}_free", "free", "world", f"b{i}")
        b.add_geom(f"b{i}", f"b{i}", "mesh", vertices=points.tolist(),
                   friction=float(rng.uniform(0.2, 1.0)))
        solids.append(Polytope(i + 1, points))
    return b.compile(), f"pile of {nbody} hulls", solids


def random_pile(seed: int):
    """(model, description) of pile ``seed``: 3-6 free bodies of random shapes (cylinders drawn
    twice as often), sizes, masses and orientations dropped one above the other within a
    0.3 m square, so that they land on each other: every pair of shapes with a cylinder."""
    rng = np.random.default_rng([seed, 2])
    b = floor_builder(friction=float(rng.uniform(0.2, 1.0)))
    nbody = int(rng.integers(3, 7))
    shapes = []
    for i in range(nbody):
        shape = PILE[int(rng.integers(len(PILE)))]
        size = _size(rng, shape, hi=0.12)
        mass = float(np.exp(rng.uniform(np.log(0.2), np.log(5.0))))
        pos = (float(rng.uniform(-0.15, 0.15)), float(rng.uniform(-0.15, 0.15)), 0.3 + 0.3 * i)
        add_free(b, f"b{i}", shape, size, mass, inertia(shape, size, mass), pos,
                 tuple(_quat(rng)), friction=float(rng.uniform(0.2, 1.0)))
        shapes.append(shape)
    return b.compile(), f"pile of {', '.join(shapes)}"
