"""A zoo of ready models: ``ukemi.models.pendulum()``, ``ukemi.models.chain(10)``, ...

Each model is an MJCF file written for ukemi and shipped in this package (read through
:mod:`importlib.resources`), except :func:`chain`, whose XML is generated, and :func:`gymnasium`,
which loads the MJCF files gymnasium installs. Every model has actuators with a control range and
starts from a consistent reference pose (some also carry keyframes, listed in
``model.keyframe_names``).

======================  ==================================================================
name                    what
======================  ==================================================================
``box``                 a free 0.2 m cube resting on a floor
``pendulum``            1 kg at 1 m below a hinge (period checks against the analytic one)
``double_pendulum``     two capsules on hinges
``chain(n)``            ``n`` capsules on hinges, hanging from the world
``cartpole``            a cart on a limited rail with a pole
``fourbar``             a planar four-bar closed by an equality ``connect``
``raibert_hopper``      a planar body with a hip and a sprung prismatic leg, spherical foot
``half_cheetah``        a planar two-legged runner
``ant``                 a spherical torso with four two-hinge legs, free joint
``quadruped``           an A1-sized quadruped with position servos
``humanoid``            a simplified humanoid (3-hinge hips, knees, 2-hinge shoulders, elbows)
``box_pusher``          a planar two-link arm pushing a free box on a floor
======================  ==================================================================
"""

from __future__ import annotations

import warnings
from importlib import resources

from .._loaders import gymnasium_asset_path
from .._ukemi import Model
from ..errors import InputError

_GYMNASIUM = {
    "hopper": "hopper",
    "half_cheetah": "half_cheetah",
    "ant": "ant",
    "walker2d": "walker2d",
    "humanoid": "humanoid",
    "inverted_pendulum": "inverted_pendulum",
    "inverted_double_pendulum": "inverted_double_pendulum",
    "reacher": "reacher",
    "swimmer": "swimmer",
    "pusher": "pusher",
}


def _load(name: str) -> Model:
    text = resources.files(__name__).joinpath(f"{name}.xml").read_text(encoding="utf-8")
    return Model.from_xml_string(text)


def box() -> Model:
    """A free 1 kg, 0.2 m cube resting on a floor (nq 7, nu 0: the box has no actuator)."""
    return _load("box")


def pendulum() -> Model:
    """A 1 kg point-like mass 1 m below a hinge about y; one motor (ctrlrange ±2 N·m)."""
    return _load("pendulum")


def double_pendulum() -> Model:
    """Two 0.5 m capsules on hinges about y; two motors (±5 N·m)."""
    return _load("double_pendulum")


def cartpole() -> Model:
    """A cart on a rail (slide x, range ±2 m) with a 0.6 m pole; one motor on the cart (±10 N)."""
    return _load("cartpole")


def fourbar() -> Model:
    """A planar four-bar (crank, coupler, rocker) whose loop is closed by an equality connect.

    ``qpos`` holds the three hinge angles; only one is independent. One motor on the crank.
    """
    return _load("fourbar")


def raibert_hopper() -> Model:
    """A planar Raibert hopper: torso (slide x, slide z, hinge y), hip hinge and a sprung
    prismatic leg with a spherical foot; motors on hip (±10 N·m) and leg thrust (±200 N)."""
    return _load("raibert_hopper")


def half_cheetah() -> Model:
    """A planar half-cheetah: planar root and six hinges with motors."""
    return _load("half_cheetah")


def ant() -> Model:
    """An ant: spherical torso on a free joint, four legs of two hinges, eight motors."""
    return _load("ant")


def quadruped() -> Model:
    """An A1-sized quadruped with twelve position servos; keyframe ``"stand"``."""
    return _load("quadruped")


def humanoid() -> Model:
    """A simplified humanoid with a free torso and 14 motorised hinges."""
    return _load("humanoid")


def box_pusher() -> Model:
    """A planar two-link arm whose fingertip pushes a free box on a floor; two motors."""
    return _load("box_pusher")


def chain_xml(n: int, link_length: float = 0.2, timestep: float = 0.01) -> str:
    """MJCF text of an ``n``-link chain of capsules on hinges about y, hanging from the world.

    Args:
        n: Number of links (≥ 1).
        link_length: Length of each link (m).
        timestep: Time step (s).

    Returns:
        str: the MJCF document.

    Raises:
        InputError: ``n`` < 1 or a non-positive length or time step.
    """
    if not isinstance(n, int) or n < 1:
        raise InputError(f"invalid input: `n` = {n!r}: must be an integer >= 1")
    if not link_length > 0 or not timestep > 0:
        raise InputError(
            f"invalid input: `link_length` = {link_length!r}, `timestep` = {timestep!r}: must be > 0"
        )
    opening = "".join(
        f'<body name="link{i}" pos="0 0 {n * link_length if i == 1 else -link_length!r}">'
        f'<joint name="hinge{i}"/><geom fromto="0 0 0 0 0 {-link_length!r}"/>'
        for i in range(1, n + 1)
    )
    body = opening + "</body>" * n
    motors = "".join(f'<motor name="hinge{i}" joint="hinge{i}"/>' for i in range(1, n + 1))
    return (
        f'<mujoco model="chain{n}"><option timestep="{timestep!r}"/>'
        '<default><joint type="hinge" axis="0 1 0" damping="0.01"/>'
        '<geom type="capsule" size="0.02" density="1000" contype="0" conaffinity="0"/>'
        '<motor gear="1" ctrlrange="-1 1"/></default>'
        f"<worldbody>{body}</worldbody><actuator>{motors}</actuator></mujoco>"
    )


def chain(n: int = 5, link_length: float = 0.2, timestep: float = 0.01) -> Model:
    """An ``n``-link chain of capsules on hinges about y, hanging from the world; one motor each.

    Args:
        n: Number of links (≥ 1).
        link_length: Length of each link (m).
        timestep: Time step (s).

    Returns:
        ukemi.Model

    Raises:
        InputError: bad ``n``, ``link_length`` or ``timestep``.
    """
    return Model.from_xml_string(chain_xml(n, link_length, timestep))


def gymnasium(name: str) -> Model:
    """Load one of the MJCF files gymnasium installs, found from the installed package.

    Features ukemi ignores (fluid forces, solver options...) are reported by the loader as
    warnings; they are silenced here.

    Args:
        name: One of ``hopper, half_cheetah, ant, walker2d, humanoid, inverted_pendulum,
            inverted_double_pendulum, reacher, swimmer, pusher``.

    Returns:
        ukemi.Model

    Raises:
        InputError: unknown name, or gymnasium is not installed.
    """
    if name not in _GYMNASIUM:
        raise InputError(
            f"invalid input: `name` = {name!r}: expected one of {sorted(_GYMNASIUM)}"
        )
    path = gymnasium_asset_path(_GYMNASIUM[name])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Model.from_xml_path(str(path))


ZOO = (
    "box", "pendulum", "double_pendulum", "cartpole", "fourbar", "raibert_hopper",
    "half_cheetah", "ant", "quadruped", "humanoid", "box_pusher",
)
GYMNASIUM = tuple(_GYMNASIUM)

__all__ = [*ZOO, "chain", "chain_xml", "gymnasium", "ZOO", "GYMNASIUM"]
