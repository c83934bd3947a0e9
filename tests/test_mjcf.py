"""MJCF loader: the same file loaded by ukemi and by MuJoCo gives the same model (sizes, masses,
inertias, kinematics at qpos0, keyframes and random configurations, limits, actuators); a
contact-free trajectory converges to MuJoCo's as the time step shrinks; malformed or unsupported
files raise ukemi errors that name the element and line, never anything else."""

from __future__ import annotations

import random
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import ukemi
from conftest import beside_mujoco

mujoco = pytest.importorskip("mujoco")
pytest.importorskip("gymnasium")

GYM = ["hopper", "half_cheetah", "ant", "walker2d", "humanoid", "inverted_pendulum",
       "inverted_double_pendulum", "reacher", "swimmer", "pusher"]
SHARED = Path(__file__).resolve().parents[2] / "shared" / "models"
# shared models that use features ukemi does not support: the error must say which
SHARED_UNSUPPORTED: dict[str, str] = {}
TOL = 1e-9


def load(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ukemi.Model.from_xml_path(str(path))


def mj_body(mj, name):
    """MuJoCo body id of a ukemi body; unnamed MJCF bodies are ``body<id>`` in ukemi."""
    try:
        return mj.body(name).id
    except KeyError:
        return int(re.fullmatch(r"body(\d+)", name).group(1))


def quat_close(a, b, tol):
    return min(np.abs(a - b).max(), np.abs(a + b).max()) < tol


def compare_kinematics(uk, mj, qpos, label):
    """Body frames of ukemi's state at `qpos` against mujoco.mj_kinematics."""
    d = mujoco.MjData(mj)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(mj, d)
    state = uk.make_state(qpos=qpos)
    for i, name in enumerate(uk.body_names[1:], start=1):
        b = mj_body(mj, name)
        np.testing.assert_allclose(state.body_pos[i], d.xpos[b], atol=TOL,
                                   err_msg=f"{label}: body_pos[{name}]")
        assert quat_close(state.body_quat[i], d.xquat[b], 1e-9), (
            f"{label}: body_quat[{name}] {state.body_quat[i]} vs {d.xquat[b]}")
    return state


def random_qpos(mj, rng):
    q = mj.qpos0.copy()
    for j in range(mj.njnt):
        a = mj.jnt_qposadr[j]
        t = mj.jnt_type[j]
        if t == mujoco.mjtJoint.mjJNT_FREE:
            q[a:a + 3] += rng.normal(size=3) * 0.3
            v = rng.normal(size=4)
            q[a + 3:a + 7] = v / np.linalg.norm(v)
        elif t == mujoco.mjtJoint.mjJNT_BALL:
            v = rng.normal(size=4)
            q[a:a + 4] = v / np.linalg.norm(v)
        else:
            lo, hi = mj.jnt_range[j] if mj.jnt_limited[j] else (-1.0, 1.0)
            q[a] = rng.uniform(lo, hi)
    return q


def check_against_mujoco(path):
    uk = load(path)
    mj = mujoco.MjModel.from_xml_path(str(path))
    assert (uk.nq, uk.nv, uk.nu) == (mj.nq, mj.nv, mj.nu)
    np.testing.assert_allclose(uk.qpos0, mj.qpos0, atol=TOL, err_msg="qpos0")
    # masses and inertias, compared as full tensors in the body frame
    for i, name in enumerate(uk.body_names[1:], start=1):
        b = mj_body(mj, name)
        np.testing.assert_allclose(uk.body_mass[i], mj.body_mass[b], rtol=TOL,
                                   err_msg=f"body_mass[{name}]")
        r = np.zeros(9)
        mujoco.mju_quat2Mat(r, mj.body_iquat[b])
        r = r.reshape(3, 3)
        full = r @ np.diag(mj.body_inertia[b]) @ r.T
        scale = np.abs(full).max()
        np.testing.assert_allclose(uk.body_inertia[i], full, atol=TOL * scale,
                                   err_msg=f"body_inertia[{name}]")
        np.testing.assert_allclose(uk.body_com[i], mj.body_ipos[b], atol=TOL,
                                   err_msg=f"body_com[{name}]")
    # joint limits per dof, actuators
    lim = np.full((mj.nv, 2), [-np.inf, np.inf])
    for j in range(mj.njnt):
        if mj.jnt_limited[j]:
            lim[mj.jnt_dofadr[j]] = mj.jnt_range[j]
    np.testing.assert_allclose(uk.dof_range, lim, atol=TOL, err_msg="dof_range")
    np.testing.assert_allclose(uk.actuator_gear, mj.actuator_gear[:, 0], rtol=TOL)
    ctrl = np.where(mj.actuator_ctrllimited[:, None] > 0, mj.actuator_ctrlrange,
                    [-np.inf, np.inf])
    np.testing.assert_allclose(uk.actuator_ctrlrange, ctrl, atol=TOL)
    # kinematics at qpos0, keyframes and random configurations
    compare_kinematics(uk, mj, mj.qpos0, "qpos0")
    assert uk.keyframe_names == [mj.key(k).name for k in range(mj.nkey)]
    for k in range(mj.nkey):
        state = uk.make_state(key=mj.key(k).name)
        np.testing.assert_allclose(state.qpos, mj.key_qpos[k], atol=1e-9)
        compare_kinematics(uk, mj, mj.key_qpos[k], f"key {mj.key(k).name}")
    rng = np.random.default_rng(0)
    for trial in range(5):
        q = random_qpos(mj, rng)
        state = compare_kinematics(uk, mj, q, f"random qpos {trial}")
        # hinge/slide coordinates come back exactly (quaternions up to sign)
        for j in range(mj.njnt):
            a = mj.jnt_qposadr[j]
            if mj.jnt_type[j] in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
                assert abs(state.qpos[a] - q[a]) < 1e-8, f"qpos[{a}] ({mj.joint(j).name})"
    return uk, mj


@pytest.mark.parametrize("name", GYM)
def test_gymnasium_asset_matches_mujoco(name):
    check_against_mujoco(ukemi.gymnasium_asset_path(name))


@pytest.mark.parametrize("name", ["a1", "humanoid", "panda", "x2"])
def test_shared_model(name):
    path = SHARED / f"{name}.xml"
    if not path.exists():
        pytest.skip(f"{path} is absent (shared models live beside the repository)")
    if name in SHARED_UNSUPPORTED:
        with pytest.raises(ukemi.UnsupportedError, match=re.escape(SHARED_UNSUPPORTED[name])):
            load(path)
        return
    check_against_mujoco(path)


def test_warnings_name_ignored_features():
    with pytest.warns(UserWarning, match=r"viscosity.*no fluid forces"):
        ukemi.Model.from_xml_path(str(ukemi.gymnasium_asset_path("swimmer")))


def test_single_joint_equality_holds_joint_and_flags_ignored_polycoef():
    """equality/joint without joint2 holds joint1 at qpos0 + polycoef[0] (MuJoCo's semantics);
    explicit higher coefficients are ignored there, and the loader says so (line named)."""
    xml = """<mujoco><worldbody><body pos="0 0 1">
      <joint name="h" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.05"/></body></worldbody>
      <equality><joint joint1="h" polycoef="0.3 2 0 0 0"/></equality></mujoco>"""
    with pytest.warns(UserWarning, match=r"<string>:4:.*only polycoef\[0\] is used"):
        m = ukemi.Model.from_xml_string(xml)
    tr = ukemi.rollout(m, m.make_state(qpos=[0.3]), nsteps=50)
    np.testing.assert_allclose(tr.qpos[:, 0], 0.3, atol=1e-9)
    quiet = xml.replace(' polycoef="0.3 2 0 0 0"', ' polycoef="0.3"')
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ukemi.Model.from_xml_string(quiet)


def test_load_dispatches_on_suffix(tmp_path):
    m = ukemi.load(ukemi.gymnasium_asset_path("inverted_pendulum"))
    assert m.nq == 2
    urdf = tmp_path / "r.urdf"
    urdf.write_text("<robot/>")
    with pytest.raises(ukemi.UrdfError, match="no <link>"):
        ukemi.load(urdf)
    with pytest.raises(ukemi.UnsupportedError, match="suffix"):
        ukemi.load(tmp_path / "r.sdf")
    with pytest.raises(ukemi.MjcfError, match="cannot read"):
        ukemi.load(tmp_path / "missing.xml")


PENDULUM = """
<mujoco>
  <option timestep="{h}" integrator="{integrator}"/>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="shoulder_x" type="hinge" axis="2 1 1"/>
      <joint name="shoulder_y" type="hinge" axis="0 -1 1"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 -0.4" size="0.05"/>
      <body name="lower" pos="0.3 0 -0.4">
        <joint name="elbow" type="hinge" axis="0 1 0" ref="20" damping="0.05" armature="0.01"/>
        <geom type="box" size="0.05 0.04 0.2" pos="0 0 -0.2" euler="10 20 30"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor joint="elbow" gear="2"/>
    <position joint="shoulder_y" kp="3" kv="0.2"/>
  </actuator>
</mujoco>
"""


def _mj_rollout(xml, q0, ctrl, seconds):
    m = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(m)
    d.qpos[:] = q0
    d.ctrl[:] = ctrl
    for _ in range(round(seconds / m.opt.timestep)):
        mujoco.mj_step(m, d)
    return d.qpos.copy()


def test_trajectory_converges_to_mujoco_as_dt_shrinks():
    """Non-orthogonal composite shoulder + elbow with ref, damping, armature, a motor and a
    position servo, no contact: |qpos_ukemi(1 s) - qpos_truth(1 s)| shrinks with dt, where the
    truth is MuJoCo RK4 at dt = 1e-4."""
    q0 = [0.3, -0.4, np.deg2rad(20) + 0.5]
    ctrl = [0.2, 0.1]
    truth = _mj_rollout(PENDULUM.format(h=1e-4, integrator="RK4"), q0, ctrl, 1.0)
    rows = []
    for h in (0.01, 0.005, 0.0025):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = ukemi.Model.from_xml_string(PENDULUM.format(h=h, integrator="Euler"))
        state = m.make_state(qpos=q0)
        traj = ukemi.rollout(m, state, ctrls=np.tile(ctrl, (round(1.0 / h), 1)))
        err = np.abs(traj.qpos[-1] - truth).max()
        mj_err = np.abs(_mj_rollout(PENDULUM.format(h=h, integrator="Euler"), q0, ctrl, 1.0)
                        - truth).max()
        rows.append((h, err, mj_err))
    print("\n   dt      |ukemi - truth|   |mujoco Euler - truth|   (truth: MuJoCo RK4, dt=1e-4)")
    for h, e, me in rows:
        print(f"  {h:<8} {e:14.3e}   {me:14.3e}")
    assert rows[0][1] < 0.05
    # error shrinks with dt (the servo and joint forces are explicit: at least first order)
    assert rows[1][1] < 0.6 * rows[0][1] and rows[2][1] < 0.6 * rows[1][1]


def test_inverted_pendulum_free_swing_matches_mujoco():
    path = ukemi.gymnasium_asset_path("inverted_pendulum")
    xml = path.read_text()
    q0 = [0.1, 0.4]
    truth = _mj_rollout(xml.replace('integrator="RK4" timestep="0.02"',
                                    'integrator="RK4" timestep="0.0001"'), q0, [0.3], 0.5)
    errs = []
    for h in (0.004, 0.002):
        m = load(path).with_options(timestep=h)
        traj = ukemi.rollout(m, m.make_state(qpos=q0), ctrls=np.tile([0.3], (round(0.5 / h), 1)))
        errs.append(np.abs(traj.qpos[-1] - truth).max())
    print(f"\ninverted_pendulum 0.5 s: |ukemi - MuJoCo RK4| = {errs[0]:.3e} (dt 0.004), "
          f"{errs[1]:.3e} (dt 0.002)")
    assert errs[0] < 2e-2 and errs[1] < 0.6 * errs[0]


# --- malformed and unsupported input ---------------------------------------------------------

BAD = [
    ("<mujoco><worldbody><body><geom size='abc'/></body></worldbody></mujoco>", "geom", 1),
    ("<mujoco>\n<worldbody>\n<body>\n<joint type='hinje'/>\n</body></worldbody></mujoco>", "joint", 4),
    ("<mujoco><worldbody/><actuator><motor joint='nope'/></actuator></mujoco>", "motor", 1),
    ("<mujoco><worldbody><body><geom size='0.1'/><joint range='1 0'/></body></worldbody></mujoco>",
     "joint", 1),
    ("<robot/>", "robot", 1),
    ("<mujoco><worldbody><body>", "malformed", 1),
    ("<mujoco>\n\n<worldbody><body><joint/></body></worldbody></mujoco>", "mass", 3),
]


@pytest.mark.parametrize("xml,what,line", BAD)
def test_bad_xml_raises_mjcf_error_with_element_and_line(xml, what, line):
    with pytest.raises(ukemi.MjcfError) as e:
        ukemi.Model.from_xml_string(xml)
    msg = str(e.value)
    assert what in msg and f":{line}:" in msg, msg


UNSUPPORTED = [
    "<mujoco><asset><mesh name='m' vertex='0 0 0 1 0 0 0 1 0 0 0 1' inertia='shell'/></asset>"
    "<worldbody><body><joint/><geom type='mesh' mesh='m' mass='0'/><geom size='.1'/></body>"
    "</worldbody></mujoco>",
    "<mujoco><worldbody><body><joint/><geom type='hfield' size='1 1 1' mass='0'/>"
    "<geom size='.1'/></body></worldbody></mujoco>",
    "<mujoco><worldbody><body><joint type='hinge'/><joint type='slide'/><geom size='.1'/></body>"
    "</worldbody></mujoco>",
    "<mujoco><worldbody><body><freejoint/><geom size='.1'/><site name='s'/><site name='r'/></body>"
    "</worldbody><actuator><motor site='s' refsite='r'/></actuator></mujoco>",
]


@pytest.mark.parametrize("xml", UNSUPPORTED)
def test_unsupported_features_are_explicit(xml):
    with pytest.raises(ukemi.UnsupportedError, match=r"MJCF <string>:\d+: <\w+"):
        ukemi.Model.from_xml_string(xml)


def test_visual_mesh_is_skipped():
    xml = ("<mujoco><asset><mesh name='m' vertex='0 0 0 1 0 0 0 1 0 0 0 1'/></asset><worldbody>"
           "<body><joint/><geom type='mesh' mesh='m' contype='0' conaffinity='0' density='0'/>"
           "<geom size='.1'/></body></worldbody></mujoco>")
    m = ukemi.Model.from_xml_string(xml)
    assert m.ngeom == 1


def test_fuzzed_gymnasium_files_raise_only_ukemi_errors():
    rng = random.Random(1234)
    texts = [ukemi.gymnasium_asset_path(n).read_text() for n in GYM]
    garbage = ["abc", "nan", "inf", "-1", "", "1e400", "0", "1 2", "-5 5 5 5 5 5 5 5", "true"]
    outcomes = {"loaded": 0, "error": 0}
    for case in range(200):
        text = rng.choice(texts)
        attrs = list(re.finditer(r'(\w+)="([^"]*)"', text))
        kind = rng.randrange(3)
        if kind == 0 and attrs:
            m = rng.choice(attrs)
            text = text[:m.start()] + text[m.end():]
        elif kind == 1 and attrs:
            m = rng.choice(attrs)
            text = text[:m.start(2)] + rng.choice(garbage) + text[m.end(2):]
        else:
            text = text[:rng.randrange(len(text))]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                model = ukemi.Model.from_xml_string(text)
            model.make_state()
            outcomes["loaded"] += 1
        except ukemi.UkemiError as e:
            assert not isinstance(e, ukemi.InternalError), f"case {case}: {e}"
            outcomes["error"] += 1
    assert outcomes["loaded"] > 0 and outcomes["error"] > 0, outcomes


# --- shared robot models against MuJoCo, contact out of the picture ---------------------------

def contact_free_xml(path, h, integrator=None):
    """The file as a string with every geom's contype/conaffinity 0 (MuJoCo and ukemi then have
    no contacts), no fluid forces and time step `h`; MuJoCo's default Euler integrator, or
    `integrator` (e.g. "implicitfast")."""
    import xml.etree.ElementTree as ET
    root = ET.parse(path).getroot()
    for g in root.iter("geom"):
        g.set("contype", "0")
        g.set("conaffinity", "0")
    opt = root.find("option")
    if opt is None:
        opt = ET.SubElement(root, "option")
    for a in ("density", "viscosity", "integrator"):
        opt.attrib.pop(a, None)
    if integrator is not None:
        opt.set("integrator", integrator)
    opt.set("timestep", str(h))
    return ET.tostring(root, encoding="unicode")


def shared_path(name):
    path = SHARED / f"{name}.xml"
    if not path.exists():
        pytest.skip(f"{path} is absent (shared models live beside the repository)")
    return path


def rollout_both(xml, q0, v0, ctrls):
    """qpos/qvel of ukemi and MuJoCo (mj_step) from the same state and controls."""
    mj = mujoco.MjModel.from_xml_string(xml)
    d = mujoco.MjData(mj)
    uk = ukemi.Model.from_xml_string(xml)
    d.qpos[:], d.qvel[:] = q0, v0
    traj = ukemi.rollout(uk, uk.make_state(qpos=q0, qvel=v0), ctrls=ctrls)
    mq, mv = [], []
    for u in ctrls:
        d.ctrl[:] = u
        mujoco.mj_step(mj, d)
        mq.append(d.qpos.copy())
        mv.append(d.qvel.copy())
    return mj, traj, np.array(mq), np.array(mv)


def trajectory_errors(name, h, dofs=None, seconds=0.05):
    """Max over the run of |q_ukemi ⊖ q_mujoco| (mj_differentiatePos) and |v_ukemi - v_mujoco|,
    from the first keyframe (or qpos0) with random velocities and random controls in ctrlrange."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # the Panda's position servos: their velocity gains are implicit in ukemi, as in
        # MuJoCo's `implicitfast` (which its MJCF asks for); Euler takes them explicitly
        xml = contact_free_xml(shared_path(name), h,
                               "implicitfast" if name == "panda" else None)
        mj = mujoco.MjModel.from_xml_string(xml)
        rng = np.random.default_rng(0)
        q0 = (mj.key_qpos[0] if mj.nkey else mj.qpos0).copy()
        if name == "panda":
            q0[7:9] = 0.02   # fingers off their limits (MuJoCo's limits are soft)
        v0 = rng.uniform(-0.2, 0.2, mj.nv)
        lo = np.where(mj.actuator_ctrllimited, mj.actuator_ctrlrange[:, 0], -1.0)
        hi = np.where(mj.actuator_ctrllimited, mj.actuator_ctrlrange[:, 1], 1.0)
        n = round(seconds / h)
        ctrls = rng.uniform(lo, hi, (n, mj.nu))
        mj, traj, mq, mv = rollout_both(xml, q0, v0, ctrls)
    dq = np.zeros((n, mj.nv))
    for k in range(n):
        mujoco.mj_differentiatePos(mj, dq[k], 1.0, mq[k], traj.qpos[k + 1])
    dv = traj.qvel[1:] - mv
    sel = slice(None) if dofs is None else dofs
    return np.abs(dq[:, sel]).max(), np.abs(dv[:, sel]).max(), traj


@pytest.mark.parametrize("name, qtol", [("humanoid", 5e-3), ("panda", 5e-5), ("x2", 5e-6)])
def test_shared_model_trajectory_converges_to_mujoco(name, qtol):
    """50 ms of random controls, no contact, at dt 1e-3 and 5e-4. The integrators differ
    (variational vs MuJoCo's semi-implicit Euler), both first order, so the gap must be small
    (qtol, measured with margin: humanoid 3.0e-3, panda arm 7.5e-6, x2 1.1e-6 rad or m at 1e-3)
    and shrink with dt. Panda: against MuJoCo's `implicitfast` (its servos' velocity gains
    implicit in both; against Euler the gap was 3.3e-3, the first-order difference between
    implicit and explicit damping), arm joints only; its fingers follow MuJoCo's *soft* equality
    (solref 5 ms, violations ~1e-4 that do not shrink with dt) while ukemi's is hard, so the
    fingers are compared through their mean, which the coupling leaves alone."""
    dofs = slice(0, 7) if name == "panda" else None
    eq1, ev1, t1 = trajectory_errors(name, 1e-3, dofs)
    eq2, ev2, _ = trajectory_errors(name, 5e-4, dofs)
    print(f"\n{name}: |dq| {eq1:.3e} (dt 1e-3) {eq2:.3e} (dt 5e-4); "
          f"|dv| {ev1:.3e} {ev2:.3e}")
    assert eq1 < qtol, f"{name}: qpos gap {eq1:.3e} at dt 1e-3"
    assert eq2 < 0.7 * eq1, f"{name}: qpos gap does not shrink with dt ({eq1:.3e} -> {eq2:.3e})"
    if name == "panda":
        # its servos saturate at forcerange (±87, ±12 N·m): the clamp is non-smooth, so the step
        # at which a joint's force leaves the clamp differs between the integrators and single
        # joints' velocity gaps (joints 2 and 6, ~9e-4 rad/s) do not shrink over 50 ms
        assert ev1 < 2e-3 and ev2 < 2e-3, f"panda: qvel gap {ev1:.3e}, {ev2:.3e}"
    else:
        assert ev2 < 0.7 * ev1, f"{name}: qvel gap does not shrink with dt ({ev1:.3e} -> {ev2:.3e})"


def test_panda_finger_coupling_stays_satisfied():
    """equality/joint finger_joint1 = finger_joint2 is a hard constraint in ukemi: ≤ 1e-9 over
    the random-control run, and the fingers' mean follows MuJoCo's."""
    _, _, traj = trajectory_errors("panda", 1e-3)
    assert np.abs(traj.qpos[:, 7] - traj.qpos[:, 8]).max() < 1e-9


def test_x2_thrust_lifts_with_the_analytic_acceleration():
    """Equal thrust u on the four rotors (yaw torques ±0.0201 u cancel): the drone rises with
    a = 4u/m - g from rest, level, no contact."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = ukemi.Model.from_xml_string(contact_free_xml(shared_path("x2"), 0.01))
    mass = m.body_mass[1:].sum()
    u = 5.0
    state = m.make_state(key="hover")
    traj = ukemi.rollout(m, state, ctrls=np.full((50, 4), u))
    t = 50 * 0.01
    a = 4 * u / mass - 9.81
    np.testing.assert_allclose(traj.qvel[-1, 2], a * t, rtol=1e-9)
    np.testing.assert_allclose(traj.qvel[-1, 3:], 0.0, atol=1e-9)


OFFSET_HINGES = """
<mujoco><option timestep="{h}"/>
<worldbody><body name="foot" pos="0 0 1" euler="10 20 5">
  <joint name="ay" axis="0 1 0" pos="0 0 .08" damping="0.1"/>
  <joint name="ax" axis="1 0 .5" pos="0.02 0 .04" stiffness="2"/>
  {third}
  <geom type="capsule" fromto="-.07 -.01 0 .14 -.03 0" size=".027"/>
  <geom type="box" size=".05 .03 .02" pos=".1 .02 -.03"/>
</body></worldbody>
<actuator><motor joint="ay" gear="2"/><motor joint="ax"/></actuator></mujoco>"""


@pytest.mark.parametrize("third", ["", '<joint name="az" axis="0 0 1" pos="-.05 .03 .01"/>'])
def test_offset_hinges_in_one_body_match_mujoco(third):
    """Two (three) hinges of one body about different anchors: same kinematics as
    mj_kinematics at random configurations (1e-12), and the trajectory gap to MuJoCo shrinks
    with dt."""
    gaps = []
    for h in (1e-3, 5e-4):
        xml = OFFSET_HINGES.format(h=h, third=third)
        mj = mujoco.MjModel.from_xml_string(xml)
        uk = ukemi.Model.from_xml_string(xml)
        rng = np.random.default_rng(1)
        for _ in range(3):
            compare_kinematics(uk, mj, rng.uniform(-1.5, 1.5, mj.nq), "offset hinges")
        rng = np.random.default_rng(0)
        q0, v0 = rng.uniform(-0.5, 0.5, mj.nq), rng.uniform(-1, 1, mj.nv)
        ctrls = rng.uniform(-1, 1, (round(0.05 / h), mj.nu))
        _, traj, mq, _ = rollout_both(xml, q0, v0, ctrls)
        gaps.append(np.abs(traj.qpos[1:] - mq).max())
    print(f"\noffset hinges{' x3' if third else ''}: |dq| {gaps[0]:.3e} (1e-3), {gaps[1]:.3e} (5e-4)")
    assert gaps[0] < 2e-3 and gaps[1] < 0.7 * gaps[0]


def test_forcerange_clamps_the_actuator_force():
    """A motor with forcerange ±2 on a 1 kg slide (no gravity): ctrl 10 accelerates at 2 m/s²,
    ctrl 1 at 1 m/s² (inside the clamp)."""
    xml = ("<mujoco><option gravity='0 0 0' timestep='0.01'/><worldbody><body>"
           "<joint name='x' type='slide' axis='1 0 0'/>"
           "<inertial pos='0 0 0' mass='1' diaginertia='1 1 1'/></body></worldbody>"
           "<actuator><motor joint='x' forcerange='-2 2'/></actuator></mujoco>")
    m = ukemi.Model.from_xml_string(xml)
    for u, a in ((10.0, 2.0), (1.0, 1.0), (-7.0, -2.0)):
        traj = ukemi.rollout(m, m.make_state(), ctrls=np.full((10, 1), u))
        np.testing.assert_allclose(traj.qvel[-1, 0], a * 0.1, rtol=1e-12)


DAMPRATIO_ARM = """<mujoco><option timestep="0.01"/><worldbody>
  <body name="a"><joint name="j" type="hinge" axis="0 1 0" armature="0.05"/>
    <geom type="capsule" fromto="0 0 0 0.4 0 0" size="0.03" mass="2"/>
    <body name="b" pos="0.4 0 0"><joint name="k" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.03" mass="1"/></body></body></worldbody>
  <tendon><fixed name="t"><joint joint="j" coef="0.5"/><joint joint="k" coef="1.5"/></fixed></tendon>
  <actuator><position joint="j" kp="100" gear="2" dampratio="1"/>
    <position joint="k" kp="50" dampratio="0.5"/>
    <general joint="k" gainprm="30" biastype="affine" biasprm="0 -30 0.7"/>
    {tendon}</actuator></mujoco>"""


def test_dampratio_servos_follow_mujoco():
    """`dampratio` (MuJoCo's damping ratio of a position servo, turned into its velocity gain
    by the inertia its transmission reflects at qpos0; also a `general` servo's positive
    `biasprm[2]`): a two-link arm on three such joint servos follows MuJoCo's `implicitfast`
    on the same MJCF for 3 s (measured 1.0e-4 rad at most; with the damping ratios left out,
    0.57 rad), and with a fourth on a fixed tendon over both joints, 5.5e-5 rad (6.9e-3 when
    the tendon servo's velocity gain was explicit)."""
    def worst_gap(tendon):
        xml = DAMPRATIO_ARM.format(tendon=tendon)
        model = ukemi.Model.from_xml_string(xml)
        mj = mujoco.MjModel.from_xml_string(xml)
        mj.opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        u = np.array([0.5, -0.4, 0.2, 0.1][:model.nu])
        s, d, worst = beside_mujoco(model, model.make_state(), mj, [u] * 300)
        assert np.abs(s.qpos - d.qpos).max() < 1e-6
        return worst

    assert worst_gap("") < 1e-3
    assert worst_gap('<position tendon="t" kp="20" dampratio="0.3"/>') < 1e-3
    with pytest.raises(ukemi.MjcfError, match="kv and dampratio"):
        ukemi.Model.from_xml_string(
            DAMPRATIO_ARM.format(tendon="").replace('dampratio="1"', 'dampratio="1" kv="2"'))


def test_inherited_control_ranges_match_mujoco():
    """`<position inheritrange>`: ukemi's control ranges are MuJoCo's on the same MJCF (the
    joint's or tendon's range about its centre, scaled; degrees converted)."""
    xml = """<mujoco><worldbody><body name="a"><joint name="j" axis="0 1 0" range="-1 2" limited="true"/>
      <geom size="0.1" mass="1"/><body name="b"><joint name="s" type="slide" range="0 0.04"/>
      <geom size="0.1" mass="1"/></body></body></worldbody>
      <tendon><fixed name="t" range="0 0.3" limited="true"><joint joint="j" coef="0.5"/></fixed></tendon>
      <actuator><position joint="j" kp="10" inheritrange="1"/><position joint="j" kp="10" inheritrange="0.5"/>
        <position joint="s" kp="10" inheritrange="2"/><position tendon="t" kp="10" inheritrange="1"/>
      </actuator></mujoco>"""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ours = np.array(ukemi.Model.from_xml_string(xml).actuator_ctrlrange)
    theirs = mujoco.MjModel.from_xml_string(xml).actuator_ctrlrange
    np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-15)


FRICTION_PENDULUM = """<mujoco><option timestep="{h}"/><worldbody><body pos="0 0 1">
  <joint name="j" type="hinge" axis="0 1 0" frictionloss="{f}" damping="0.5" armature="0.01"/>
  <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.05" contype="0" conaffinity="0"/>
  </body></worldbody><actuator><motor joint="j" ctrlrange="-3 3"/></actuator></mujoco>"""


def test_frictionloss_slides_as_mujoco_and_holds_where_mujoco_creeps():
    """Joint `frictionloss` is dry friction solved as a complementarity problem. A horizontal
    arm under gravity (torque 4.24 N·m at the hinge) and controls: where it slides, ukemi
    follows MuJoCo (whose friction force is exactly the frictionloss while sliding) to 1e-5
    rad (measured 1.2e-6 over 0.5 s). Held by friction 4.5 N·m, ukemi's arm moves by the
    interior point's complementarity alone, at most `kappa_tol / (f dt - |τ|)` a step
    (measured 2.8e-6 rad in 1 s), where MuJoCo's soft friction lets it creep 4.0e-2 rad (its
    default `solreffriction` time constant, 0.02 s, does not shrink with dt)."""
    h = 1e-3
    rng = np.random.default_rng(0)
    ctrls = np.repeat(rng.uniform(-3, 3, (5, 1)), 100, axis=0)
    xml = FRICTION_PENDULUM.format(h=h, f=0.2)
    mj, traj, mq, _ = rollout_both(xml, [0.0], [0.1], ctrls)
    gap = np.abs(traj.qpos[1:, 0] - mq[:, 0]).max()
    print(f"\nsliding: |q_ukemi - q_mujoco| {gap:.2e} rad over 0.5 s")
    assert gap < 1e-5, gap
    held = FRICTION_PENDULUM.format(h=h, f=4.5)
    mj, traj, mq, _ = rollout_both(held, [0.0], [0.0], np.zeros((1000, 1)))
    ours, theirs = np.abs(traj.qpos[-1, 0]), np.abs(mq[-1, 0])
    print(f"held for 1 s: ukemi moved {ours:.1e} rad, MuJoCo {theirs:.1e} rad")
    assert ours < 1e-5 and theirs > 1000 * ours, (ours, theirs)


def test_a1_joint_friction_is_mujocos_hardest_friction():
    """The A1's joints carry frictionloss 0.2. Against MuJoCo's default soft friction the
    contact-free trajectory gap is ~2.6e-3 rad and does not shrink with dt (MuJoCo's friction
    regularisation has a fixed time constant); against MuJoCo's friction made as hard as it
    allows (`solreffriction` = 2 dt, impedance 0.99-0.999) it does shrink: ukemi's exact dry
    friction is its limit. (Measured at dt 1e-3, 5e-4, 2.5e-4: 2.7e-4, 1.9e-4, 6.4e-5 rad.)"""
    orig = contact_free_xml

    def hardest(path, h, integrator=None):
        return orig(path, h, integrator).replace(
            'frictionloss="0.2"',
            f'frictionloss="0.2" solreffriction="{2 * h} 1" solimpfriction="0.99 0.999 0.001"')

    gaps = []
    try:
        globals()["contact_free_xml"] = hardest
        for h in (1e-3, 2.5e-4):
            gaps.append(trajectory_errors("a1", h)[0])
    finally:
        globals()["contact_free_xml"] = orig
    print(f"\na1 against MuJoCo's hardest friction: |dq| {gaps[0]:.2e} (dt 1e-3), "
          f"{gaps[1]:.2e} (dt 2.5e-4)")
    assert gaps[0] < 1e-3 and gaps[1] < 0.5 * gaps[0], gaps


PAIR_SCENE = """<mujoco><option timestep="0.005"/>
  <default><pair friction="0.3 0.3 0.005 0.0001 0.0001"/></default>
  <worldbody><geom name="floor" type="plane" size="5 5 0.1" friction="1" {floor}/>
    <body name="box" pos="0 0 0.1"><freejoint/>
      <geom name="box" type="box" size="0.1 0.1 0.1" mass="1" friction="1"/></body></worldbody>
  <contact>{contact}</contact></mujoco>"""


@pytest.mark.parametrize("floor, contact", [
    ("", '<pair geom1="floor" geom2="box"/>'),
    ('contype="0" conaffinity="0"', '<pair geom1="box" geom2="floor" friction="0.3"/>'),
    ("", '<exclude body1="world" body2="box"/><pair geom1="floor" geom2="box"/>'),
])
def test_contact_pairs_are_mujocos(floor, contact):
    """`<contact><pair>`: the two geoms collide whatever their bit masks and exclusions, with
    the pair's friction (its class's `<pair>` default, 0.3) in place of the geoms' (1). A box
    pushed at 2 m/s slides to rest after v²/(2 μ g) = 0.68 m, as in MuJoCo (whose soft contact
    sinks ~1 mm and stops it a little sooner)."""
    xml = PAIR_SCENE.format(floor=floor, contact=contact)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a pair's friction="0.3" alone is isotropic here
        uk = ukemi.Model.from_xml_string(xml)
    assert uk.ncontact > 0
    mj = mujoco.MjModel.from_xml_string(xml)
    qvel = [2.0, 0, 0, 0, 0, 0]
    tr = ukemi.rollout(uk, uk.make_state(qvel=qvel), nsteps=200)
    assert tr.converged
    d = mujoco.MjData(mj)
    d.qvel[:] = qvel
    for _ in range(200):
        mujoco.mj_step(mj, d)
    ours, theirs = tr.qpos[-1, 0], d.qpos[0]
    print(f"\nslid {ours:.4f} m (analytic {4 / (2 * 0.3 * 9.81):.4f}), MuJoCo {theirs:.4f} m")
    assert abs(ours - 4 / (2 * 0.3 * 9.81)) < 0.01 and abs(ours - theirs) < 0.02
    assert abs(tr.qpos[-1, 2] - 0.1) < 1e-9  # resting on the floor, not through it


def test_contact_pair_errors_and_warnings_name_the_line():
    xml = PAIR_SCENE.format(floor="", contact='<pair geom1="floor" geom2="nothing"/>')
    with pytest.raises(ukemi.MjcfError, match=r":6:.*geom2.*unknown geom"):
        ukemi.Model.from_xml_string(xml)
    frictionless = PAIR_SCENE.format(floor="", contact='<pair geom1="floor" geom2="box" condim="1"/>')
    uk = ukemi.Model.from_xml_string(frictionless)
    tr = ukemi.rollout(uk, uk.make_state(qvel=[2.0, 0, 0, 0, 0, 0]), nsteps=100)
    np.testing.assert_allclose(tr.qvel[-1, 0], 2.0, atol=1e-9)  # condim 1: no friction
    aniso = PAIR_SCENE.format(floor="", contact='<pair geom1="floor" geom2="box" friction="0.2 0.5"/>')
    with pytest.warns(UserWarning, match=r":6:.*anisotropic friction 0.2 / 0.5"):
        ukemi.Model.from_xml_string(aniso)


WHEEL = """<mujoco><option timestep="{h}"/><worldbody><body pos="0 0 1">
  <joint name="axle" type="hinge" axis="0 1 0" stiffness="{k}" springref="{ref}"/>
  <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.05" contype="0" conaffinity="0"/>
  </body></worldbody></mujoco>"""


@pytest.mark.parametrize("k, ref, v0", [(0.0, 0.0, 15.0), (20.0, 520.0, 0.0)])
def test_unlimited_hinges_wind_on_as_mujocos(k, ref, v0):
    """An unlimited hinge's qpos winds on past ±π as MuJoCo's does: a pendulum flung over the
    top turns over and over (qpos past 4π), and a torsion spring wound to 9.08 rad (springref
    520°) swings through its turns about it. ukemi's qpos follows MuJoCo's on the same MJCF to
    the integrators' difference, which shrinks with dt (2 s; spring: 0.25, 0.063 rad at dt
    1e-3, 5e-4). Before session 40 the angle wrapped to (-π, π] and the spring pulled towards
    9.08 - 2π."""
    gaps = []
    for h in (1e-3, 5e-4):
        xml = WHEEL.format(h=h, k=k, ref=ref)
        mj, traj, mq, _ = rollout_both(xml, [0.0], [v0], np.zeros((round(2.0 / h), 0)))
        gaps.append(np.abs(traj.qpos[1:, 0] - mq[:, 0]).max())
        assert np.abs(traj.qpos[:, 0]).max() > 4 * np.pi
    print(f"\nk {k} springref {ref}: qpos {traj.qpos[-1, 0]:.4f} (MuJoCo {mq[-1, 0]:.4f}), "
          f"range {traj.qpos[:, 0].min():.3f}..{traj.qpos[:, 0].max():.3f}, gaps {gaps}")
    assert gaps[0] < 0.5 and gaps[1] < 0.5 * gaps[0], gaps
    # the state's qpos goes back in as it came out, turns included
    uk = ukemi.Model.from_xml_string(xml)
    np.testing.assert_allclose(uk.make_state(qpos=traj.qpos[-1]).qpos, traj.qpos[-1], atol=1e-12)


TENDON_SPRING = """<mujoco><option timestep="{h}" integrator="implicitfast"/><worldbody>
  <body name="a" pos="0 0 1"><joint name="j1" type="hinge" axis="0 1 0" ref="10"/>
    <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.04" contype="0" conaffinity="0"/>
    <body name="b" pos="0.3 0 0"><joint name="j2" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.04" contype="0" conaffinity="0"/>
    </body></body></worldbody>
  <tendon><fixed name="t" stiffness="30" damping="{d}" {springlength}>
    <joint joint="j1" coef="1"/><joint joint="j2" coef="-0.5"/></fixed></tendon></mujoco>"""


@pytest.mark.parametrize("springlength, d", [("", 0.5), ('springlength="0.4"', 2.0)])
def test_passive_tendons_follow_mujoco(springlength, d):
    """A fixed tendon's `stiffness`, `damping` and `springlength`: a spring on L = q1 - q2/2
    (rest length MuJoCo's default, L at the joints' springref, 0 here though j1's ref is 10°;
    or 0.4) and an implicit damper on its rate, on a double pendulum under gravity. ukemi
    follows MuJoCo's `implicitfast` on the same MJCF, and the gap shrinks with dt (1 s)."""
    q0, gaps = [0.5, -0.3], []
    for h in (1e-3, 5e-4):
        xml = TENDON_SPRING.format(h=h, d=d, springlength=springlength)
        mj, traj, mq, _ = rollout_both(xml, q0, [0.0, 0.0], np.zeros((round(1.0 / h), 0)))
        gaps.append(np.abs(traj.qpos[1:] - mq).max())
    uk = ukemi.Model.from_xml_string(xml)
    free = ukemi.Model.from_xml_string(re.sub(r'stiffness="30" damping="[0-9.]+"', "", xml))
    apart = np.abs(ukemi.rollout(free, free.make_state(qpos=q0), nsteps=2000).qpos[-1]
                   - traj.qpos[-1]).max()
    print(f"\n{springlength or 'default springlength'} d {d}: gaps {gaps}, "
          f"without the tendon {apart:.2f} rad away")
    assert gaps[0] < 5e-3 and gaps[1] < 0.7 * gaps[0] and apart > 0.1, (gaps, apart)
    assert dict(uk.variable_counts)["joint_impulse"] == dict(free.variable_counts)["joint_impulse"]


def test_tendon_spring_dead_bands_are_unsupported():
    xml = TENDON_SPRING.format(h=1e-3, d=0.5, springlength='springlength="0.1 0.3"')
    with pytest.raises(ukemi.UnsupportedError, match="dead band"):
        ukemi.Model.from_xml_string(xml)


def test_tendon_frictionloss_follows_mujoco():
    """A fixed tendon's `frictionloss` (dry friction on L = q1 - q2/2, 0.4 N·m) on the double
    pendulum: sliding, ukemi follows MuJoCo on the same MJCF and the gap shrinks with dt;
    without it the pendulum ends elsewhere. The impulse is reported."""
    q0, gaps = [0.5, -0.3], []
    for h in (1e-3, 5e-4):
        xml = TENDON_SPRING.format(h=h, d=0.0, springlength='frictionloss="0.4"').replace(
            'stiffness="30" ', "")
        mj, traj, mq, _ = rollout_both(xml, q0, [0.0, 0.0], np.zeros((round(0.5 / h), 0)))
        gaps.append(np.abs(traj.qpos[1:] - mq).max())
    uk = ukemi.Model.from_xml_string(xml)
    free = ukemi.Model.from_xml_string(xml.replace('frictionloss="0.4"', ""))
    apart = np.abs(ukemi.rollout(free, free.make_state(qpos=q0), nsteps=1000).qpos[-1]
                   - traj.qpos[-1]).max()
    print(f"\ntendon frictionloss: gaps {gaps}, without it {apart:.3f} rad away")
    assert gaps[0] < 5e-3 and gaps[1] < 0.7 * gaps[0] and apart > 0.01, (gaps, apart)
    assert dict(uk.variable_counts)["tendon_friction"] == 4
    state, _ = ukemi.step(uk, uk.make_state(qpos=q0, qvel=[2.0, 0.0]))
    # (within the interior point's room `kappa_tol / (dt L̇)` of its bound)
    np.testing.assert_allclose(state.tendon_friction_impulse, [0.4 * 5e-4], rtol=1e-4)


def test_include_splices_files_as_mujoco(tmp_path):
    """`<include file>`: a scene that includes a robot from a subdirectory, which includes its
    actuators (found beside it or beside the scene, as MuJoCo finds them), loads as MuJoCo loads
    it and steps as the same model written in one file does. Messages name the file and line
    an element came from; a model given as a string cannot include files."""
    (tmp_path / "robot").mkdir()
    (tmp_path / "robot" / "arm.xml").write_text("""<mujoco>
  <worldbody>
    <body name="arm" pos="0 0 1">
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom name="link" type="capsule" fromto="0 0 0 0.3 0 0" size="0.05"/>
    </body>
  </worldbody>
  <include file="motors.xml"/>
</mujoco>""")
    (tmp_path / "robot" / "motors.xml").write_text(
        '<mujoco><actuator><motor joint="hinge" gear="2"/></actuator></mujoco>')
    scene = tmp_path / "scene.xml"
    scene.write_text("""<mujoco>
  <option timestep="0.005"/>
  <include file="robot/arm.xml"/>
  <worldbody><geom name="floor" type="plane" size="5 5 .1"/></worldbody>
</mujoco>""")
    one_file = """<mujoco><option timestep="0.005"/><worldbody>
    <body name="arm" pos="0 0 1"><joint name="hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom name="link" type="capsule" fromto="0 0 0 0.3 0 0" size="0.05"/></body>
    <geom name="floor" type="plane" size="5 5 .1"/></worldbody>
  <actuator><motor joint="hinge" gear="2"/></actuator></mujoco>"""
    ours, flat = ukemi.load(scene), ukemi.Model.from_xml_string(one_file)
    mj = mujoco.MjModel.from_xml_path(str(scene))
    assert (ours.nq, ours.nu, ours.ncontact) == (mj.nq, mj.nu, flat.ncontact) == (1, 1, flat.ncontact)
    ctrls = np.full((200, 1), 0.3)
    a = ukemi.rollout(ours, ours.make_state(), ctrls=ctrls)
    b = ukemi.rollout(flat, flat.make_state(), ctrls=ctrls)
    np.testing.assert_array_equal(a.qpos, b.qpos)
    # a bad element in an included file is named there
    (tmp_path / "robot" / "motors.xml").write_text(
        '<mujoco>\n<actuator>\n<motor joint="elbow"/></actuator></mujoco>')
    with pytest.raises(ukemi.MjcfError, match=r"motors\.xml:3: .*elbow"):
        ukemi.load(scene)
    (tmp_path / "robot" / "motors.xml").unlink()
    with pytest.raises(ukemi.MjcfError, match=r"arm\.xml:8: <include>: cannot read"):
        ukemi.load(scene)
    with pytest.raises(ukemi.MjcfError, match="given as a string"):
        ukemi.Model.from_xml_string(scene.read_text())
    (tmp_path / "robot" / "motors.xml").write_text('<mujoco><include file="motors.xml"/></mujoco>')
    with pytest.raises(ukemi.MjcfError, match="nested deeper"):
        ukemi.load(scene)


def test_gravcomp_follows_mujoco():
    """A body's `gravcomp`: a double pendulum whose links cancel 0.6 and 1.0 of their weight
    swings as MuJoCo's on the same MJCF (gap 2.1e-3 -> 1.0e-3 as dt halves), and 3 rad from
    the one without; a free body with gravcomp 1 floats, also built with `gravcomp=`."""
    xml = """<mujoco><option timestep="{h}"/><worldbody>
      <body name="a" pos="0 0 1" gravcomp="0.6"><joint name="j1" type="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.04" contype="0" conaffinity="0"/>
        <body name="b" pos="0.3 0 0" gravcomp="1"><joint name="j2" type="hinge" axis="0 1 0"/>
          <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.04" contype="0" conaffinity="0"/>
        </body></body>
      <body name="float" pos="1 0 1" gravcomp="1"><freejoint/><geom size="0.1"/></body>
      </worldbody></mujoco>"""
    q0 = np.zeros(9)
    q0[[2, 4, 5]] = 1.0, 1.0, 1.0  # the ball at (1, 0, 1), unturned
    q0[0:2] = 0.4, -0.3
    gaps = []
    for h in (1e-3, 5e-4):
        mj, traj, mq, _ = rollout_both(xml.format(h=h), q0.copy(), np.zeros(8),
                                       np.zeros((round(1.0 / h), 0)))
        gaps.append(np.abs(traj.qpos[1:, :2] - mq[:, :2]).max())
        np.testing.assert_allclose(traj.qpos[:, 2:5], np.tile([1.0, 0, 1.0], (len(traj.qpos), 1)),
                                   atol=1e-12)  # the floating ball stays put
    uk = ukemi.Model.from_xml_string(xml.format(h=5e-4))
    plain = ukemi.Model.from_xml_string(re.sub(r' gravcomp="[0-9.]+"', "", xml.format(h=5e-4)))
    apart = np.abs(ukemi.rollout(plain, plain.make_state(qpos=q0), nsteps=2000).qpos[-1, :2]
                   - traj.qpos[-1, :2]).max()
    print(f"\ngravcomp: gaps {gaps}, without it {apart:.2f} rad away")
    assert gaps[0] < 5e-3 and gaps[1] < 0.7 * gaps[0] and apart > 0.1, (gaps, apart)
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_body("ball", mass=1.0, inertia=(0.004, 0.004, 0.004), pos=(0, 0, 1), gravcomp=1.0)
    b.add_joint("free", "free", "world", "ball")
    m = b.compile()
    tr = ukemi.rollout(m, m.make_state(), nsteps=50)
    np.testing.assert_allclose(tr.qpos[-1, :3], [0, 0, 1], atol=1e-12)
    with pytest.raises(ValueError, match="gravcomp"):
        b.add_body("bad", mass=1.0, inertia=(1, 1, 1), gravcomp=float("nan"))
        b.compile()


FORCE_LIMITED_ARM = """<mujoco><option timestep="{h}" integrator="{integrator}"/><worldbody>
  <body pos="0 0 1"><joint name="j" type="hinge" axis="0 1 0" damping="0.1" {limit}/>
  <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.05" contype="0" conaffinity="0"/>
  </body></worldbody><actuator>{actuators}</actuator></mujoco>"""


@pytest.mark.filterwarnings("ignore:.*integrator")
@pytest.mark.parametrize("servo", [False, True], ids=["motor", "position_servo"])
def test_joint_actuatorfrcrange_clamps_as_mujoco(servo):
    """A joint's `actuatorfrcrange` clamps the total actuator force on it (after the actuator's
    own `forcerange`). Driven by one motor (gear 2) or one position servo (kp 20, kv 2, its
    velocity gain implicit as in `implicitfast`), ukemi follows MuJoCo with the clamp to 1e-4
    rad over 0.5 s, while the same run without the clamp is 10x farther away."""
    h = 1e-3
    act = ('<position joint="j" kp="20" kv="2" ctrlrange="-2 2"/>' if servo
           else '<motor joint="j" gear="2" ctrlrange="-3 3"/>')
    limit = 'actuatorfrcrange="-1.2 1.5"'
    xml = FORCE_LIMITED_ARM.format(h=h, integrator="implicitfast", limit=limit, actuators=act)
    free = FORCE_LIMITED_ARM.format(h=h, integrator="implicitfast", limit="", actuators=act)
    rng = np.random.default_rng(2)
    ctrls = np.repeat(rng.uniform(-2, 2, (5, 1)), 100, axis=0)
    mj, traj, mq, _ = rollout_both(xml, [0.3], [0.0], ctrls)
    gap = np.abs(traj.qpos[1:, 0] - mq[:, 0]).max()
    # the clamp binds: MuJoCo's own actuator forces reach the range
    d = mujoco.MjData(mj)
    forces = []
    for u in ctrls:
        d.ctrl[:] = u
        mujoco.mj_step(mj, d)
        forces.append(d.qfrc_actuator[0])
    assert np.isclose(min(forces), -1.2) and np.isclose(max(forces), 1.5), (min(forces),
                                                                           max(forces))
    _, unclamped, _, _ = rollout_both(free, [0.3], [0.0], ctrls)
    off = np.abs(unclamped.qpos[1:, 0] - mq[:, 0]).max()
    print(f"\n{'servo' if servo else 'motor'}: clamped |q - q_mujoco| {gap:.1e} rad, "
          f"without the clamp {off:.1e}")
    assert gap < 1e-4 and off > 10 * gap, (gap, off)


@pytest.mark.filterwarnings("ignore:.*integrator")
def test_joint_actuatorfrcrange_with_two_actuators_is_named_as_ignored():
    """The clamp of a sum of actuator forces is not modelled: with two motors on one joint the
    range is ignored with a warning naming it and its line; the motors' own ranges still act.
    One motor's range loads quietly, and so does an unlimited range."""
    one = FORCE_LIMITED_ARM.format(h=0.01, integrator="Euler", limit='actuatorfrcrange="-1 1"',
                                   actuators='<motor joint="j"/>')
    unlimited = one.replace('"-1 1"', '"-1 1" actuatorfrclimited="false"')
    for xml in (one, unlimited):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            warnings.filterwarnings("ignore", message=".*integrator")
            m = ukemi.Model.from_xml_string(xml)
        # one motor at control 3: clamped to 1 N·m, or not
        v = ukemi.step(m, m.make_state(), [3.0])[0].qvel
        ref = ukemi.step(m, m.make_state(), [1.0 if xml is one else 3.0])[0].qvel
        np.testing.assert_array_equal(v, ref)
    xml = FORCE_LIMITED_ARM.format(
        h=0.01, integrator="Euler", limit='actuatorfrcrange="-1 1"',
        actuators='<motor joint="j"/><motor joint="j" forcerange="-0.5 0.5"/>')
    with pytest.warns(UserWarning, match=r"<string>:2: <joint>: `actuatorfrcrange` is ignored"):
        m = ukemi.Model.from_xml_string(xml)
    s = m.make_state()
    n, _ = ukemi.step(m, s, [0.0, 3.0])
    ref = ukemi.step(m, s, [0.0, 0.5])[0]
    np.testing.assert_array_equal(n.qvel, ref.qvel)
