"""Model loaders: ``ukemi.load`` (dispatch on the file suffix) and gymnasium's MJCF assets.

``ukemi.Model.from_xml_path``, ``from_xml_string``, ``from_urdf_path`` and ``from_urdf_string``
are implemented in the extension; features the loader ignores are reported with :func:`warnings.warn`.
"""

from __future__ import annotations

import os
from pathlib import Path

from ._ukemi import Model
from .errors import InputError, UnsupportedError

_GYMNASIUM_ASSETS = (
    "ant", "half_cheetah", "hopper", "humanoid", "humanoidstandup", "inverted_double_pendulum",
    "inverted_pendulum", "point", "pusher", "pusher_v5", "reacher", "swimmer", "walker2d",
    "walker2d_v5",
)


def load(path: str | os.PathLike, floating: bool = True) -> Model:
    """Load a model file, choosing the format by its suffix.

    Args:
        path: An MJCF file (``.xml``, ``.mjcf``) or a URDF file (``.urdf``).
        floating: URDF only: give the root link a free joint (``True``) or fix it to the world.

    Returns:
        ukemi.Model

    Raises:
        MjcfError: the MJCF file is missing, malformed, or has an invalid value (the message
            names the element and line).
        UrdfError: the same for a URDF file.
        UnsupportedError: the model uses a feature ukemi does not support, or the suffix is
            not known.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in (".xml", ".mjcf"):
        return Model.from_xml_path(str(p))
    if suffix == ".urdf":
        return Model.from_urdf_path(str(p), floating=floating)
    raise UnsupportedError(f"unsupported: unknown model file suffix {suffix!r} of {p} (expected .xml or .urdf)")


def gymnasium_asset_path(name: str) -> Path:
    """Path of one of gymnasium's MuJoCo MJCF assets, found in the installed package.

    Args:
        name: Asset name without ``.xml``, e.g. ``"hopper"``, ``"half_cheetah"``.

    Returns:
        pathlib.Path of the XML file.

    Raises:
        InputError: unknown name, or gymnasium is not installed.
    """
    if name not in _GYMNASIUM_ASSETS:
        raise InputError(f"invalid input: `name` = {name!r}: unknown gymnasium asset; expected one of {_GYMNASIUM_ASSETS}")
    try:
        import gymnasium
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise InputError("invalid input: gymnasium is not installed (pip install gymnasium)") from e
    path = Path(gymnasium.__file__).parent / "envs" / "mujoco" / "assets" / f"{name}.xml"
    if not path.is_file():
        raise InputError(f"invalid input: `name` = {name!r}: {path} does not exist in this gymnasium version")
    return path
