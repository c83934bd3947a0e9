"""Robot drops at 20 … 1000 Hz: gymnasium's humanoid, the shared humanoid.xml (MuJoCo's own
model) and the zoo quadruped, zero control, lowest point 0.1 m above the floor, 1 s (0.5 s in
the reduced run)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

import ukemi

from ._util import FULL, assert_stable

RATES = (20, 50, 100, 500, 1000) if FULL else (20, 50, 100)
DURATION = 1.0 if FULL else 0.5


def drop(model, hz: int):
    s0 = model.make_state()
    q = np.array(s0.qpos)
    q[2] += 0.1 - ukemi.signed_distances(model, s0).min()
    m = model.with_options(timestep=1.0 / hz)
    return m, ukemi.rollout(m, m.make_state(qpos=q), nsteps=int(hz * DURATION),
                            on_failure="return")


# 2026-11-23, 1 s drops (UKEMI_STRESS=full), after Nesterov–Todd scaling: unconverged steps
# (all line_search_failed). Rates not listed pass: 50 and
# 100 Hz (before the scaling: 1/50 and 1/100 with −18 mm and −13 mm).
HUMANOID_MEASURED = {
    20: "1/20 line_search_failed at step 14",
    50: "converged, but the discrete energy rises 4.5e-4 (relative) in free fall before landing",
    100: "converged, but the discrete energy rises 1.8e-3 (relative, +0.22 J in the first 5 "
         "steps of free fall); the model has armature on jointed limbs, whose discrete term "
         "uses the dof map at the current configuration (exact for a world hinge: 5e-5 J band)",
    500: "2/500 line_search_failed from step 387",
    1000: "2/1000 line_search_failed from step 564, least distance -4.8e-4 m",
}
SHARED_HUMANOID = Path(__file__).resolve().parents[3] / "shared" / "models" / "humanoid.xml"


def _humanoid_case(hz):
    if hz not in HUMANOID_MEASURED or (not FULL and hz == 20):  # the 20 Hz failure is at 0.7 s
        return hz
    return pytest.param(hz, marks=pytest.mark.xfail(strict=False, reason=(
        "known engine limit (README 'Known limits': degenerate multi-contact stalls); "
        f"measured: {HUMANOID_MEASURED[hz]}")))


@pytest.mark.parametrize("hz", [_humanoid_case(hz) for hz in RATES])
def test_humanoid_drop(hz):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium's fluid/solver options
        model = ukemi.Model.from_xml_path(ukemi.gymnasium_asset_path("humanoid"))
    m, tr = drop(model, hz)
    assert_stable(m, tr)


@pytest.mark.skipif(not SHARED_HUMANOID.exists(), reason=f"{SHARED_HUMANOID} not present")
@pytest.mark.parametrize("hz", RATES)
def test_shared_humanoid_drop(hz):
    """Issue #4's acceptance: MuJoCo's humanoid.xml lands and settles at every rate without a
    solver failure, never below −1e-8 m (MuJoCo 4.0.0 on the same file: −3.0 mm at dt 0.01)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # solver options, tendon limits
        model = ukemi.load(str(SHARED_HUMANOID))
    m, tr = drop(model, hz)
    assert_stable(m, tr)


@pytest.mark.parametrize("hz", RATES)
def test_quadruped_drop(hz):
    m, tr = drop(ukemi.models.quadruped(), hz)
    assert_stable(m, tr)
