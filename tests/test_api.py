"""The Python API of the engine core: shapes, conventions, physics through the bindings."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import pendulum

import ukemi


def test_model_attributes(pend):
    assert (pend.nq, pend.nv, pend.nu, pend.nbody, pend.njoint) == (1, 1, 1, 2, 1)
    assert pend.body_names == ["world", "bob"]
    assert pend.joint_names == ["hinge"] and pend.actuator_names == ["motor"]
    assert pend.timestep == 0.01
    np.testing.assert_allclose(pend.body_mass, [0.0, 1.0])
    assert pend.body_inertia.shape == (2, 3, 3)
    assert set(ukemi.JOINT_KINDS) >= {"fixed", "revolute", "prismatic", "spherical", "floating"}
    assert len(ukemi.JOINT_KINDS) == 16


def test_state_arrays_and_reference_pose(pend):
    s = pend.make_state()
    assert s.time == 0.0
    np.testing.assert_allclose(s.qpos, [0.0])
    np.testing.assert_allclose(s.body_pos, [[0, 0, 0], [0, 0, -1]], atol=1e-15)
    np.testing.assert_allclose(s.body_quat[1], [1, 0, 0, 0])
    s = pend.make_state(qpos=[np.pi / 2], qvel=[2.0])
    # hinge about +y by +90°: the bob at -z swings to -x; velocity ω × r
    np.testing.assert_allclose(s.body_pos[1], [-1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(s.body_angvel[1], [0, 2, 0], atol=1e-12)
    np.testing.assert_allclose(s.body_linvel[1], np.cross([0, 2, 0], [-1, 0, 0]), atol=1e-12)
    np.testing.assert_allclose(s.qvel, [2.0], atol=1e-12)


def test_free_joint_uses_mujoco_layout(free_body):
    q = np.array([0.1, -0.2, 1.3, np.cos(0.4), 0, np.sin(0.4), 0])
    v = np.array([0.5, 0.0, -0.3, 0.1, 0.2, -0.7])
    s = free_body.make_state(qpos=q, qvel=v)
    np.testing.assert_allclose(s.qpos, q, atol=1e-14)
    np.testing.assert_allclose(s.qvel, v, atol=1e-14)
    np.testing.assert_allclose(s.body_pos[1], q[:3], atol=1e-15)
    np.testing.assert_allclose(s.body_quat[1], q[3:], atol=1e-15)
    np.testing.assert_allclose(s.body_linvel[1], v[:3], atol=1e-14)


def test_step_is_functional_and_free_fall_is_exact():
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_body("ball", mass=1.0, inertia=(0.1, 0.1, 0.1), pos=(0, 0, 1))
    b.add_joint("free", kind="free", parent="world", child="ball")
    model = b.compile()
    s0 = model.make_state()
    s, info = ukemi.step(model, s0)
    assert info.status == "converged" and info.converged and info.residual <= 1e-10
    assert s0.time == 0.0 and s0.qpos[2] == 1.0  # input unchanged
    traj = ukemi.rollout(model, s0, nsteps=100)
    # variational integrator: z_k = z0 - g h² k (k+1) / 2 exactly (midpoint velocities)
    k = np.arange(101)
    z = 1.0 - 9.81 * 0.01**2 * k * (k + 1) / 2
    np.testing.assert_allclose(traj.qpos[:, 2], z, atol=1e-12)
    np.testing.assert_allclose(traj.time, 0.01 * k, atol=1e-12)
    assert traj.qpos.shape == (101, 7) and traj.body_pos.shape == (101, 2, 3)
    assert traj.status.shape == (100,) and traj.converged


def test_actuator_torque_matches_angular_impulse():
    """From rest with gravity off, a torque τ = gear·clamp(u) gives θ after k steps as
    τ h² k(k+1)/2 / I for a point mass on a rod (I = m L²)."""
    b = ukemi.ModelBuilder(timestep=0.001, gravity=(0, 0, 0))
    b.add_body("bob", mass=2.0, inertia=(1e-6, 1e-6, 1e-6), pos=(0, 0, -0.5))
    b.add_joint("hinge", "revolute", "world", "bob", axis=(0, 1, 0), child_anchor=(0, 0, 0.5))
    b.add_actuator("m", joint="hinge", gear=3.0, ctrlrange=(-0.5, 0.5))
    model = b.compile()
    traj = ukemi.rollout(model, model.make_state(), ctrls=np.full((20, 1), 7.0))  # clamped to 0.5
    I = 2.0 * 0.25 + 1e-6
    k = 20
    expected = 1.5 * 0.001**2 * k * (k + 1) / 2 / I
    assert traj.qpos[-1, 0] == pytest.approx(expected, rel=1e-3)


def test_pendulum_period_through_python():
    model = pendulum(timestep=0.01, actuated=False)
    traj = ukemi.rollout(model, model.make_state(qpos=[0.01]), nsteps=1000)
    x, t = traj.qpos[:, 0], traj.time
    up = np.where((x[:-1] < 0) & (x[1:] >= 0))[0]
    tc = t[up] - x[up] * (t[up + 1] - t[up]) / (x[up + 1] - x[up])
    period = np.diff(tc).mean()
    assert period == pytest.approx(2 * np.pi * np.sqrt(1 / 9.81), rel=5e-3)


def test_damping_dissipates_and_energy_is_conserved_without_it():
    undamped = pendulum(actuated=False)
    damped = pendulum(damping=0.5, actuated=False)
    for model, expect_loss in ((undamped, False), (damped, True)):
        s0 = model.make_state(qpos=[1.0])
        traj = ukemi.rollout(model, s0, nsteps=1000)
        loss = s0.energy() - traj.final_state.energy()
        if expect_loss:
            assert loss > 1.0
        else:
            assert abs(loss) < 1e-3 * 9.81 * (1 - np.cos(1.0))  # 0.1% of the swing energy


def test_applied_forces_and_wrenches(free_body):
    s = free_body.make_state()
    f = np.zeros((2, 6))
    f[1, :3] = [2.0, 0.0, 0.0]  # 1 m/s² on a 2 kg body
    s1, _ = ukemi.step(free_body, s, xfrc_applied=f)
    np.testing.assert_allclose(s1.qvel[:3], [0.01, 0, 0], atol=1e-12)
    s2, _ = ukemi.step(free_body, s, qfrc_applied=[0, 0, 4.0, 0, 0, 0])
    np.testing.assert_allclose(s2.qvel[:3], [0, 0, 0.02], atol=1e-12)


def test_with_options_returns_new_model(pend):
    m2 = pend.with_options(timestep=0.002, rtol=1e-12)
    assert m2.timestep == 0.002 and pend.timestep == 0.01
    s, _ = ukemi.step(m2, m2.make_state(qpos=[0.2]))
    assert s.time == pytest.approx(0.002)


def test_iteration_counts_reject_negative_values_by_name(pend):
    # a negative count is a named ValueError (not pyo3's OverflowError); the model is unchanged
    for name in ("max_iter", "endgame_iter", "acceptable_iter", "stall_iter", "max_ls",
                 "max_subdivisions"):
        with pytest.raises(ValueError, match=name):
            pend.with_options(**{name: -1})
        assert pend.options[name] > 0
    assert pend.with_options(endgame_iter=0).options["endgame_iter"] == 0
    assert pend.with_options(stall_iter=0).options["stall_iter"] == 0


def test_switch_options_must_be_bools_and_are_named(pend):
    # 1, "yes" or None-like strings would be silent typos: a TypeError that names the option
    for name in ("warm_start", "nt_scaling", "central_warm_start", "smooth_every_candidate", "cone_gap",
                 "drop_redundant_friction", "pyramid_fallback"):
        for bad in ("yes", 1, 0.0):
            with pytest.raises(TypeError, match=name):
                pend.with_options(**{name: bad})
    # the switches take effect (the options dict holds the numeric ones only)
    s0 = pend.make_state(qpos=[0.3])
    a, _ = ukemi.step(pend.with_options(cone_gap=False, nt_scaling=False), s0)
    b, _ = ukemi.step(pend, s0)
    np.testing.assert_allclose(a.qpos, b.qpos, atol=1e-12)  # no contact: the same step


def test_warm_start_margin_is_an_option_and_validated(pend):
    # a resting sphere warm-started with any margin stays at rest (the margin changes only the
    # interior-point start); bad margins name the field
    for bad in (0.0, -1e-3, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="warm_start_margin"):
            pend.with_options(warm_start_margin=bad)
    b = ukemi.ModelBuilder(timestep=0.001)
    b.add_geom("floor", body="world", shape="plane", friction=0.8)
    b.add_body("ball", mass=1.0, inertia=(0.004, 0.004, 0.004), pos=(0, 0, 0.1))
    b.add_joint("free", kind="floating", parent="world", child="ball")
    b.add_geom("g", body="ball", shape="sphere", size=(0.1,), friction=0.8)
    m = b.compile()
    for margin in (1e-6, 1e-3):
        tr = ukemi.rollout(m.with_options(warm_start_margin=margin), m.make_state(), nsteps=500)
        assert np.abs(tr.qvel[-100:]).max() < 1e-8


def _thrown_box():
    """A 0.2 m box on a free joint, thrown tilted and spinning onto a floor (μ = 0.8), and its
    start state."""
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("floor", body="world", shape="plane", friction=0.8)
    b.add_body("box", mass=1.0, inertia=(0.01, 0.01, 0.01), pos=(0, 0, 0.3))
    b.add_joint("free", kind="floating", parent="world", child="box")
    b.add_geom("g", body="box", shape="box", size=(0.1, 0.1, 0.1), friction=0.8)
    m = b.compile()
    return m, m.make_state(qpos=[0, 0, 0.3, 0.9659, 0.2588, 0, 0], qvel=[0.5, 0, 0, 0, 0, 2.0])


@pytest.mark.parametrize("name, bad, default, values", [
    ("warm_start_widening", (0.0, -1e-2, float("nan"), float("inf")), 1e-2, (1e-3, 1e-2, 1e-1)),
    # relative to the model's weight impulse Σ m g h (the larger of the two is taken)
    ("warm_start_widening_weight", (-0.1, float("nan"), float("inf")), 0.1, (0.0, 0.1, 3.0)),
])
def test_warm_start_widening_is_an_option_and_validated(pend, name, bad, default, values):
    # bad values name the field; a box thrown onto the floor lands and comes to rest, on the
    # same surface, whatever the widening of its warm starts (it changes only the solver's path)
    for b in bad:
        with pytest.raises(ValueError, match=name):
            pend.with_options(**{name: b})
    assert pend.options[name] == default
    m, s0 = _thrown_box()
    ends = []
    for v in values:
        tr = ukemi.rollout(m.with_options(**{name: v}), s0, nsteps=300)
        assert tr.converged
        assert np.abs(tr.qvel[-20:]).max() < 1e-6
        ends.append(tr.qpos[-1, 2])
    # at rest on a face: the centre 0.1 m above the floor
    np.testing.assert_allclose(ends, 0.1, atol=1e-8)


def test_friction_proximal_is_an_option_and_leaves_solutions_alone(pend):
    # bad values name the field; the proximal friction term changes only the solver's
    # directions (the residual stays exact): a box thrown spinning onto the floor follows the
    # same trajectory, to the solver's tolerances, with it off, at its default and 1e6x larger
    # (which takes other iterations: the option reaches the solver)
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="friction_proximal"):
            pend.with_options(friction_proximal=bad)
    assert pend.options["friction_proximal"] == 1e-2
    m, s0 = _thrown_box()
    runs = [ukemi.rollout(m.with_options(friction_proximal=p), s0, nsteps=150)
            for p in (0.0, 1e-2, 1e4)]
    assert all(tr.converged for tr in runs)
    for tr in runs[1:]:
        np.testing.assert_allclose(tr.qpos, runs[0].qpos, atol=1e-7)
    assert runs[2].iterations.sum() != runs[0].iterations.sum()


def test_nonconvergence_is_reported_not_silent(pend):
    tight = pend.with_options(max_iter=1, rtol=1e-300, acceptable_rtol=0.0)
    s0 = tight.make_state(qpos=[1.0], qvel=[3.0])
    with pytest.raises(ukemi.ConvergenceError) as err:
        ukemi.step(tight, s0)
    assert err.value.info.status == "max_iterations"
    s, info = ukemi.step(tight, s0, on_failure="return")
    assert info.status == "max_iterations" and not info.converged
    traj = ukemi.rollout(tight, s0, nsteps=5, on_failure="return")
    assert list(traj.status) == ["max_iterations"] * 5
    with pytest.raises(ukemi.ConvergenceError) as err:
        ukemi.rollout(tight, s0, nsteps=5)
    assert err.value.step_index == 0


def test_round_off_stall_is_acceptable_and_reported(pend):
    """An unreachable rtol stalls on round-off: status "acceptable" (a valid state, reported
    with its true residual) within acceptable_rtol; a failure when acceptance is off."""
    assert ukemi.STATUS_NAMES[:2] == ("converged", "acceptable")
    # the codes of the failures stay 2-4; the pyramid friction cones' valid state is last
    assert ukemi.STATUS_NAMES[5] == "pyramid_friction"
    assert ukemi.SUCCESS_STATUSES == ("converged", "acceptable", "pyramid_friction")
    s0 = pend.make_state(qpos=[1.0], qvel=[3.0])
    ref, _ = ukemi.step(pend, s0)
    strict = pend.with_options(rtol=1e-300)
    assert strict.options["acceptable_rtol"] == 1e-8
    s, info = ukemi.step(strict, s0)
    assert info.status == "acceptable" and info.converged
    assert 0 < info.residual < 1e-8
    np.testing.assert_allclose(s.qvel, ref.qvel, atol=1e-9)
    with pytest.raises(ukemi.ConvergenceError):
        ukemi.step(pend.with_options(rtol=1e-300, acceptable_rtol=0.0), s0)
    for field in ("acceptable_rtol", "acceptable_kappa_tol"):
        with pytest.raises(ValueError, match=field):
            pend.with_options(**{field: -1.0})


def test_fast_spin_is_reported_never_a_crash(free_body):
    """|ω| must stay below √2/h (a step turns a body by at most 90°; beyond, the discrete
    momentum has a second, spurious root before the step map's domain ends at 2/h): a spin past
    it fails cleanly in one step of h, is taken as sub-steps of h / n while √2 n/h exceeds it
    (max_subdivisions), and fails cleanly beyond that. (The accuracy limit `max_step_rotation`
    is off here: see test_fast_turns_are_taken_as_sub_steps_of_at_most_max_step_rotation.)"""
    free_body = free_body.with_options(max_step_rotation=np.inf)
    s = free_body.make_state(qvel=[0, 0, 0, 0, 0, 250.0])  # √2/h = 141 rad/s
    one = free_body.with_options(max_subdivisions=1)
    s1, info = ukemi.step(one, s, on_failure="return")
    assert info.status not in ukemi.SUCCESS_STATUSES
    assert np.all(np.isfinite(s1.qpos))
    # between √2/h and 2/h the step map is defined, and the spin is still subdivided
    _, info = ukemi.step(free_body, free_body.make_state(qvel=[0, 0, 0, 0, 0, 170.0]))
    assert info.converged and info.subdivisions == 2
    # two sub-steps of h/2 (limit 283 rad/s): the torque-free tumble keeps its energy
    s2, info = ukemi.step(free_body, s)
    assert info.converged and info.subdivisions == 2
    assert s2.energy() == pytest.approx(s.energy(), rel=1e-10)
    # 2000 rad/s needs 16 sub-steps (limit 2263 rad/s; 8 allow 1131)
    s3, info = ukemi.step(free_body, free_body.make_state(qvel=[0, 0, 0, 0, 0, 2000.0]))
    assert info.converged and info.subdivisions == 16
    # past 32 sub-steps' limit (4525 rad/s): reported, finite
    fast = free_body.make_state(qvel=[0, 0, 0, 0, 0, 10000.0])
    s3, info = ukemi.step(free_body, fast, on_failure="return")
    assert info.status not in ukemi.SUCCESS_STATUSES and info.subdivisions == 1
    assert np.all(np.isfinite(s3.qpos))


@pytest.mark.parametrize(("spin", "substeps"), [(20.0, 1), (40.0, 2), (170.0, 8), (250.0, 16),
                                                (2000.0, 32)])
def test_fast_turns_are_taken_as_sub_steps_of_at_most_max_step_rotation(free_body, spin,
                                                                          substeps):
    """The default `max_step_rotation` = 0.3 rad: a step that turns a body further is taken as
    the fewest sub-steps (a power of two) that turn it at most that much each, up to
    `max_subdivisions` (2000 rad/s turns 0.625 rad in each of 32 sub-steps: the most there
    are). A torque-free tumble keeps its energy through them."""
    assert free_body.options["max_step_rotation"] == 0.3
    s = free_body.make_state(qvel=[0, 0, 0, 0, 0, spin])
    nxt, info = ukemi.step(free_body, s)
    assert info.converged and info.subdivisions == substeps
    assert nxt.energy() == pytest.approx(s.energy(), rel=1e-10)


@pytest.mark.parametrize("bad", [0.0, -0.1, np.nan])
def test_max_step_rotation_is_validated(free_body, bad):
    with pytest.raises(ValueError, match="max_step_rotation"):
        free_body.with_options(max_step_rotation=bad)
    assert free_body.with_options(max_step_rotation=np.inf).options["max_step_rotation"] == np.inf


def test_four_bar_loop_through_python():
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_body("crank", 1.0, (1 / 12, 1 / 12, 1e-3), pos=(0, 0, 0.5))
    b.add_body("coupler", 1.0, (1e-3, 1 / 3, 1 / 3), pos=(1, 0, 1))
    b.add_body("rocker", 1.0, (1 / 12, 1 / 12, 1e-3), pos=(2, 0, 0.5))
    y = (0, 1, 0)
    b.add_joint("a", "revolute", "world", "crank", axis=y, child_anchor=(0, 0, -0.5))
    b.add_joint("b", "revolute", "crank", "coupler", axis=y, parent_anchor=(0, 0, 0.5),
                child_anchor=(-1, 0, 0))
    b.add_joint("c", "revolute", "coupler", "rocker", axis=y, parent_anchor=(1, 0, 0),
                child_anchor=(0, 0, 0.5))
    b.add_joint("d", "revolute", "rocker", "world", axis=y, parent_anchor=(0, 0, -0.5),
                child_anchor=(2, 0, 0), loop=True)
    model = b.compile()
    assert model.nq == 3
    traj = ukemi.rollout(model, model.make_state(qvel=[1.0, -1.0, 1.0]), nsteps=500)
    dist = np.linalg.norm(traj.body_pos[:, 3] - [2.0, 0.0, 0.0], axis=1)
    np.testing.assert_allclose(dist, 0.5, atol=1e-8)
    assert np.ptp(traj.qpos[:, 0]) > 1.0


def test_steps_do_not_depend_on_earlier_calls():
    """`ukemi.step` reuses the model's solver workspaces between calls (allocating one per call
    cost more than a robot's step): two trajectories stepped alternately on one model, warm
    starts and contact activation included, must equal their own rollouts bit for bit."""
    path = ukemi.gymnasium_asset_path("hopper")
    with pytest.warns(UserWarning):
        m = ukemi.load(path)
    lo, hi = np.array(m.actuator_ctrlrange).T
    rng = np.random.default_rng(7)
    ctrls = [lo + (hi - lo) * rng.random((400, m.nu)) for _ in range(2)]
    starts = [m.make_state(), m.make_state(qpos=m.qpos0 + 0.05 * rng.standard_normal(m.nq))]
    states = list(starts)
    for k in range(400):
        for i in range(2):
            states[i], info = ukemi.step(m, states[i], ctrls[i][k])
            assert info.converged
    for i in range(2):
        tr = ukemi.rollout(m, starts[i], ctrls[i])
        assert tr.min_distance.min() < 1e-6  # it landed: contacts were active
        assert np.array_equal(tr.qpos[-1], states[i].qpos)
        assert np.array_equal(tr.qvel[-1], states[i].qvel)


def test_a_snapshot_restores_a_state_and_its_future_bit_for_bit():
    """`state.snapshot()` keeps the solver's warm start with the motion: a hopper landing and
    hopping under random controls, restored from the snapshot halfway, steps the rest of the way
    bit for bit as the original did. A snapshot of the wrong length (another model's) or with a
    bad interval entry is refused by name."""
    path = ukemi.gymnasium_asset_path("hopper")
    with pytest.warns(UserWarning):
        m = ukemi.load(path)
    lo, hi = np.array(m.actuator_ctrlrange).T
    ctrls = lo + (hi - lo) * np.random.default_rng(3).random((120, m.nu))
    s = m.make_state()
    for u in ctrls[:60]:
        s, _ = ukemi.step(m, s, u)
    snap = s.snapshot()
    assert snap.dtype == np.float64 and snap.ndim == 1 and len(snap) > m.nq + m.nv
    restored = m.state_from_snapshot(snap)
    assert np.array_equal(restored.snapshot(), snap)
    tr_a = ukemi.rollout(m, s, ctrls[60:])
    tr_b = ukemi.rollout(m, restored, ctrls[60:])
    assert tr_a.min_distance.min() < 1e-6  # in contact: the warm start mattered
    assert np.array_equal(tr_a.qpos, tr_b.qpos) and np.array_equal(tr_a.qvel, tr_b.qvel)
    with pytest.raises(ValueError, match="snapshot"):
        m.state_from_snapshot(snap[:-1])
    with pytest.raises(ValueError, match="snapshot"):
        ukemi.models.pendulum().state_from_snapshot(snap)
    bad = snap.copy()
    bad[1] = -3.0
    with pytest.raises(ValueError, match="interval"):
        m.state_from_snapshot(bad)
    with pytest.raises(TypeError, match="snapshot"):
        m.state_from_snapshot("not numbers")
    bad = snap.copy()
    bad[5] = np.nan
    with pytest.raises(ValueError, match=r"snapshot\[5\]"):
        m.state_from_snapshot(bad)


def test_builder_servos_are_mujocos_position_and_velocity_actuators():
    """`ModelBuilder.add_actuator(kp=, kv=, forcerange=)`: a pendulum on a stiff position servo
    (h kv / I = 5 at h = 0.01, unstable if its velocity gain were explicit) built in Python
    steps as the same pendulum read from MJCF with `<position kp kv forcerange>`, and follows
    MuJoCo's `implicitfast` on that MJCF; a velocity servo likewise. Bad gains name the field."""
    mujoco = pytest.importorskip("mujoco")
    from conftest import beside_mujoco

    def built(**servo):
        b = ukemi.ModelBuilder(timestep=0.01)
        b.add_body("bob", mass=1.0, inertia=(1e-3, 1e-3, 1e-3), pos=(0, 0, -1))
        b.add_joint("hinge", kind="revolute", parent="world", child="bob", axis=(0, 1, 0),
                    child_anchor=(0, 0, 1))
        b.add_actuator("servo", joint="hinge", **servo)
        return b.compile()

    xml = """<mujoco><option timestep="0.01"/><worldbody><body name="bob" pos="0 0 -1">
      <joint name="hinge" type="hinge" axis="0 1 0" pos="0 0 1" {}/>
      <inertial pos="0 0 0" mass="1" diaginertia="1e-3 1e-3 1e-3"/></body></worldbody>
      <actuator>{}</actuator></mujoco>"""
    cases = [(dict(kp=300.0, kv=500.0, forcerange=(-200.0, 200.0)), "",
              '<position joint="hinge" kp="300" kv="500" forcelimited="true" forcerange="-200 200"/>'),
             # the joint's clamp of gear · F (gear 2: F within ±30)
             (dict(kp=300.0, kv=500.0, gear=2.0, actuatorfrcrange=(-60.0, 60.0)),
              'actuatorfrcrange="-60 60"', '<position joint="hinge" kp="300" kv="500" gear="2"/>'),
             (dict(kv=50.0), "", '<velocity joint="hinge" kv="50"/>')]
    for servo, joint, act in cases:
        ours = built(**servo)
        from_xml = ukemi.Model.from_xml_string(xml.format(joint, act))
        mj = mujoco.MjModel.from_xml_string(xml.format(joint, act))
        mj.opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        ctrls = [np.array([0.8])] * 200
        a, d, worst = beside_mujoco(ours, ours.make_state(), mj, ctrls)
        b, _, _ = beside_mujoco(from_xml, from_xml.make_state(), mj, ctrls)
        np.testing.assert_allclose(a.qpos, b.qpos, atol=1e-12)
        np.testing.assert_allclose(a.qvel, b.qvel, atol=1e-10)
        assert worst < 5e-3, (servo, worst)
    assert np.abs(a.qvel).max() > 0.5  # the velocity servo spins the pendulum at its target
    with pytest.raises(ValueError, match="kp"):
        built(kp=-1.0)
    with pytest.raises(ValueError, match="forcerange"):
        built(kp=1.0, forcerange=(2.0, 1.0))
    with pytest.raises(ValueError, match="joint_forcerange"):
        built(kp=1.0, actuatorfrcrange=(2.0, 1.0))


def test_builder_frictionloss_is_mujocos_dry_joint_friction():
    """`ModelBuilder.add_joint(frictionloss=)`: a slider pushed by 5 N against 3 N of friction
    accelerates at (5 - 3) / m, as from MJCF `frictionloss` and in MuJoCo; pushed by 2 N it
    stays put (MuJoCo's soft friction creeps); the friction impulse is reported; bad values
    name the field."""
    mujoco = pytest.importorskip("mujoco")

    def built(f):
        b = ukemi.ModelBuilder(timestep=0.01, gravity=(0, 0, 0))
        b.add_body("m", mass=2.0, inertia=(0.1, 0.1, 0.1))
        b.add_joint("slider", kind="prismatic", parent="world", child="m", axis=(1, 0, 0),
                    frictionloss=f)
        b.add_actuator("push", joint="slider")
        return b.compile()

    xml = """<mujoco><option timestep="0.01" gravity="0 0 0"/><worldbody><body name="m">
      <joint name="slider" type="slide" axis="1 0 0" frictionloss="3"/>
      <inertial pos="0 0 0" mass="2" diaginertia="0.1 0.1 0.1"/></body></worldbody>
      <actuator><motor joint="slider"/></actuator></mujoco>"""
    ours, from_xml = built(3.0), ukemi.Model.from_xml_string(xml)
    mj = mujoco.MjModel.from_xml_string(xml)
    for push, accel in ((5.0, 1.0), (2.0, 0.0)):
        a = ukemi.rollout(ours, ours.make_state(), ctrls=np.full((100, 1), push))
        b = ukemi.rollout(from_xml, from_xml.make_state(), ctrls=np.full((100, 1), push))
        np.testing.assert_array_equal(a.qpos, b.qpos)
        np.testing.assert_allclose(a.qvel[-1, 0], accel * 1.0, atol=1e-6)
        d = mujoco.MjData(mj)
        d.ctrl[:] = push
        for _ in range(100):
            mujoco.mj_step(mj, d)
        if accel:
            np.testing.assert_allclose(d.qvel[0], accel, atol=1e-9)
        else:
            assert abs(a.qpos[-1, 0]) < 1e-6 < abs(d.qpos[0])
    state, _ = ukemi.step(ours, ours.make_state(), [5.0])
    np.testing.assert_allclose(state.joint_friction_impulse, [3.0 * 0.01], rtol=1e-6)
    assert dict(built(0.0).variable_counts)["joint_friction"] == 0
    with pytest.raises(ValueError, match="frictionloss"):
        built(-1.0)


def test_builder_pairs_and_passive_tendons_are_the_mjcf_ones():
    """`ModelBuilder.add_pair` and `add_passive_tendon` build what MJCF `<contact><pair>` and a
    fixed tendon with stiffness and damping load: the same trajectories, bit for bit. Bad
    values name the field."""
    def built(pair_friction=0.3, k=30.0, d=0.5, contact="nonlinear"):
        b = ukemi.ModelBuilder(timestep=0.01)
        b.add_geom("floor", "world", "plane", friction=1.0, contype=0, conaffinity=0)
        b.add_body("a", mass=1.0, inertia=(0.01, 0.01, 0.01), pos=(0, 0, 0.2))
        b.add_joint("j1", "slide", "world", "a", axis=(0, 0, 1), parent_anchor=(0, 0, 0.2))
        b.add_body("b", mass=1.0, inertia=(0.01, 0.01, 0.01), pos=(0, 0, 0.2))
        b.add_joint("j2", "hinge", "a", "b", axis=(0, 1, 0))
        b.add_geom("ball", "b", "sphere", size=(0.1,), pos=(0.2, 0, 0), friction=1.0)
        b.add_pair("floor", "ball", friction=pair_friction, contact=contact)
        b.add_passive_tendon("t", [("j1", 1.0), ("j2", -0.5)], stiffness=k, damping=d,
                             springlength=0.1)
        return b.compile()

    xml = """<mujoco><option timestep="0.01"/><worldbody>
      <geom name="floor" type="plane" size="5 5 .1" friction="1" contype="0" conaffinity="0"/>
      <body name="a" pos="0 0 0.2"><joint name="j1" type="slide" axis="0 0 1"/>
        <inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
        <body name="b"><joint name="j2" type="hinge" axis="0 1 0"/>
          <inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
          <geom name="ball" type="sphere" size="0.1" pos="0.2 0 0" mass="0" friction="1"/>
        </body></body></worldbody>
      <contact><pair geom1="floor" geom2="ball" friction="0.3 0.3"/></contact>
      <tendon><fixed name="t" stiffness="30" damping="0.5" springlength="0.1">
        <joint joint="j1" coef="1"/><joint joint="j2" coef="-0.5"/></fixed></tendon></mujoco>"""
    ours, theirs = built(), ukemi.Model.from_xml_string(xml)
    a = ukemi.rollout(ours, ours.make_state(qvel=[0.0, 3.0]), nsteps=100)
    b = ukemi.rollout(theirs, theirs.make_state(qvel=[0.0, 3.0]), nsteps=100)
    assert a.converged and b.converged
    np.testing.assert_allclose(a.qpos, b.qpos, atol=1e-12)  # (MJCF inertias: round-off)
    # the floor's bitmasks collide with nothing: only the pair holds the ball up
    assert ours.ncontact > 0 and a.qpos[:, 0].min() > -0.3, a.qpos[:, 0].min()
    with pytest.raises(ValueError, match=r"pair\[0\].friction"):
        built(pair_friction=-1.0)
    with pytest.raises(ValueError, match="contact"):
        built(contact="sticky")
    with pytest.raises(ValueError, match=r"passive_tendon\[t\].stiffness"):
        built(k=-1.0)
