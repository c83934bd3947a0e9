"""URDF loader: hand-written URDF robots against the same robots written as MJCF and compiled by
MuJoCo (masses, full inertias, COMs, body poses at several configurations, joint ranges, actuator
control ranges, to 1e-9), fixed-joint merging, floating/fixed bases, and malformed files raising
``UrdfError`` (or ``UnsupportedError``) that name the element and line."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import ukemi

DATA = Path(__file__).parent / "data"
TOL = 1e-9


def load_urdf(path_or_text, floating):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if isinstance(path_or_text, Path):
            return ukemi.Model.from_urdf_path(str(path_or_text), floating=floating)
        return ukemi.Model.from_urdf_string(path_or_text, floating=floating)


def quat_close(a, b, tol):
    return min(np.abs(a - b).max(), np.abs(a + b).max()) < tol


def compare(uk, mj):
    """ukemi's model of a URDF against MuJoCo's of the MJCF twin."""
    mujoco = pytest.importorskip("mujoco")
    assert (uk.nq, uk.nv, uk.nu) == (mj.nq, mj.nv, mj.nu)
    assert uk.nbody == mj.nbody, (uk.body_names, [mj.body(i).name for i in range(mj.nbody)])
    assert uk.ngeom == mj.ngeom
    np.testing.assert_allclose(uk.qpos0, mj.qpos0, atol=TOL)
    for i, name in enumerate(uk.body_names[1:], start=1):
        b = mj.body(name).id
        np.testing.assert_allclose(uk.body_mass[i], mj.body_mass[b], rtol=TOL,
                                   err_msg=f"body_mass[{name}]")
        r = np.zeros(9)
        mujoco.mju_quat2Mat(r, mj.body_iquat[b])
        r = r.reshape(3, 3)
        full = r @ np.diag(mj.body_inertia[b]) @ r.T
        np.testing.assert_allclose(uk.body_inertia[i], full, atol=TOL * np.abs(full).max(),
                                   err_msg=f"body_inertia[{name}]")
        np.testing.assert_allclose(uk.body_com[i], mj.body_ipos[b], atol=TOL,
                                   err_msg=f"body_com[{name}]")
    lim = np.full((mj.nv, 2), [-np.inf, np.inf])
    for j in range(mj.njnt):
        if mj.jnt_limited[j]:
            lim[mj.jnt_dofadr[j]] = mj.jnt_range[j]
    np.testing.assert_allclose(uk.dof_range, lim, atol=TOL, err_msg="dof_range")
    np.testing.assert_allclose(uk.actuator_gear, mj.actuator_gear[:, 0], rtol=TOL)
    ctrl = np.where(mj.actuator_ctrllimited[:, None] > 0, mj.actuator_ctrlrange,
                    [-np.inf, np.inf])
    np.testing.assert_allclose(uk.actuator_ctrlrange, ctrl, atol=TOL, err_msg="ctrlrange")
    rng = np.random.default_rng(0)
    d = mujoco.MjData(mj)
    for trial in range(6):
        q = mj.qpos0.copy()
        if trial:
            for j in range(mj.njnt):
                a = mj.jnt_qposadr[j]
                if mj.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
                    q[a:a + 3] += rng.normal(size=3) * 0.3
                    v = rng.normal(size=4)
                    q[a + 3:a + 7] = v / np.linalg.norm(v)
                else:
                    lo, hi = mj.jnt_range[j] if mj.jnt_limited[j] else (-2.0, 2.0)
                    q[a] = rng.uniform(lo, hi)
        d.qpos[:] = q
        mujoco.mj_kinematics(mj, d)
        state = uk.make_state(qpos=q)
        for i, name in enumerate(uk.body_names[1:], start=1):
            b = mj.body(name).id
            np.testing.assert_allclose(state.body_pos[i], d.xpos[b], atol=TOL,
                                       err_msg=f"config {trial}: body_pos[{name}]")
            assert quat_close(state.body_quat[i], d.xquat[b], TOL), f"config {trial}: {name}"


def test_arm_matches_mjcf_twin():
    mujoco = pytest.importorskip("mujoco")
    uk = load_urdf(DATA / "arm2.urdf", floating=False)
    assert uk.body_names == ["world", "upper", "fore"]  # tool merged into fore, base = world
    assert uk.joint_names == ["shoulder", "elbow"]
    assert uk.actuator_names == ["shoulder", "elbow"]
    mj = mujoco.MjModel.from_xml_path(str(DATA / "arm2.xml"))
    compare(uk, mj)


def test_load_dispatches_on_suffix():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = ukemi.load(DATA / "arm2.urdf", floating=False)
    assert m.nq == 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = ukemi.load(DATA / "arm2.urdf")  # floating by default: the base gets a free joint
    assert (m.nq, m.nv) == (9, 8)
    assert m.body_names[1] == "base"


# ---------------------------------------------------------------- a small quadruped, generated

LEGS = {"FR": (0.2, -0.1), "FL": (0.2, 0.1), "RR": (-0.2, -0.1), "RL": (-0.2, 0.1)}


def quadruped_urdf():
    legs = []
    for leg, (x, y) in LEGS.items():
        legs.append(f"""
  <link name="{leg}_hip">
    <inertial><origin xyz="0 {0.3 * y} 0" rpy="0.1 0 0.2"/><mass value="0.6"/>
      <inertia ixx="0.0005" iyy="0.0007" izz="0.0006" ixy="0.00001" ixz="0" iyz="0.00002"/></inertial>
  </link>
  <link name="{leg}_thigh">
    <inertial><origin xyz="0 0 -0.1"/><mass value="1.0"/>
      <inertia ixx="0.005" iyy="0.005" izz="0.0008"/></inertial>
    <collision><origin xyz="0 0 -0.1"/><geometry><capsule radius="0.02" length="0.16"/></geometry></collision>
  </link>
  <link name="{leg}_calf">
    <inertial><origin xyz="0 0 -0.1"/><mass value="0.2"/>
      <inertia ixx="0.001" iyy="0.001" izz="0.0001"/></inertial>
  </link>
  <link name="{leg}_foot">
    <inertial><mass value="0.05"/><inertia ixx="1e-5" iyy="1e-5" izz="1e-5"/></inertial>
    <collision><geometry><sphere radius="0.02"/></geometry></collision>
  </link>
  <joint name="{leg}_hip_joint" type="revolute">
    <parent link="trunk"/><child link="{leg}_hip"/><origin xyz="{x} {y} 0"/>
    <axis xyz="1 0 0"/><limit lower="-0.8" upper="0.8" effort="20" velocity="20"/>
  </joint>
  <joint name="{leg}_thigh_joint" type="revolute">
    <parent link="{leg}_hip"/><child link="{leg}_thigh"/><origin xyz="0 {0.8 * y} 0"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="3" effort="20" velocity="20"/>
    <dynamics damping="0.1" friction="0"/>
  </joint>
  <joint name="{leg}_calf_joint" type="revolute">
    <parent link="{leg}_thigh"/><child link="{leg}_calf"/><origin xyz="0 0 -0.2"/>
    <axis xyz="0 1 0"/><limit lower="-2.7" upper="-0.9" effort="30" velocity="20"/>
  </joint>
  <joint name="{leg}_foot_fixed" type="fixed">
    <parent link="{leg}_calf"/><child link="{leg}_foot"/><origin xyz="0 0 -0.2"/>
  </joint>""")
    return f"""<?xml version="1.0"?>
<robot name="quad">
  <link name="base"/>
  <joint name="floating_base" type="fixed"><parent link="base"/><child link="trunk"/></joint>
  <link name="trunk">
    <inertial><origin xyz="0.01 0 0"/><mass value="6"/>
      <inertia ixx="0.02" iyy="0.06" izz="0.07" ixy="0.0001" ixz="0.0002" iyz="0"/></inertial>
    <collision><geometry><box size="0.4 0.2 0.1"/></geometry></collision>
  </link>{''.join(legs)}
</robot>"""


def quadruped_mjcf(floating):
    legs = []
    for leg, (x, y) in LEGS.items():
        legs.append(f"""
      <body name="{leg}_hip" pos="{x} {y} 0">
        <joint name="{leg}_hip_joint" axis="1 0 0" range="-0.8 0.8"/>
        <inertial pos="0 {0.3 * y} 0" mass="0.6" fullinertia="{hip_inertia()}"/>
        <body name="{leg}_thigh" pos="0 {0.8 * y} 0">
          <joint name="{leg}_thigh_joint" axis="0 1 0" range="-1 3" damping="0.1"/>
          <inertial pos="0 0 -0.1" mass="1" diaginertia="0.005 0.005 0.0008"/>
          <geom type="capsule" size="0.02 0.08" pos="0 0 -0.1"/>
          <body name="{leg}_calf" pos="0 0 -0.2">
            <joint name="{leg}_calf_joint" axis="0 1 0" range="-2.7 -0.9"/>
            <inertial pos="0 0 -0.1" mass="0.2" diaginertia="0.001 0.001 0.0001"/>
            <body name="{leg}_foot" pos="0 0 -0.2">
              <inertial pos="0 0 0" mass="0.05" diaginertia="1e-5 1e-5 1e-5"/>
              <geom type="sphere" size="0.02"/>
            </body>
          </body>
        </body>
      </body>""")
    motors = "".join(
        f'<motor joint="{leg}_{j}_joint" ctrlrange="-{e} {e}"/>'
        for leg in LEGS for j, e in (("hip", 20), ("thigh", 20), ("calf", 30)))
    return f"""<mujoco model="quad">
  <compiler angle="radian" eulerseq="XYZ" inertiafromgeom="false" fusestatic="true"/>
  <worldbody>
    <body name="base">
      {'<freejoint/>' if floating else ''}
      <body name="trunk">
        <inertial pos="0.01 0 0" mass="6" fullinertia="0.02 0.06 0.07 0.0001 0.0002 0"/>
        <geom type="box" size="0.2 0.1 0.05"/>
      </body>{''.join(legs)}
    </body>
  </worldbody>
  <actuator>{motors}</actuator>
</mujoco>"""


def _rpy(r, p, y):
    cx, sx, cy, sy, cz, sz = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rz @ ry @ rx


def hip_inertia():
    """The hip's URDF inertia (rpy 0.1 0 0.2) in the link frame, R I Rᵀ, as MJCF fullinertia."""
    i = np.array([[0.0005, 0.00001, 0], [0.00001, 0.0007, 0.00002], [0, 0.00002, 0.0006]])
    r = _rpy(0.1, 0, 0.2)
    f = r @ i @ r.T
    return " ".join(repr(float(v)) for v in (f[0, 0], f[1, 1], f[2, 2], f[0, 1], f[0, 2], f[1, 2]))


@pytest.mark.parametrize("floating", [True, False])
def test_quadruped_matches_mjcf_twin(floating):
    mujoco = pytest.importorskip("mujoco")
    uk = load_urdf(quadruped_urdf(), floating=floating)
    mj = mujoco.MjModel.from_xml_string(quadruped_mjcf(floating))
    if floating:
        assert uk.body_names[1] == "base"  # trunk merged into the massless root
    compare(uk, mj)


def test_quadruped_stands_on_a_floor():
    """The floating quadruped dropped on a floor (added through the MJCF it translates to)."""
    mjcf = ukemi.Model.urdf_to_mjcf(quadruped_urdf(), floating=True)
    mjcf = mjcf.replace("<worldbody>", '<option timestep="0.01"/><worldbody>'
                        '<geom name="floor" type="plane" size="5 5 0.1"/>', 1)
    mjcf = mjcf.replace('<body name="base" pos="0 0 0"', '<body name="base" pos="0 0 0.5"', 1)
    model = ukemi.Model.from_xml_string(mjcf)
    q = model.qpos0.copy()
    q[7:] = np.tile([0.0, 0.8, -1.6], 4)
    traj = ukemi.rollout(model, model.make_state(qpos=q), nsteps=100, on_failure="return")
    assert np.isfinite(traj.qpos).all()


# ---------------------------------------------------------------- errors

ARM = (DATA / "arm2.urdf").read_text()


def line_of(text, needle):
    return text[: text.index(needle)].count("\n") + 1


@pytest.mark.parametrize(
    "old, new, needle, match",
    [
        ('type="continuous"', 'type="spinning"', '<joint name="elbow"', "spinning"),
        ('<mass value="2"/>', '<mass value="-2"/>', '<mass value="2"/>', "must be >= 0"),
        ('<child link="fore"/>', '<child link="nowhere"/>', '<joint name="elbow"', "nowhere"),
        ('<axis xyz="0 0.6 0.8"/>', '<axis xyz="0 0 0"/>', '<axis xyz="0 0.6 0.8"/>', "zero length"),
        ('<axis xyz="0 1 0"/>', '<axis xyz="0 1"/>', '<axis xyz="0 1 0"/>', "xyz"),
        ('lower="-1.5" upper="1.5"', 'lower="1.5" upper="-1.5"', 'lower="-1.5"', "lower"),
        ('<parent link="upper"/><child link="fore"/>', '<parent link="fore"/><child link="upper"/>',
         '<joint name="elbow"', "already has the parent joint"),
    ],
)
def test_malformed_urdf_names_element_and_line(old, new, needle, match):
    bad = ARM.replace(old, new, 1)
    assert bad != ARM
    with pytest.raises(ukemi.UrdfError, match=re.escape(match)) as e:
        load_urdf(bad, floating=False)
    assert isinstance(e.value, ValueError)
    assert f"<string>:{line_of(ARM, needle)}:" in str(e.value), str(e.value)


SWING = """<robot name="swing">
  <link name="base"><collision><origin xyz="0.35 0 -0.3"/><geometry><box size="0.4 0.4 0.1"/>
    </geometry></collision></link>
  <link name="arm"><inertial><origin xyz="0.2 0 0"/><mass value="1"/>
    <inertia ixx="0.001" iyy="0.01" izz="0.01"/></inertial></link>
  <link name="paddle"><inertial><mass value="0.5"/><inertia ixx="0.001" iyy="0.001" izz="0.001"/>
    </inertial><collision><origin xyz="0 0 -0.05" rpy="0.1 0.2 0.3"/>
    <geometry>{shape}</geometry></collision></link>
  <joint name="shoulder" type="continuous"><parent link="base"/><child link="arm"/>
    <axis xyz="0 1 0"/></joint>
  <joint name="wrist" type="revolute"><parent link="arm"/><child link="paddle"/>
    <origin xyz="0.35 0 0"/><axis xyz="0 1 0"/><limit lower="-0.001" upper="0.001" effort="1"/>
  </joint>
</robot>"""


def ascii_stl(points):
    """An ASCII STL of the given points' tetrahedra fan (the hull is what collides)."""
    tris = [(0, i, i + 1) for i in range(1, len(points) - 1)]
    body = "".join("facet normal 0 0 0\nouter loop\n"
                   + "".join(f"vertex {x} {y} {z}\n" for x, y, z in (points[k] for k in t))
                   + "endloop\nendfacet\n" for t in tris)
    return f"solid m\n{body}endsolid m\n"


def test_collision_mesh_from_a_package_steps_as_its_primitive(tmp_path):
    """A URDF collision mesh (`package://` resolved without ROS, beside the URDF's folder) is
    the convex hull of its vertices: a paddle whose mesh is a box's eight corners swings down
    onto a table as the same paddle with a `<box>` (to 1e-7 over 0.6 s), stopped by it (the
    paddle hangs on a stiff wrist: a link jointed to the base does not collide with it); a
    package that is nowhere names where it was looked for."""
    half = (0.05, 0.04, 0.02)
    corners = [(sx * half[0], sy * half[1], sz * half[2])
               for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)]
    pkg = tmp_path / "swing_description"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf").mkdir()
    (pkg / "meshes" / "paddle.stl").write_text(ascii_stl(corners))
    mesh = '<mesh filename="package://swing_description/meshes/paddle.stl" scale="2 2 2"/>'
    (pkg / "urdf" / "swing.urdf").write_text(SWING.format(shape=mesh))
    m = ukemi.Model.from_urdf_path(str(pkg / "urdf" / "swing.urdf"), floating=False)
    box = load_urdf(SWING.format(shape='<box size="0.2 0.16 0.08"/>'), floating=False)
    assert m.ngeom == box.ngeom == 2
    a, b = m.with_options(timestep=0.005), box.with_options(timestep=0.005)
    sa, sb = a.make_state(), b.make_state()
    for _ in range(120):
        sa, ia = ukemi.step(a, sa, [0.0, 0.0])
        sb, ib = ukemi.step(b, sb, [0.0, 0.0])
        assert ia.converged and ib.converged
    np.testing.assert_allclose(sa.qpos, sb.qpos, atol=1e-7)
    assert 0.3 < sb.qpos[0] < 1.0 and abs(sb.qvel[0]) < 1e-6  # resting on the table
    missing = SWING.format(shape=mesh.replace("swing_description", "nowhere_description"))
    with pytest.raises(ukemi.UrdfError, match=r'link "paddle".*nowhere_description.*tried'):
        load_urdf(missing, floating=False)


def test_massless_moving_link_is_an_error():
    bad = ARM.replace('<mass value="1"/>', '<mass value="0"/>').replace(
        '<mass value="0.3"/>', '<mass value="0"/>')
    with pytest.raises(ukemi.UrdfError, match=r'link "fore" moves .* no mass'):
        load_urdf(bad, floating=False)


def test_not_a_robot_and_broken_xml():
    with pytest.raises(ukemi.UrdfError, match=r"<string>:1: .*<robot>"):
        load_urdf("<mujoco/>", floating=True)
    with pytest.raises(ukemi.UrdfError, match="malformed XML"):
        load_urdf("<robot><link name='a'></robot>", floating=True)
    with pytest.raises(ukemi.UrdfError, match="cannot read"):
        ukemi.Model.from_urdf_path("/nonexistent/robot.urdf")


def test_mimic_joint_follows_its_leader():
    """`<mimic joint multiplier offset>` couples the elbow to the shoulder, q_elbow = -2
    q_shoulder + 0.1, as a hard joint equality: along a rollout under random shoulder torques
    the coupling holds to the solver's tolerance while both joints move; the mimic joint has
    no motor of its own; a leader that does not exist is named with the mimic's line."""
    mimic = '<mimic joint="shoulder" multiplier="-2" offset="0.1"/><limit effort="10"'
    coupled = ARM.replace('<limit effort="10"', mimic)
    assert coupled != ARM
    m = load_urdf(coupled, floating=False)
    free = load_urdf(ARM, floating=False)
    assert m.nu == free.nu - 1 and list(m.actuator_names) == ["shoulder"]
    s = m.make_state(qpos=[0.2, -0.3])
    rng = np.random.default_rng(0)
    qs = []
    for u in rng.uniform(-20, 20, (100, 1)):
        s, info = ukemi.step(m, s, u)
        assert info.converged
        qs.append(np.array(s.qpos))
    qs = np.array(qs)
    np.testing.assert_allclose(qs[:, 1], -2 * qs[:, 0] + 0.1, atol=1e-9)
    assert np.ptp(qs[:, 0]) > 0.1
    unknown = coupled.replace('<mimic joint="shoulder"', '<mimic joint="hip"')
    with pytest.raises(ukemi.UrdfError, match=rf"<string>:{line_of(coupled, '<mimic')}:.*hip"):
        load_urdf(unknown, floating=False)


def test_dynamics_friction_is_dry_joint_friction():
    """`<dynamics friction>` becomes the joint's frictionloss, as MuJoCo's URDF import maps it:
    the shoulder, tilted under gravity with the elbow swinging below it, holds still while its
    friction exceeds the torques on it, and falls without it."""
    rub = ARM.replace('<dynamics damping="0.1"/>', '<dynamics damping="0.1" friction="30"/>')
    assert rub != ARM
    with pytest.raises(ukemi.UrdfError, match="friction"):
        load_urdf(rub.replace('friction="30"', 'friction="-1"'), floating=False)
    held = load_urdf(rub, floating=False)
    assert dict(held.variable_counts)["joint_friction"] == 4
    free = load_urdf(ARM, floating=False)
    assert dict(free.variable_counts)["joint_friction"] == 0
    q0 = np.full(held.nq, 0.8)
    for m, moves in ((held, False), (free, True)):
        tr = ukemi.rollout(m, m.make_state(qpos=q0), nsteps=100)
        assert tr.converged
        assert np.abs(tr.qpos[-1, 1] - q0[1]) > 1e-2  # the elbow swings in both
        travel = np.abs(tr.qpos[:, 0] - q0[0]).max()
        assert (travel > 1e-2) if moves else (travel < 1e-8), travel
    state = held.make_state(qpos=q0)
    state, _ = ukemi.step(held, state)
    assert 0 < np.abs(state.joint_friction_impulse).max() < 30 * held.timestep


def test_every_collision_pair_has_a_kernel_and_mesh_errors_name_the_urdf_line():
    """The arm's cylinder base, capsule and box links all collide (until session 42 a cylinder
    met planes only, and its pairs were left out with a warning at the URDF line); a collision
    mesh that cannot be read is reported at its URDF line."""
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        ukemi.Model.from_urdf_string(ARM, floating=False)
    assert not [w for w in record if "never collide" in str(w.message)]
    base_collision = line_of(ARM, '<collision><origin xyz="0 0 0.05"/>')
    cylinder = '<cylinder radius="0.1" length="0.1"/>'
    missing = ARM.replace(cylinder, '<mesh filename="missing.stl"/>', 1)
    assert missing != ARM
    with pytest.raises(ukemi.UrdfError, match="missing.stl") as e:
        ukemi.Model.from_urdf_string(missing, floating=False)
    assert f"URDF <string>:{base_collision}:" in str(e.value), str(e.value)


def test_fuzzed_urdf_raises_only_ukemi_errors():
    rng = np.random.default_rng(1)
    tokens = ['"', "<", ">", "/", "0", "-1", "nan", "1e400", " ", "joint", "link", "x"]
    for _ in range(300):
        text = list(ARM)
        for _ in range(rng.integers(1, 4)):
            i = int(rng.integers(len(text)))
            op = rng.integers(3)
            if op == 0:
                del text[i]
            elif op == 1:
                text.insert(i, tokens[int(rng.integers(len(tokens)))])
            else:
                text[i] = tokens[int(rng.integers(len(tokens)))]
        try:
            load_urdf("".join(text), floating=bool(rng.integers(2)))
        except (ukemi.UrdfError, ukemi.UnsupportedError, ukemi.ModelError, ukemi.MjcfError):
            pass


def test_ros_conventions_a_world_root_and_axes_of_fixed_joints():
    """Two conventions of ROS robots (pybullet's Panda and xArm URDFs use them): a root link
    named `world` is the world frame, so the robot is fixed to it even when a floating base is
    asked for; a fixed joint's axis is ignored, zero or not (the URDF spec ignores it)."""
    fixed = load_urdf(ARM, floating=False)
    zero_axis = ARM.replace('<origin xyz="0.4 0 0" rpy="0.2 0.7 -0.4"/>',
                            '<origin xyz="0.4 0 0" rpy="0.2 0.7 -0.4"/><axis xyz="0 0 0"/>')
    assert zero_axis != ARM
    m = load_urdf(zero_axis, floating=False)
    np.testing.assert_array_equal(m.body_mass, fixed.body_mass)
    world = ARM.replace('<link name="base">', '<link name="world"/>\n  <link name="base">', 1)
    world = world.replace('<joint name="shoulder"', '<joint name="pin" type="fixed"><parent '
                          'link="world"/><child link="base"/></joint>\n  <joint name="shoulder"')
    m = load_urdf(world, floating=True)
    assert (m.nq, m.nv) == (fixed.nq, fixed.nv) == (2, 2)
    s = m.make_state(qpos=[0.3, -0.2])
    t = fixed.make_state(qpos=[0.3, -0.2])
    for _ in range(20):
        s, _ = ukemi.step(m, s, [1.0, -0.5])
        t, _ = ukemi.step(fixed, t, [1.0, -0.5])
    np.testing.assert_allclose(s.qpos, t.qpos, atol=1e-12)


def test_links_jointed_to_a_fixed_base_do_not_collide_with_it():
    """MuJoCo's pair rules let the world collide with its children; a fixed URDF base is the
    world, and its jointed child overlaps it at the joint (pybullet_data's KUKA iiwa sinks 1 cm
    into its base and jammed its first step): that pair is excluded, the grandchild still
    collides with the base."""
    urdf = """<robot name="r">
      <link name="base"><collision><geometry><box size="0.2 0.2 0.2"/></geometry></collision>
      </link>
      <link name="l1"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/>
        </inertial><collision><geometry><box size="0.1 0.1 0.3"/></geometry></collision></link>
      <link name="l2"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"/>
        </inertial><collision><origin xyz="0 0 0.2"/><geometry><sphere radius="0.05"/>
        </geometry></collision></link>
      <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
        <origin xyz="0 0 0.15"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="5"/></joint>
      <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
        <origin xyz="0 0 0.15"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="5"/></joint>
    </robot>"""
    m = load_urdf(urdf, floating=False)
    pairs = {tuple(sorted(p[:2])) for p in m.contact_pairs}
    assert ("base_collision0", "l1_collision0") not in pairs
    assert ("base_collision0", "l2_collision0") in pairs
    assert '<exclude body1="world" body2="l1"/>' in ukemi.Model.urdf_to_mjcf(urdf, floating=False)
