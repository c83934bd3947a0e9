"""Mesh geoms (MJCF `<asset><mesh>`): a mesh collides and weighs as the convex hull of its
vertices, as in MuJoCo; from inline `vertex` lists, STL and OBJ files."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import ukemi

BOX = [(sx * 0.1, sy * 0.15, sz * 0.05) for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)]
# an irregular convex "rock" (every point on its hull) and a point inside it (not a vertex)
ROCK = [(0, 0, 0.12), (0.1, 0, -0.03), (-0.05, 0.09, -0.03), (-0.05, -0.08, -0.04),
        (0.02, 0.01, 0.05), (0.06, 0.05, 0.02), (0.0, 0.0, 0.0)]


def flat(points):
    return " ".join(f"{x:.17g}" for p in points for x in p)


DROP = """<mujoco><option timestep="0.002"/>
  <asset><mesh name="box" vertex="{box}"/><mesh name="rock" vertex="{rock}" scale="1 1.2 1"/>
  </asset>
  <worldbody><geom type="plane" size="5 5 0.1"/>
    <body name="b" pos="0 0 0.5"><freejoint/>
      <geom type="mesh" mesh="box" pos="0.01 0.02 0" euler="10 20 30"/></body>
    <body name="r" pos="0.5 0 0.5" euler="30 40 10"><freejoint/><geom type="mesh" mesh="rock"/>
    </body>
  </worldbody></mujoco>"""


def load(xml):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ukemi.Model.from_xml_string(xml)


def test_mesh_mass_properties_and_resting_poses_match_mujoco():
    """Mass and principal inertia of a box mesh (placed with an offset and a turn) and of an
    irregular scaled mesh equal MuJoCo's (its vertices are float32: 1e-6); dropped on the floor
    both come to rest on the face MuJoCo rests them on, at MuJoCo's height less its soft
    contact's penetration (within 0.5 mm), converged at every step."""
    mujoco = pytest.importorskip("mujoco")
    xml = DROP.format(box=flat(BOX), rock=flat(ROCK))
    mj, m = mujoco.MjModel.from_xml_string(xml), load(xml)
    np.testing.assert_allclose(m.body_mass, mj.body_mass, rtol=1e-6)
    for b in (1, 2):
        ours = np.linalg.eigvalsh(np.array(m.body_inertia)[b])
        np.testing.assert_allclose(ours, np.sort(mj.body_inertia[b]), rtol=1e-6)
    # the box: 6 kg, m/12 (b² + c²) ... about its axes
    np.testing.assert_allclose(np.linalg.eigvalsh(np.array(m.body_inertia)[1]),
                               [0.025, 0.05, 0.065], rtol=1e-12)
    s, d = m.make_state(), mujoco.MjData(mj)
    for _ in range(500):
        s, info = ukemi.step(m, s, np.zeros(0))
        assert info.converged, info.status
        mujoco.mj_step(mj, d)
    assert np.abs(s.qvel).max() < 1e-6
    q, mq = np.array(s.qpos), d.qpos
    for k in (0, 7):  # each body: resting height and orientation (up to sign)
        assert 0 < q[k + 2] - mq[k + 2] < 5e-4, (q[k + 2], mq[k + 2])
        assert abs(abs(q[k + 3:k + 7] @ mq[k + 3:k + 7]) - 1) < 1e-3


def test_a_mesh_box_steps_as_the_box_primitive():
    """A mesh of a box's eight corners is that box: its candidates against the floor are the
    corners, so a tumbling drop follows the primitive box's to round-off (the candidates come
    in another order), and so does the contact with a sphere resting on it."""
    def scene(geom):
        return f"""<mujoco><option timestep="0.01"/><asset><mesh name="m" vertex="{flat(BOX)}"/>
          </asset><worldbody><geom type="plane" size="5 5 0.1"/>
          <body pos="0 0 0.3" euler="20 35 5"><freejoint/>{geom}</body>
          <body pos="0.02 0.01 0.55"><freejoint/><geom type="sphere" size="0.04"/></body>
          </worldbody></mujoco>"""
    mesh = load(scene('<geom type="mesh" mesh="m" density="800"/>'))
    prim = load(scene('<geom type="box" size="0.1 0.15 0.05" density="800"/>'))
    np.testing.assert_allclose(mesh.body_mass, prim.body_mass, rtol=1e-14)
    a, b = mesh.make_state(), prim.make_state()
    for _ in range(150):
        a, ia = ukemi.step(mesh, a, np.zeros(0))
        b, ib = ukemi.step(prim, b, np.zeros(0))
        assert ia.converged and ib.converged
    np.testing.assert_allclose(a.qpos, b.qpos, atol=1e-7)
    assert b.qpos[2] < 0.1 and b.qpos[9] < 0.25  # the box landed, the sphere on it


def test_mesh_on_mesh_rests_without_sinking():
    """A small mesh box (half the size) dropped flat onto a mesh box resting on the floor
    settles at the sum of the heights (0.1 + 0.025 m) to the solver's tolerance and stays
    there. (Its corners land on the lower box's top face: an edge crossing an edge is not a
    contact, as for two box primitives.)"""
    xml = f"""<mujoco><option timestep="0.01"/><asset><mesh name="m" vertex="{flat(BOX)}"/>
      <mesh name="small" vertex="{flat(BOX)}" scale="0.5 0.5 0.5"/>
      </asset><worldbody><geom type="plane" size="5 5 0.1"/>
      <body pos="0 0 0.05"><freejoint/><geom type="mesh" mesh="m"/></body>
      <body pos="0.01 0.02 0.2"><freejoint/><geom type="mesh" mesh="small"/></body>
      </worldbody></mujoco>"""
    m = load(xml)
    s = m.make_state()
    for _ in range(200):
        s, info = ukemi.step(m, s, np.zeros(0))
        assert info.converged, info.status
    np.testing.assert_allclose([s.qpos[2], s.qpos[9]], [0.05, 0.125], atol=1e-7)
    assert np.abs(s.qvel).max() < 1e-7


def ascii_stl(points, triangles):
    lines = ["solid rock"]
    for t in triangles:
        lines += ["facet normal 0 0 0", "outer loop"]
        lines += [f"vertex {points[i][0]} {points[i][1]} {points[i][2]}" for i in t]
        lines += ["endloop", "endfacet"]
    return "\n".join(lines + ["endsolid rock"]) + "\n"


def test_stl_and_obj_files_load_as_the_inline_mesh(tmp_path):
    """Mesh files under `compiler/@meshdir` (relative to the model file): an ASCII STL and an
    OBJ of the rock give the mass and inertia of the inline `vertex` mesh; an unnamed mesh is
    named after its file; `strippath` keeps the file's name alone; a missing file and an
    unknown mesh name are errors naming them."""
    tris = [(0, 1, 2), (0, 2, 3), (0, 3, 1), (1, 3, 2), (4, 5, 0), (5, 1, 0)]
    (tmp_path / "assets").mkdir()
    (tmp_path / "assets" / "rock.stl").write_text(ascii_stl(ROCK, tris))
    obj = "".join(f"v {x} {y} {z}\n" for x, y, z in ROCK)
    obj += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in tris)
    (tmp_path / "assets" / "rock.obj").write_text(obj)
    body = """<body pos="{x} 0 1"><freejoint/><geom type="mesh" mesh="{mesh}"/></body>"""
    xml = f"""<mujoco><compiler meshdir="assets"/><asset>
      <mesh file="rock.stl"/><mesh name="obj" file="rock.obj"/>
      <mesh name="inline" vertex="{flat(ROCK)}"/></asset><worldbody>
      {body.format(x=0, mesh="rock")}{body.format(x=1, mesh="obj")}
      {body.format(x=2, mesh="inline")}</worldbody></mujoco>"""
    (tmp_path / "model.xml").write_text(xml)
    m = ukemi.Model.from_xml_path(str(tmp_path / "model.xml"))
    # (the files are read as float32, as MuJoCo reads them)
    np.testing.assert_allclose(m.body_mass[1:], m.body_mass[3], rtol=1e-6)
    inertia = np.array(m.body_inertia)
    for b in (1, 2):
        np.testing.assert_allclose(inertia[b], inertia[3], rtol=1e-5, atol=1e-11)
    # compiler/@strippath: the file's name alone, under meshdir
    stripped = xml.replace('<compiler meshdir="assets"/>',
                           '<compiler meshdir="assets" strippath="true"/>')
    stripped = stripped.replace('file="rock.stl"', 'file="/elsewhere/meshes/rock.stl"')
    s = ukemi.Model.from_xml_path(_write(tmp_path, stripped))
    np.testing.assert_array_equal(s.body_mass, m.body_mass)
    missing = xml.replace('<mesh file="rock.stl"/>', '<mesh name="rock" file="missing.stl"/>')
    with pytest.raises(ukemi.MjcfError, match=r"missing\.stl"):
        ukemi.Model.from_xml_path(_write(tmp_path, missing))
    with pytest.raises(ukemi.MjcfError, match=r"mesh.*\"nope\".*unknown mesh"):
        ukemi.Model.from_xml_path(_write(tmp_path, xml.replace('mesh="obj"', 'mesh="nope"')))


def _write(tmp_path, xml):
    path = tmp_path / "other.xml"
    path.write_text(xml)
    return str(path)


def test_a_flat_mesh_is_rejected_with_its_name():
    xml = """<mujoco><asset><mesh name="sheet" vertex="0 0 0 1 0 0 0 1 0 1 1 0"/></asset>
      <worldbody><body><freejoint/><geom type="mesh" mesh="sheet"/></body></worldbody></mujoco>"""
    with pytest.raises(ukemi.MjcfError, match=r"sheet"):
        ukemi.Model.from_xml_string(xml)


def test_visual_meshes_are_not_read():
    """A visual mesh (no collision) on a body with an `<inertial>` sets nothing: its file is
    never opened, so a model whose display meshes are absent still loads; the same mesh
    colliding is read (and its absence named)."""
    xml = """<mujoco><asset><mesh file="absent.stl"/></asset><worldbody><body>
      <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/><freejoint/>
      <geom type="mesh" mesh="absent" contype="0" conaffinity="0"/><geom size="0.1"/></body>
      </worldbody></mujoco>"""
    m = ukemi.Model.from_xml_string(xml)
    assert m.body_mass[1] == 1.0
    with pytest.raises(ukemi.MjcfError, match=r"absent\.stl"):
        ukemi.Model.from_xml_string(xml.replace(' contype="0" conaffinity="0"', ""))


def test_builder_mesh_geoms_are_convex_hulls():
    """`ModelBuilder.add_geom(shape="mesh", vertices=...)`: a rock dropped on the floor comes
    to rest on a face of its hull, its lowest vertex on the floor (not below it: 1e-8), the
    interior point not a contact; a flat or missing vertex list, or vertices on another shape,
    is a ValueError naming the geom."""
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("floor", body="world", shape="plane")
    b.add_body("rock", mass=0.99, inertia=(2e-3, 1.7e-3, 2e-3), pos=(0, 0, 0.3))
    b.add_joint("free", kind="floating", parent="world", child="rock")
    b.add_geom("rock", body="rock", shape="mesh", vertices=np.array(ROCK))
    m = b.compile()
    s = m.make_state()
    for _ in range(100):
        s, info = ukemi.step(m, s, np.zeros(0))
        assert info.converged
    # at rest on its lowest face: some hull vertex touches the floor, none is below it
    rot = np.array(s.body_quat[1])
    w, x, y, z = rot
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    heights = (np.array(s.body_pos[1]) + np.array(ROCK) @ R.T)[:, 2]
    assert -1e-8 < heights.min() < 1e-6 and np.abs(s.qvel).max() < 1e-6, heights.min()
    for kwargs, match in [(dict(shape="mesh"), "vertices"),
                          (dict(shape="mesh", vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0],
                                                        [1, 1, 0]]), "rock2"),
                          (dict(shape="sphere", size=(0.1,), vertices=ROCK), "vertices")]:
        b2 = ukemi.ModelBuilder()
        b2.add_body("rock", mass=1.0, inertia=(1, 1, 1))
        with pytest.raises(ValueError, match=match):
            b2.add_geom("rock2", body="rock", **kwargs)


def test_msh_file_of_mujocos_testdata_weighs_as_in_mujoco():
    """MuJoCo's binary MSH format, on the 4374-vertex mesh MuJoCo ships in its tests: with
    `inertia="convex"` (the hull, which ukemi uses) mass, principal inertia and the centre of
    mass equal MuJoCo's to 1e-9 relative."""
    mujoco = pytest.importorskip("mujoco")
    from pathlib import Path
    data = Path(mujoco.__file__).parent / "testdata"
    if not (data / "abdomen_1_body.msh").exists():
        pytest.skip("mujoco's testdata has no abdomen_1_body.msh")
    xml = f"""<mujoco><compiler meshdir="{data}"/><asset>
      <mesh name="a" file="abdomen_1_body.msh" inertia="convex"/></asset><worldbody>
      <body pos="0 0 0.5"><freejoint/><geom type="mesh" mesh="a"/></body></worldbody></mujoco>"""
    mj, m = mujoco.MjModel.from_xml_string(xml), load(xml)
    np.testing.assert_allclose(m.body_mass, mj.body_mass, rtol=1e-9)
    np.testing.assert_allclose(np.linalg.eigvalsh(np.array(m.body_inertia)[1]),
                               np.sort(mj.body_inertia[1]), rtol=1e-9)
    np.testing.assert_allclose(np.array(m.body_com)[1], mj.body_ipos[1], atol=1e-9)
