"""The separating-axis oracle of ``_overlap`` against separations known in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from ._overlap import Polytope, separation

IDENTITY = (1.0, 0.0, 0.0, 0.0)


def turn(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return (np.cos(angle / 2), *(np.sin(angle / 2) * axis))


@pytest.mark.parametrize(("gap", "quat_b"), [(0.1, IDENTITY), (-0.05, IDENTITY), (0.0, IDENTITY),
                                             (0.02, turn((0, 0, 1), 0.7)),
                                             (-0.03, turn((0, 0, 1), 0.7))])
def test_stacked_cubes_are_apart_by_the_gap(gap, quat_b):
    """A unit cube on another, turned about the vertical or not: apart (or overlapping) by the
    gap between the top face and the bottom one."""
    a, b = Polytope.box(1, (0.5, 0.5, 0.5)), Polytope.box(2, (0.5, 0.5, 0.5))
    s = separation(a, ((0, 0, 1 + gap), IDENTITY), b, ((0, 0, 0), quat_b))
    assert abs(s - gap) < 1e-12


def test_cubes_crossed_edge_on_edge_overlap_along_the_edges_normal():
    """Two unit cubes turned 45° about crossed horizontal axes meet edge on edge: a lower edge
    along y over an upper edge along x, at heights ±√2/2 from the centres."""
    a = Polytope.box(1, (0.5, 0.5, 0.5))
    b = Polytope.box(2, (0.5, 0.5, 0.5))
    h = np.sqrt(2) / 2
    for gap in (0.05, -0.04):
        s = separation(a, ((0, 0, 2 * h + gap), turn((0, 1, 0), np.pi / 4)),
                       b, ((0, 0, 0), turn((1, 0, 0), np.pi / 4)))
        assert abs(s - gap) < 1e-12, (gap, s)


def test_a_hull_given_by_its_points_matches_the_box():
    """A hull of a box's eight corners and a few interior points measures as the box."""
    rng = np.random.default_rng(0)
    corners = Polytope.box(1, (0.3, 0.2, 0.1)).vertices
    hull = Polytope(1, np.vstack([corners, rng.uniform(-0.05, 0.05, (4, 3))]))
    other = Polytope.box(2, (0.2, 0.2, 0.2))
    for z in (0.35, 0.25):
        pose_b = ((0.1, 0.0, -z), turn((1, 1, 0), 0.2))
        expect = separation(Polytope.box(1, (0.3, 0.2, 0.1)), ((0, 0, 0), IDENTITY), other, pose_b)
        assert abs(separation(hull, ((0, 0, 0), IDENTITY), other, pose_b) - expect) < 1e-12
