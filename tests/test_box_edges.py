"""Boxes that meet edge on edge (engine/src/contact/pairs/box_edges.rs). Until session 43 a box
pair's candidates were its sixteen corners: a cube stacked on an equal cube turned about the
vertical by any angle (0.3° was enough) fell through it, every corner passing beside the other
box, and a cube dropped edge-down across another's edge sank 10 cm into it."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import ukemi

ROOT2 = np.sqrt(2.0)


def load(xml):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ukemi.Model.from_xml_string(xml)


def mujoco_run(xml, nsteps):
    mujoco = pytest.importorskip("mujoco")
    mj = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(mj)
    for _ in range(nsteps):
        mujoco.mj_step(mj, d)
    return d


def least_distance(m, traj):
    return min(ukemi.signed_distances(m, m.make_state(qpos=q)).min() for q in traj.qpos)


def assert_rests(xml, nsteps, index, height):
    """Simulate ``xml`` for ``nsteps``: every step converges, qpos[index] ends at ``height`` to
    1e-8 m and still, no candidate overlaps at any step, and MuJoCo's soft contacts end it at
    that height within 1 mm. Returns the model and trajectory."""
    m = load(xml)
    traj = ukemi.rollout(m, m.make_state(), nsteps=nsteps)
    assert traj.converged
    assert abs(traj.qpos[-1, index] - height) < 1e-8, traj.qpos[-1]
    assert np.abs(traj.qvel[-1]).max() < 1e-6
    assert least_distance(m, traj) > -1e-8
    d = mujoco_run(xml, nsteps)
    assert abs(d.qpos[index] - height) < 1e-3, d.qpos
    return m, traj


def stack_xml(yaw_degrees):
    return f"""<mujoco><option timestep="0.01"/><worldbody>
      <geom type="plane" size="2 2 0.1"/>
      <body pos="0 0 0.1"><freejoint/><geom type="box" size="0.1 0.1 0.1" mass="1"/></body>
      <body pos="0 0 0.305" euler="0 0 {yaw_degrees}"><freejoint/>
        <geom type="box" size="0.1 0.1 0.1" mass="1"/></body>
    </worldbody></mujoco>"""


@pytest.mark.parametrize("yaw", [0.0, 0.3, 20.0, 45.0])
def test_a_cube_turned_on_a_cube_rests_on_their_edge_crossings(yaw):
    """Turned by any angle, every corner of either cube lies outside the other's face: the
    upper one rests on the points where its bottom edges cross the lower one's top edges (the
    contact octagon's vertices), at the analytic height to 1e-8 m, still, with no overlap at
    any step; MuJoCo's soft contacts rest it at the same height within 1 mm."""
    _, traj = assert_rests(stack_xml(yaw), 150, 9, 0.3)
    assert abs(traj.qpos[-1, 2] - 0.1) < 1e-8


def ridge_xml(dx, dy=0.0, tilt=45.0):
    top = 0.3 + 0.1 * ROOT2
    return f"""<mujoco><option timestep="0.01"/><worldbody>
      <geom type="plane" size="2 2 0.1"/>
      <geom type="box" size="0.4 0.1 0.1" pos="0 0 0.3" euler="45 0 0"/>
      <body pos="{dx} {dy} {top + 0.1 * ROOT2 + 0.005}" euler="0 {tilt} 0"><freejoint/>
        <geom type="box" size="0.1 0.1 0.1" mass="1"/></body>
    </worldbody></mujoco>"""


def test_a_cube_dropped_edge_down_across_a_ridge_lands_on_the_crossing():
    """A cube turned 45° about y (its lowest edge along y) dropped 5 mm onto a ridge along x
    (a box turned 45° about x), anywhere along it: the edges cross at one point below the
    cube's centre, which holds it balanced there, its lowest edge at the ridge's height to
    1e-8 m (MuJoCo: within 1 mm)."""
    xml = ridge_xml(0.13)
    m = load(xml)
    traj = ukemi.rollout(m, m.make_state(), nsteps=30)
    assert traj.converged
    lowest = traj.qpos[:, 2] - 0.1 * ROOT2
    ridge = 0.3 + 0.1 * ROOT2
    assert np.abs(lowest[10:] - ridge).max() < 1e-8, lowest - ridge
    assert least_distance(m, traj) > -1e-8
    d = mujoco_run(xml, 30)
    assert abs(d.qpos[2] - 0.1 * ROOT2 - ridge) < 1e-3, d.qpos


@pytest.mark.parametrize(("dy", "tilt"), [(0.05, 45.0), (0.0, 40.0), (0.09, 30.0)])
def test_a_cube_tipping_off_a_ridge_never_sinks_into_it(dy, tilt):
    """Dropped beside the ridge's line or tilted, the cube lands on its edge or a corner across
    the ridge, tips and slides off it: every step converges, no candidate overlaps at any step
    (edges, corners and the floor) and the energy never rises."""
    m = load(ridge_xml(0.0, dy, tilt))
    traj = ukemi.rollout(m, m.make_state(), nsteps=300)
    assert traj.converged
    assert least_distance(m, traj) > -1e-8
    assert np.max(traj.energy - traj.energy[0]) < 1e-4 * max(1.0, abs(traj.energy[0]))


def test_a_plank_lies_across_a_box_on_four_crossings():
    """A plank lying face down diagonally across a box's top: every corner of the plank is
    beyond the box's top and every corner of the box's top beyond the plank, so only the four
    crossings of their edges hold it, at the analytic height (still, to 1e-8 m; MuJoCo 1 mm)."""
    assert_rests("""<mujoco><option timestep="0.01"/><worldbody>
      <geom type="plane" size="2 2 0.1"/>
      <geom type="box" size="0.1 0.1 0.1" pos="0 0 0.1"/>
      <body pos="0.01 -0.02 0.225" euler="0 0 45"><freejoint/>
        <geom type="box" size="0.4 0.03 0.02" mass="2"/></body>
    </worldbody></mujoco>""", 150, 2, 0.22)


def test_turned_stacks_of_random_cubes_stand():
    """Five cubes of random sizes and turns stacked on each other (each top face wider than the
    next cube's bottom diagonal would need, or not): the stack stands, nothing overlaps."""
    rng = np.random.default_rng(7)
    bodies, z = [], 0.0
    for k in range(5):
        half = rng.uniform(0.05, 0.1)
        z += half
        yaw = rng.uniform(0, 90)
        bodies.append(f'<body pos="{rng.uniform(-0.01, 0.01)} {rng.uniform(-0.01, 0.01)} '
                      f'{z + 0.002 * (k + 1)}" euler="0 0 {yaw}"><freejoint/>'
                      f'<geom type="box" size="{half} {half} {half}" mass="1"/></body>')
        z += half
    xml = ('<mujoco><option timestep="0.01"/><worldbody><geom type="plane" size="2 2 0.1"/>'
           + "".join(bodies) + "</worldbody></mujoco>")
    m = load(xml)
    traj = ukemi.rollout(m, m.make_state(), nsteps=200)
    assert traj.converged
    assert least_distance(m, traj) > -1e-8
    assert np.abs(traj.qvel[-1]).max() < 1e-5
    tops = traj.qpos[-1, 2::7]
    np.testing.assert_allclose(np.diff(tops), np.diff(traj.qpos[0, 2::7]) - 0.002, atol=1e-7)


def bridge_xml(block):
    """A capsule lying across two blocks (boxes or cube meshes) with a gap between them."""
    geom = {"box": '<geom type="box" size="0.1 0.1 0.1" pos="0 {y} 0.1"/>',
            "mesh": '<geom type="mesh" mesh="block" pos="0 {y} 0.1"/>'}[block]
    block_mesh = " ".join(f"{sx * 0.1} {sy * 0.1} {sz * 0.1}"
                          for sx in (1, -1) for sy in (1, -1) for sz in (1, -1))
    return f"""<mujoco><option timestep="0.01"/>
  <asset><mesh name="block" vertex="{block_mesh}"/></asset><worldbody>
  <geom type="plane" size="2 2 0.1"/>
  {geom.format(y=0.2)}
  {geom.format(y=-0.2)}
  <body pos="0.02 0 0.225" euler="90 0 0"><freejoint/>
    <geom type="capsule" size="0.02 0.35" mass="1"/></body>
</worldbody></mujoco>"""


@pytest.mark.parametrize("block", ["box", "mesh"])
def test_a_capsule_bridging_two_blocks_rests_on_their_edges(block):
    """A capsule lying across two boxes (or cube meshes) with a gap between them, its end
    spheres beyond their outer sides and its middle sphere over the gap: only the crossings of
    its segment with the blocks' top edges can hold it (with the three spheres alone it fell
    through), at the analytic height to 1e-8 m, still; MuJoCo rests it within 1 mm."""
    assert_rests(bridge_xml(block), 100, 2, 0.22)


@pytest.mark.parametrize(("dy", "turn"), [(0.15, 90.0), (0.1, 60.0)])
def test_a_capsule_dropped_across_a_ridge_never_sinks_into_it(dy, turn):
    """A capsule dropped across a ridge (a box turned 45° about x) where the ridge meets its
    segment between its spheres: it lands on the crossing, tips and slides off, with no
    overlap at any step and no energy gained (before, it sank 14 cm into the ridge)."""
    top = 0.3 + 0.1 * ROOT2
    xml = f"""<mujoco><option timestep="0.01"/><worldbody>
      <geom type="plane" size="2 2 0.1"/>
      <geom type="box" size="0.4 0.1 0.1" pos="0 0 0.3" euler="45 0 0"/>
      <body pos="0 {dy} {top + 0.03}" euler="{turn} 0 0"><freejoint/>
        <geom type="capsule" size="0.02 0.3" mass="1"/></body>
    </worldbody></mujoco>"""
    m = load(xml)
    traj = ukemi.rollout(m, m.make_state(), nsteps=200)
    assert traj.converged
    assert least_distance(m, traj) > -1e-8
    assert np.max(traj.energy - traj.energy[0]) < 1e-4 * max(1.0, abs(traj.energy[0]))


CUBE_MESH = " ".join(f"{sx * 0.1} {sy * 0.1} {sz * 0.1}"
                     for sx in (1, -1) for sy in (1, -1) for sz in (1, -1))


@pytest.mark.parametrize(("lower", "upper"), [("mesh", "mesh"), ("box", "mesh"), ("mesh", "box")])
def test_mesh_cubes_turned_on_each_other_rest_on_their_edge_crossings(lower, upper):
    """As two boxes: a cube mesh (its hull) turned 30° on a box or another cube mesh, or a box
    on a cube mesh, rests on the crossings of the hulls' edges at the analytic height (to
    1e-8 m), with no overlap at any step; MuJoCo rests it within 1 mm."""
    geom = {"mesh": '<geom type="mesh" mesh="cube" mass="1"/>',
            "box": '<geom type="box" size="0.1 0.1 0.1" mass="1"/>'}
    xml = f"""<mujoco><option timestep="0.01"/>
      <asset><mesh name="cube" vertex="{CUBE_MESH}"/></asset><worldbody>
      <geom type="plane" size="2 2 0.1"/>
      <body pos="0 0 0.1"><freejoint/>{geom[lower]}</body>
      <body pos="0 0 0.305" euler="0 0 30"><freejoint/>{geom[upper]}</body>
    </worldbody></mujoco>"""
    assert_rests(xml, 150, 9, 0.3)


def test_hulls_resting_edge_on_edge_do_not_sink_into_each_other():
    """Random hull pile 116 (``tests/stress``): two hulls of random points come to rest edge on
    edge at a sharp edge. Its crossing failed the crossing search's tests (the normal must point
    into each solid at its edge), so the hulls sank into each other (1.0, then 2.5 cm by the
    separating-axis test) with every candidate's distance ≥ 0, until a crossing 5.3 cm deep
    along another edge pair pushed them apart: 13 J → 36 J in one step. The crossing along which
    the two overlap least is now kept, and crossed ones much deeper than the overlap are not."""
    from stress._overlap import deepest_overlap
    from stress._random_scenes import hull_pile_with_solids

    m, _, solids = hull_pile_with_solids(116)
    tr = ukemi.rollout(m, m.make_state(), nsteps=60)
    least, state = deepest_overlap(tr, solids)
    assert least > -1e-8, (least, state)
    assert tr.min_distance.min() > -1e-8
    assert np.max(tr.energy - tr.energy[0]) < 1e-4 * abs(tr.energy[0])


@pytest.mark.parametrize("seed", [196, 241])
def test_a_hull_edge_through_another_hull_with_both_ends_outside_is_held(seed):
    """Random hull piles 196 and 241 (``tests/stress``): an edge of one hull sank through another
    with both of its ends outside, so no vertex candidate measured it, and the pair's edge
    crossings did not hold it: the two overlapped by 4.7 and 3.0 cm by the separating-axis
    test with every candidate's distance ≥ 0. Each hull's edges are now candidates against the
    other hull (the edge's point nearest it, as box edges meet cylinders)."""
    from stress._overlap import deepest_overlap
    from stress._random_scenes import hull_pile_with_solids

    m, _, solids = hull_pile_with_solids(seed)
    tr = ukemi.rollout(m, m.make_state(), nsteps=80)
    least, state = deepest_overlap(tr, solids)
    assert least > -1e-7, (least, state)
    assert tr.min_distance.min() > -1e-7
    assert np.max(tr.energy - tr.energy[0]) < 1e-4 * abs(tr.energy[0])
