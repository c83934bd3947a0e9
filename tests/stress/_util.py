"""Scene builders and the common stress assertion for ``tests/stress``.

``UKEMI_STRESS=full`` runs every case at full length; the default is the reduced CI form.
"""

from __future__ import annotations

import os

import numpy as np

import ukemi

FULL = os.environ.get("UKEMI_STRESS", "").lower() == "full"
PENETRATION_TOL = -1e-8  # m: least signed distance allowed
BOX_INERTIA = (1 / 150,) * 3  # 1 kg cube of side 0.2 m


def steps(reduced: int, full: int) -> int:
    """Step count for the current mode."""
    return full if FULL else reduced


def failure_summary(traj) -> str:
    bad = ~np.isin(traj.status, ukemi.SUCCESS_STATUSES)
    if not bad.any():
        return "all converged"
    kinds = {str(k): int(np.sum(traj.status == k)) for k in set(traj.status[bad])}
    return f"{int(bad.sum())}/{len(bad)} unconverged {kinds}, first at step {int(np.argmax(bad))}"


def violations(model, traj, energy_gain: float = 1e-4, work=None, overlap=None) -> list[str]:
    """What breaks the stress contract: solver failures, NaN, penetration below -1e-8 m, energy
    growth. Empty when the run is stable.

    Contacts are inelastic, friction and dampers dissipate, so the discrete energy may rise above
    its initial value plus the actuators' work ``work`` (T+1,) (zero when None) only by
    ``energy_gain`` relative to max(1 J, |E0|). ``overlap``: the deepest overlap of the scene's
    polytopes by the separating-axis test and its state (``_overlap.deepest_overlap``), which
    sees what no contact candidate does.
    """
    out = []
    if not traj.converged:
        out.append(failure_summary(traj))
    if not (np.all(np.isfinite(traj.qpos)) and np.all(np.isfinite(traj.qvel))):
        return [*out, "non-finite state"]
    least = float(traj.min_distance.min())
    if least < PENETRATION_TOL:
        out.append(f"penetration {least:.1e} m at state {int(traj.min_distance.argmin())}")
    if overlap is not None and overlap[0] < PENETRATION_TOL:
        out.append(f"solids overlap {overlap[0]:.1e} m at state {overlap[1]}")
    energy = traj.energy
    if work is not None:
        energy = energy - work
    gain = float(np.max(energy - energy[0])) / max(1.0, abs(energy[0]))
    if gain > energy_gain:
        out.append(f"energy grew by {gain:.1e} (relative)")
    return out


def assert_stable(model, traj, energy_gain: float = 1e-4, converged: bool = True,
                  work=None, overlap=None) -> None:
    """Assert :func:`violations` finds nothing (solver failures ignored if not ``converged``)."""
    found = violations(model, traj, energy_gain, work, overlap)
    if not converged and not traj.converged:
        found = found[1:]
    assert not found, "; ".join(found)


def floor_builder(timestep: float = 0.01, friction: float = 0.5, contact: str = "nonlinear"):
    b = ukemi.ModelBuilder(timestep=timestep)
    b.add_geom("floor", "world", "plane", friction=friction, contact=contact)
    return b


def add_free(b, name: str, shape: str, size, mass: float, inertia, pos, quat=(1, 0, 0, 0),
             friction: float = 0.5) -> None:
    b.add_body(name, mass, inertia, pos=pos, quat=quat)
    b.add_joint(name + "_free", "free", "world", name)
    b.add_geom(name, name, shape, size=size, friction=friction)


def box_stack(n: int, masses=None, gap: float = 1e-4, timestep: float = 0.01):
    """``n`` cubes of side 0.2 m stacked with ``gap`` between them."""
    b = floor_builder(timestep)
    masses = masses or [1.0] * n
    for i, mass in enumerate(masses):
        inertia = tuple(mass * x for x in BOX_INERTIA)
        add_free(b, f"b{i}", "box", (0.1, 0.1, 0.1), mass, inertia,
                 (0, 0, 0.1 + i * (0.2 + gap)))
    return b.compile()
