"""Contact and limits through the Python API."""

from __future__ import annotations

import numpy as np
import pytest

import ukemi


def ball_on_floor(timestep=0.01, contact="nonlinear", friction=0.5, z=0.5):
    b = ukemi.ModelBuilder(timestep=timestep)
    b.add_geom("floor", "world", "plane", friction=friction, contact=contact)
    b.add_body("ball", mass=2.0, inertia=(0.008, 0.008, 0.008), pos=(0, 0, z))
    b.add_joint("free", "floating", "world", "ball")
    b.add_geom("ball", "ball", "sphere", size=(0.1,), friction=friction, contact=contact)
    return b.compile()


def test_model_reports_contacts_and_variable_counts():
    m = ball_on_floor()
    assert m.ngeom == 2 and m.ncontact == 1
    assert m.contact_pairs == [("ball", "floor", "nonlinear")]
    counts = dict(m.variable_counts)
    assert counts["contact_nonlinear_cone"] == 8 and counts["contact_impact"] == 0
    assert dict(ball_on_floor(contact="impact").variable_counts)["contact_impact"] == 2
    assert dict(ball_on_floor(contact="linear").variable_counts)["contact_linear_cone"] == 12
    assert dict(ball_on_floor(friction=0.0).variable_counts)["contact_impact"] == 2


def test_drop_never_penetrates_and_rests_with_weight_as_impulse():
    m = ball_on_floor()
    s = m.make_state()
    np.testing.assert_allclose(ukemi.signed_distances(m, s), [0.4])
    traj = ukemi.rollout(m, s, nsteps=300)
    assert traj.min_distance.min() >= -1e-8
    assert traj.qpos[-1, 2] == pytest.approx(0.1, abs=1e-6)
    # at rest the normal impulse per step carries the weight: γ = m g h
    gamma = traj.final_state.contact_impulse[0, 0]
    assert gamma == pytest.approx(2.0 * 9.81 * 0.01, rel=1e-6)
    assert np.abs(traj.qvel[-1]).max() < 1e-8


def test_tilted_plane_via_normal():
    b = ukemi.ModelBuilder()
    n = np.array([0.0, -np.sin(0.3), np.cos(0.3)])
    b.add_geom("ramp", "world", "plane", normal=n)
    b.add_body("p", 1.0, (0.01, 0.01, 0.01), pos=tuple(0.5 * n))
    b.add_joint("f", "free", "world", "p")
    b.add_geom("pt", "p", "point")
    m = b.compile()
    assert ukemi.signed_distances(m, m.make_state())[0] == pytest.approx(0.5)


def test_limits_hold_from_python():
    b = ukemi.ModelBuilder()
    b.add_body("bob", 1.0, (1e-3, 1e-3, 1e-3), pos=(0, 0, -1))
    b.add_joint("h", "revolute", "world", "bob", axis=(0, 1, 0), child_anchor=(0, 0, 1),
                range=(-0.2, 0.2))
    m = b.compile()
    assert m.nlimit == 1
    traj = ukemi.rollout(m, m.make_state(qpos=[0.0], qvel=[4.0]), nsteps=200)
    assert traj.qpos[:, 0].max() <= 0.2 + 1e-8
    assert traj.qpos[:, 0].min() >= -0.2 - 1e-8


def test_limit_range_wider_than_pi_passes_through_180_degrees():
    """A hinge limited to (-1, 4.5) rad (wider than π, like the A1's hips) swings through
    θ = π without a 2π jump: the angle is reported on its range's branch, energy is conserved
    while it swings freely (no limit impulse), and the upper limit at 4.5 rad holds."""
    b = ukemi.ModelBuilder(timestep=0.002)
    b.add_body("bob", 1.0, (1e-3, 1e-3, 1e-3), pos=(0, 0, -1))
    b.add_joint("h", "revolute", "world", "bob", axis=(0, 1, 0), child_anchor=(0, 0, 1),
                range=(-1.0, 4.5))
    m = b.compile()
    s0 = m.make_state(qpos=[2.5], qvel=[3.0])  # rises towards the top at θ = π
    tr = ukemi.rollout(m, s0, nsteps=400)
    q = tr.qpos[:, 0]
    assert np.abs(np.diff(q)).max() < 0.1, "the angle jumped"
    assert q.max() > np.pi + 0.3, "passed through 180°"
    assert q.max() <= 4.5 + 1e-8 and q.min() >= -1.0 - 1e-8
    free = q < 4.5 - 1e-3  # before it reaches the upper limit
    first_hit = int(np.argmin(free)) if not free.all() else len(free)
    e = tr.energy[:first_hit]
    assert np.ptp(e) < 1e-3 * abs(e[0]), f"energy band {np.ptp(e):.2e} J"


def test_contact_argument_errors():
    b = ukemi.ModelBuilder()
    b.add_body("a", 1.0, (0.1, 0.1, 0.1))
    b.add_joint("f", "free", "world", "a")
    with pytest.raises(ukemi.ModelError, match="shape"):
        b.add_geom("g", "a", "torus", size=(1,))
    with pytest.raises(ukemi.ModelError, match="contact"):
        b.add_geom("g", "a", "sphere", size=(0.1,), contact="sticky")
    with pytest.raises(ukemi.ModelError, match="size"):
        b.add_geom("g", "a", "box", size=(0.1,))
    b.add_geom("g", "a", "sphere", size=(-0.1,))
    with pytest.raises(ukemi.ModelError, match=r"geom\[g\]\.size"):
        b.compile()
    b2 = ukemi.ModelBuilder()
    b2.add_body("a", 1.0, (0.1, 0.1, 0.1))
    b2.add_joint("f", "free", "world", "a")
    b2.add_geom("c", "a", "ellipsoid", size=(0.1, 0.1, 0.2))
    b2.add_geom("d", "world", "sphere", size=(0.1,))
    with pytest.raises(ukemi.UnsupportedError, match="geom"):
        b2.compile()


def _sliding_ball_state(m):
    """Ball resting on the floor with a sideways velocity: contact and friction cone active."""
    s = m.make_state(qpos=[0, 0, 0.1, 1, 0, 0, 0], qvel=[2.0, 0.5, 0, 0, 0, 0])
    for _ in range(3):
        s, _ = ukemi.step(m, s)
    return s


@pytest.mark.parametrize("nt_scaling", [True, False])
def test_solver_trace_records_a_converging_solve(nt_scaling):
    m = ball_on_floor(z=0.1).with_options(nt_scaling=nt_scaling, warm_start=False)
    s = _sliding_ball_state(m)
    nxt, info, trace = ukemi.solver_trace(m, s, condition=True)
    assert info.status == "converged"
    n = info.iterations
    assert len(trace["residual"]) == n and n > 3
    assert np.all(trace["attempt"] == 0)
    # the trace is of the same solve as ukemi.step
    ref, ref_info = ukemi.step(m, s)
    assert ref_info.iterations == n
    np.testing.assert_array_equal(nxt.qvel, ref.qvel)
    # interior-point progress: μ falls by orders of magnitude, every step length in (0, 1]
    assert trace["mu"][-1] < 1e-6 * trace["mu"][0]
    assert np.all((trace["alpha"] > 0) & (trace["alpha"] <= 1))
    # the records are taken before each iteration: the last one is still above tolerance
    assert trace["complementarity"][-1] > 0 or trace["residual"][-1] > 0
    # Newton matrices are finite and non-singular; conditioning grows as contact hardens
    cond = trace["condition"]
    assert np.all(np.isfinite(cond)) and np.all(cond >= 1)
    assert cond[-1] > cond[0]


def test_nesterov_todd_scaling_reaches_the_same_step():
    m = ball_on_floor(z=0.1)
    s = _sliding_ball_state(m)
    a, ia = ukemi.step(m, s)
    b, ib = ukemi.step(m.with_options(nt_scaling=False), s)
    assert ia.converged and ib.converged
    # same complementarity solution, different paths to it
    np.testing.assert_allclose(a.qvel, b.qvel, atol=1e-9)
    np.testing.assert_allclose(a.contact_impulse, b.contact_impulse, atol=1e-9)


def _sliding_box(cone_gap, steps=40):
    """A 1 kg box sliding diagonally on the floor (μ = 0.5) from 2 m/s: its velocities."""
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("floor", "world", "plane", friction=0.5)
    b.add_body("box", mass=1.0, inertia=(0.0067, 0.0067, 0.0067), pos=(0, 0, 0.1))
    b.add_joint("free", "floating", "world", "box")
    b.add_geom("box", "box", "box", size=(0.1, 0.1, 0.1), friction=0.5)
    m = b.compile().with_options(cone_gap=cone_gap)
    v0 = 2.0 * np.array([np.cos(0.5), np.sin(0.5)])
    s = m.make_state(qpos=[0, 0, 0.1, 1, 0, 0, 0], qvel=[v0[0], v0[1], 0, 0, 0, 0])
    vs = []
    for _ in range(steps):
        s, info = ukemi.step(m, s)
        assert info.converged
        vs.append(np.array(s.qvel[:2]))
    return np.array(vs)


def test_friction_cones_judged_by_duality_gap_or_jordan_product_slide_alike():
    # cone_gap (default) ends a solve on each friction cone's duality gap bᵀc; False also asks
    # the Jordan product's vector part (the friction direction) to reach kappa_tol. The slide is
    # Coulomb's either way: deceleration μ g along the initial direction, no lateral drift
    gap, jordan = _sliding_box(True), _sliding_box(False)
    np.testing.assert_allclose(gap, jordan, atol=1e-8)
    direction = np.array([np.cos(0.5), np.sin(0.5)])
    for vs in (gap, jordan):
        speed = vs @ direction
        lateral = vs @ np.array([-direction[1], direction[0]])
        assert np.abs(lateral).max() < 1e-8
        # 2 m/s falls by μ g h = 0.049 m/s a step (until the box stops after ~41 steps)
        np.testing.assert_allclose(np.diff(speed), -0.5 * 9.81 * 0.01, rtol=1e-6)


def test_solver_trace_condition_numbers_on_a_robot():
    """On a robot the condition number is taken on the rows the solve factors: the gymnasium
    humanoid's hundreds of contact candidates left out of a resting step would make the dense
    SVD thousands of rows wide (and add their identity rows' unit singular values)."""
    m = ukemi.Model.from_xml_path(ukemi.gymnasium_asset_path("humanoid"))
    s = m.make_state()
    for _ in range(300):  # fall onto the floor (0.9 s)
        s, _ = ukemi.step(m, s, np.zeros(m.nu))
    assert ukemi.signed_distances(m, s).min() < 1e-9
    assert m.ncontact > 100
    _, info, trace = ukemi.solver_trace(m, s, condition=True)
    assert info.converged
    cond = trace["condition"]
    assert np.all(np.isfinite(cond)) and np.all(cond >= 1)
    # hard contact: the matrix grows ill-conditioned as the complementarity falls
    assert len(cond) > 5 and cond[-1] > 10 * cond[0]


def test_solver_trace_without_condition_numbers():
    m = ball_on_floor(z=0.1)
    _, info, trace = ukemi.solver_trace(m, m.make_state())
    assert np.all(np.isnan(trace["condition"]))
    with pytest.raises(TypeError):
        ukemi.solver_trace(m, "not a state")


def test_activation_falls_back_to_every_candidate_when_a_solve_fails():
    """Contact activation is a speed heuristic: a step whose solve fails with far candidates left
    out is solved again with all of them. Random stress scene 543 (a 3-link universal-joint
    chain) stalled at step 38 with activation (k = 1.3e-8 at the line-search floor, then 262 of
    300 steps unconverged) while the all-active solve converges in 13 iterations."""
    from tests.stress._random_scenes import random_scene

    m, _ = random_scene(543)
    m = m.with_options(activation_margin=0.01)
    tr = ukemi.rollout(m, m.make_state(), nsteps=60, on_failure="return")
    assert tr.converged, np.asarray(tr.status)
    least = min(ukemi.signed_distances(m, m.make_state(qpos=q, qvel=v)).min()
                for q, v in zip(tr.qpos, tr.qvel))
    assert least > -1e-8


THIN_PADS = """
<mujoco>
  <option gravity="0 0 0" timestep="0.01"/>
  <worldbody>
    <geom name="fixed_pad" type="box" size="0.003 0.002 0.003" pos="0 -0.002 0"/>
    <body name="finger">
      <inertial pos="0 0 0" mass="0.02" diaginertia="1e-5 1e-5 1e-5"/>
      <joint name="slide" type="slide" axis="0 1 0" range="0 0.04" limited="true"/>
      <geom name="pad" type="box" size="0.003 0.002 0.003" pos="0 0.002 0"/>
    </body>
  </worldbody>
</mujoco>
"""


def test_thin_box_closing_past_its_thickness_in_one_step_stops_on_the_near_face():
    """A 4 mm pad 7 mm from a fixed pad, closing at 20 m/s: the step's predicted pose lies far
    past the fixed pad. The face that measures the corners must be the near one (the pads are
    apart at the start of the step); chosen at the predicted pose it was the far face, behind
    which the pad already lay: the step failed and the pad ended 4.8 mm inside the other pad,
    below its joint limit. At the limit q = 0 the two pads are exactly flush."""
    m = ukemi.Model.from_xml_string(THIN_PADS)
    s = m.make_state(qpos=[0.007], qvel=[-20.0])
    traj = ukemi.rollout(m, s, nsteps=5, on_failure="return")
    assert list(traj.status) == ["converged"] * 5
    assert traj.qpos[:, 0].min() >= -1e-8  # the slide's lower limit
    assert traj.min_distance.min() >= -1e-8
    assert traj.qpos[1, 0] == pytest.approx(0.0, abs=1e-8)  # stopped flush in the first step
