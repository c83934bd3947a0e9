"""ukemi demo: a tumbling T-handle (the Dzhanibekov effect), a double pendulum, a four-bar
linkage and hard contact (a ball dropped onto a stack of boxes), with the conservation, constraint and
penetration numbers that show the engine at work.

Run: bash scripts/dev.sh demo
"""

from __future__ import annotations

import numpy as np

import ukemi


def tumbling_handle() -> None:
    b = ukemi.ModelBuilder(timestep=0.005, gravity=(0, 0, 0))
    b.add_body("handle", mass=1.0, inertia=(1.0, 2.0, 3.0), pos=(0, 0, 0))
    b.add_joint("free", kind="floating", parent="world", child="handle")
    model = b.compile()
    # spin about the intermediate axis (y) with a tiny perturbation
    state = model.make_state(qvel=[0, 0, 0, 1e-3, 2.0, 1e-3])
    traj = ukemi.rollout(model, state, nsteps=4000)
    wy = traj.qvel[:, 4]
    flips = int(np.sum(np.diff(np.sign(wy)) != 0))
    L0 = state.angular_momentum()
    L1 = traj.final_state.angular_momentum()
    print(f"tumbling handle: {flips} flips of the spin axis in {traj.time[-1]:.0f} s, "
          f"angular momentum drift {np.linalg.norm(L1 - L0) / np.linalg.norm(L0):.1e}, "
          f"energy drift {abs(traj.final_state.energy() - state.energy()) / state.energy():.1e}")


def double_pendulum() -> None:
    b = ukemi.ModelBuilder(timestep=0.005)
    rod = (1 / 12, 1 / 12, 1e-3)
    b.add_body("upper", mass=1.0, inertia=rod, pos=(0, 0, -0.5))
    b.add_body("lower", mass=1.0, inertia=rod, pos=(0, 0, -1.5))
    b.add_joint("shoulder", "revolute", "world", "upper", axis=(0, 1, 0), child_anchor=(0, 0, 0.5))
    b.add_joint("elbow", "revolute", "upper", "lower", axis=(0, 1, 0),
                parent_anchor=(0, 0, -0.5), child_anchor=(0, 0, 0.5))
    model = b.compile()
    state = model.make_state(qpos=[2.0, -1.0])
    traj = ukemi.rollout(model, state, nsteps=4000)
    print(f"double pendulum: 20 s chaotic swing, {traj.iterations.mean():.1f} Newton iterations "
          f"per step, energy error {abs(traj.final_state.energy() - state.energy()):.1e} J, "
          f"final angles {np.round(traj.qpos[-1], 3)}")


def four_bar() -> None:
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
    state = model.make_state(qvel=[1.0, -1.0, 1.0])
    traj = ukemi.rollout(model, state, nsteps=1000)
    rocker_tip = traj.body_pos[:, 3]  # rocker centre: 0.5 m from its ground pivot
    gap = np.abs(np.linalg.norm(rocker_tip - np.array([2.0, 0, 0.0]), axis=1) - 0.5).max()
    print(f"four-bar linkage: crank swept {np.ptp(traj.qpos[:, 0]):.2f} rad, "
          f"rocker stays on its circle to {gap:.1e} m")


def hard_contact() -> None:
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("floor", "world", "plane", friction=0.8)
    for i in range(3):
        b.add_body(f"box{i}", 1.0, (1 / 150,) * 3, pos=(0, 0, 0.1 + 0.2 * i + 1e-4 * i))
        b.add_joint(f"free{i}", "free", "world", f"box{i}")
        b.add_geom(f"box{i}", f"box{i}", "box", size=(0.1, 0.1, 0.1), friction=0.8)
    b.add_body("ball", 0.5, (0.002, 0.002, 0.002), pos=(0.03, 0.02, 1.2))
    b.add_joint("ball_free", "free", "world", "ball")
    b.add_geom("ball", "ball", "sphere", size=(0.1,), friction=0.8)
    model = b.compile()
    state = model.make_state()
    traj = ukemi.rollout(model, state, nsteps=300)
    print(f"hard contact: {model.ncontact} contact candidates, {traj.iterations.mean():.1f} "
          f"interior-point iterations per step, least signed distance "
          f"{traj.min_distance.min():+.1e} m over {traj.time[-1]:.0f} s, top box moved "
          f"{np.linalg.norm(traj.body_pos[-1, 3] - traj.body_pos[0, 3]):.3f} m")


def gradients_through_contact() -> None:
    """Dojo Fig. 4 in two numbers: how far a resting 1 kg box moves per newton of push, below
    and above the friction threshold (4.9 N), from the implicit gradient at two κ."""
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("floor", body="world", shape="plane", friction=0.5)
    b.add_body("box", mass=1.0, inertia=(1 / 600,) * 3, pos=(0, 0, 0.05))
    b.add_joint("free", kind="floating", parent="world", child="box")
    b.add_geom("box", body="box", shape="box", size=(0.05, 0.05, 0.05), friction=0.5)
    b.add_actuator("push", joint="free", gear=1.0)
    model = b.compile()
    state = model.make_state()
    for _ in range(30):
        state, _ = ukemi.step(model, state, [0.0])
    row = []
    for kappa in (1e-8, 1e-5):
        g = [ukemi.step_jacobians(model, state, [f], kappa_grad=kappa, wrt=("ctrl",)).B[0, 0]
             for f in (3.0, 7.0)]
        row.append(f"κ={kappa:.0e}: {g[0]:.2e} / {g[1]:.2e}")
    print("gradient d(dx)/dF at 3 N / 7 N (hard: 0 / 1.0e-04 m/N): " + ", ".join(row))


if __name__ == "__main__":
    print(f"ukemi {ukemi.__version__}")
    tumbling_handle()
    double_pendulum()
    four_bar()
    hard_contact()
    gradients_through_contact()
