"""Model loading for the environments: gymnasium's MJCF assets, cached, plus the few MJCF facts
the engine does not expose (sites for observations, capsule segments for the renderer)."""

from __future__ import annotations

import functools
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._loaders import gymnasium_asset_path
from .._ukemi import Model

# The loader reports MuJoCo solver options (and humanoid.xml's passive tendons) it ignores; the
# env docstrings document them.
_BENIGN = ("ukemi's own integrator and interior-point solver are used", "passive tendon ignored")


def asset_path(xml_file: str) -> Path:
    """An absolute path, or a gymnasium asset name such as ``"hopper.xml"``."""
    p = Path(xml_file)
    if p.is_absolute() or p.exists():
        return p
    return gymnasium_asset_path(p.name.removesuffix(".xml"))


@functools.lru_cache(maxsize=64)
def load_model(path: str, timestep: float | None, options: tuple[tuple[str, float], ...]) -> Model:
    """Load once per (file, options); ``Model`` is immutable, so envs share it."""
    with warnings.catch_warnings():
        for message in _BENIGN:
            warnings.filterwarnings("ignore", message=f".*{message}.*")
        model = Model.from_xml_path(path)
    opts = dict(options)
    if timestep is not None:
        opts["timestep"] = timestep
    return model.with_options(**opts) if opts else model


def _vec(text: str | None, n: int, default: float = 0.0) -> np.ndarray:
    return np.array([float(s) for s in text.split()]) if text else np.full(n, default)


_SEGMENT_TYPES = ("capsule", "cylinder", "sphere", "box")


def _segment(geom: ET.Element) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(local from, local to, radius) of a capsule, cylinder or sphere geom (renderer only)."""
    size = _vec(geom.get("size"), 1, 0.02)
    if geom.get("type") == "box":  # drawn as a disk of its first half-size
        centre = _vec(geom.get("pos"), 3)
        return centre, centre, float(size[0])
    if geom.get("fromto"):
        ft = _vec(geom.get("fromto"), 6)
        return ft[:3], ft[3:], float(size[0])
    if geom.get("type", "sphere") == "sphere":
        centre = _vec(geom.get("pos"), 3)
        return centre, centre, float(size[0])
    if len(size) < 2:
        return None
    centre = _vec(geom.get("pos"), 3)
    quat = _vec(geom.get("quat"), 4) if geom.get("quat") else np.array([1.0, 0, 0, 0])
    half = rotate(quat / np.linalg.norm(quat), np.array([0.0, 0.0, size[1]]))
    return centre - half, centre + half, float(size[0])


@dataclass
class MjcfInfo:
    """Body tree, sites and capsule segments read from the MJCF (body order as MuJoCo's)."""

    parent: list[int] = field(default_factory=list)  #: parent body index per body (world = -1)
    sites: dict[str, tuple[int, np.ndarray]] = field(default_factory=dict)  #: name -> (body, local pos)
    segments: list[tuple[int, np.ndarray, np.ndarray, float]] = field(default_factory=list)
    #: (body, local from, local to, radius) of capsule, cylinder and sphere geoms
    actuator_joints: list[str] = field(default_factory=list)  #: joint of each actuator, in order


@functools.lru_cache(maxsize=64)
def mjcf_info(path: str) -> MjcfInfo:
    info = MjcfInfo(parent=[-1])
    root = ET.parse(path).getroot()

    def visit(elem: ET.Element, body: int) -> None:
        for child in elem:
            if child.tag == "site" and child.get("name"):
                info.sites[child.get("name")] = (body, _vec(child.get("pos"), 3))
            elif child.tag == "geom" and child.get("type", "sphere") in _SEGMENT_TYPES:
                segment = _segment(child)
                if segment is not None:
                    info.segments.append((body, *segment))
            elif child.tag == "body":
                info.parent.append(body)
                visit(child, len(info.parent) - 1)

    for wb in root.iter("worldbody"):
        visit(wb, 0)
    for act in root.iter("actuator"):
        info.actuator_joints.extend(a.get("joint", "") for a in act)
    return info


def rotate(quat: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate ``v`` (..., 3) by unit quaternions ``quat`` (..., 4) in (w, x, y, z)."""
    w, u = quat[..., :1], quat[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)
