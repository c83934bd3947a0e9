"""An interior-point attempt that stalls at an acceptable iterate is solved on from that iterate,
its complementarity pairs moved back onto the central path, before any cold retry
(``engine/src/solver/newton.rs``, ``resume_recentred``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from stress._random_scenes import hull_pile_with_solids

import ukemi

DATA = Path(__file__).parent / "data"


def test_a_stall_at_an_acceptable_iterate_is_solved_on_recentred():
    """Random hull pile 114 (``tests/stress``), step 126: five hulls at rest on each other. The
    first attempt stalls 7.7e-10 from the residual tolerance with a friction cone pressed
    against its boundary; the two cold retries that followed failed too, and the step ended
    "acceptable" after 78 iterations (its velocities 3.5e-7 m/s from the converged ones).
    Recentred at κ = 1e-7 the acceptable iterate converges (32 iterations).

    The state is the pile's state before step 126 as the engine of 2026-12-05 (0742db7)
    simulated it, read from its snapshot (warm start included): the steps before are chaotic."""
    m, _, _ = hull_pile_with_solids(114)
    s = m.state_from_snapshot(np.load(DATA / "hullpile114_step126_snapshot.npy"))
    nxt, info = ukemi.step(m, s, None)
    assert info.status == "converged", info
    assert info.iterations < 60, info
    assert info.residual < 1e-10
    assert ukemi.signed_distances(m, nxt).min() > -1e-9
