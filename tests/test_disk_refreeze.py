"""A near-flat disk on a plane whose rim point is re-frozen after a solve across the disk from the
point its contact frame was built at gets its frame built again there
(``engine/src/solver/activation.rs``, ``refreeze_disks``; ``Frozen::RimFramed``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from stress._random_scenes import random_pile

import ukemi

DATA = Path(__file__).parent / "data"


def test_a_rim_point_refrozen_across_the_disk_moves_its_contact_frame():
    """Random pile 198 (``tests/stress``), step 45: a cylinder lying flat on the floor is struck
    near its rim by a capsule falling at 4.4 m/s. The whole-step solve converged holding the
    disk at the rim point lowest at the predicted poses, but at the solved poses the rim's
    lowest point was on the opposite side, 3 mm deep. Re-frozen there with the impulse still
    acting at the first point, the step had no solution (an upward impulse on one side of a
    thin disk tips its far side down): every attempt and every subdivision failed, and the step
    ended unconverged with the capsule 14 mm inside the cylinder (so it still does with the
    frame left where it was). With the frame moved to the new point the step converges,
    touching and not penetrating, and loses energy (an inelastic impact).

    The state is the pile's positions and velocities before step 45 as the engine of 2026-12-05
    (3c7f9aa) simulated them (the steps before are chaotic), without their warm start: the step
    fails from it the same way."""
    m, _ = random_pile(198)
    data = np.load(DATA / "pile198_step45_qpos_qvel.npz")
    s = m.make_state(qpos=data["qpos"], qvel=data["qvel"])
    nxt, info = ukemi.step(m, s, None)
    assert info.status == "converged", info
    assert info.subdivisions == 1 and info.iterations < 150, info
    assert ukemi.signed_distances(m, nxt).min() > -1e-9
    assert nxt.energy() < s.energy() - 1.0  # the capsule's impact dissipates (J)


def test_pile_198_runs_without_a_failed_step():
    """The whole pile, 100 steps: no unconverged step and nothing deeper than 1 µm (before, its
    step 45 failed 14 mm deep)."""
    m, _ = random_pile(198)
    tr = ukemi.rollout(m, m.make_state(), nsteps=100, on_failure="return")
    assert tr.converged
    assert tr.min_distance.min() > -1e-6
    assert np.max(tr.energy - tr.energy[0]) < 1e-4 * abs(tr.energy[0])

