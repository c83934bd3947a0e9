"""A small software renderer for ``render_mode="rgb_array"``: an orthographic view of the body
tree (parent-to-child links) and of capsule geoms given by ``fromto``, drawn with numpy. Enough
to see what a policy does; not MuJoCo's OpenGL renderer."""

from __future__ import annotations

import numpy as np

from ._assets import rotate

_AXES = {"xz": (0, 2), "xy": (0, 1), "yz": (1, 2)}
_SKY, _GROUND, _LINK, _GEOM = (235, 240, 245), (120, 130, 120), (60, 60, 60), (200, 90, 40)


def _disk_line(img, p0, p1, radius, color):
    h, w, _ = img.shape
    n = int(max(abs(p1[0] - p0[0]), abs(p1[1] - p0[1]), 1)) + 1
    pts = np.linspace(p0, p1, n)
    r = max(int(radius), 1)
    oy, ox = np.mgrid[-r : r + 1, -r : r + 1]
    mask = ox**2 + oy**2 <= r * r
    offsets = np.stack([ox[mask], oy[mask]], axis=1)
    px = (np.round(pts)[:, None, :] + offsets[None]).reshape(-1, 2).astype(int)
    ok = (px[:, 0] >= 0) & (px[:, 0] < w) & (px[:, 1] >= 0) & (px[:, 1] < h)
    img[px[ok, 1], px[ok, 0]] = color


def render_frame(env) -> np.ndarray:
    """An (height, width, 3) uint8 image of the env's current state."""
    plane, track, half_extent = env._view
    a, b = _AXES[plane]
    s = env.state
    pos, quat = s.body_pos, s.body_quat
    h, w = env.height, env.width
    centre = np.zeros(2) if track is None else np.array([pos[track, a], 0.0 if plane == "xz" else pos[track, b]])
    if plane == "xz":
        centre[1] = half_extent * 0.8
    scale = min(h, w) / (2 * half_extent)

    def to_px(p):
        return np.array([w / 2 + (p[a] - centre[0]) * scale, h / 2 - (p[b] - centre[1]) * scale])

    img = np.empty((h, w, 3), np.uint8)
    img[:] = _SKY
    if plane == "xz":
        ground = int(np.clip(h / 2 + centre[1] * scale, 0, h))
        img[ground:] = _GROUND
    for child, parent in enumerate(env._info.parent):
        if parent > 0:
            _disk_line(img, to_px(pos[parent]), to_px(pos[child]), 0.01 * scale, _LINK)
    for body, p_from, p_to, radius in env._info.segments:
        q0 = pos[body] + rotate(quat[body], p_from)
        q1 = pos[body] + rotate(quat[body], p_to)
        _disk_line(img, to_px(q0), to_px(q1), radius * scale, _GEOM)
    return img
