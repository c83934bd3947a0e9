"""Benchmark scenes built twice: as a ukemi model and as the equivalent MuJoCo MJCF.

Every function returns plain numbers per setting (no plotting, no printing) so the sweep in
:mod:`ukemi.bench.accuracy` can tabulate ukemi and MuJoCo rows side by side.
"""

from __future__ import annotations

import os
import time
import warnings
from pathlib import Path

import numpy as np

import ukemi

GRAVITY = 9.81
SLIDE_MU, SLIDE_V0, SLIDE_ANGLE = 0.5, 2.0, np.pi / 6
SLIDE_DIR = np.array([np.cos(SLIDE_ANGLE), np.sin(SLIDE_ANGLE), 0.0])
SLIDE_STOP = SLIDE_V0**2 / (2 * SLIDE_MU * GRAVITY)  # analytic stopping distance (m)
HUMANOID_DROP = 0.1  # lowest point above the floor at t = 0 (m)
TUMBLE_INERTIA = (1.0, 2.0, 2.5)
TUMBLE_ANGVEL = (0.1, 5.0, 0.1)  # near the intermediate axis: Dzhanibekov flips
PEND_QPOS = (1.2, -0.5)


def _mujoco():
    try:
        import mujoco
    except ImportError:  # comparison rows are optional
        return None
    return mujoco


# ----------------------------------------------------------------------------- sliding box
def slide_ukemi(dt: float, cone: str, tol: float | None = None):
    b = ukemi.ModelBuilder(timestep=dt)
    b.add_geom("floor", "world", "plane", friction=SLIDE_MU, contact=cone)
    b.add_body("box", 1.0, (1 / 150,) * 3, pos=(0, 0, 0.1))
    b.add_joint("free", "free", "world", "box")
    b.add_geom("box", "box", "box", size=(0.1, 0.1, 0.1), friction=SLIDE_MU, contact=cone)
    m = b.compile()
    return m if tol is None else m.with_options(rtol=tol, kappa_tol=tol)


SLIDE_MJCF = """<mujoco><option timestep="{dt}" cone="{cone}"/><worldbody>
<geom type="plane" size="5 5 .1" friction="{mu} 0 0" condim="3"/>
<body name="box" pos="0 0 0.1"><freejoint/>
<geom type="box" size=".1 .1 .1" mass="1" friction="{mu} 0 0" condim="3"/></body>
</worldbody></mujoco>"""


def _slide_metrics(disp: np.ndarray, min_dist: float) -> dict:
    along = float(disp @ SLIDE_DIR)
    return {"drift_m": float(np.linalg.norm(disp - along * SLIDE_DIR)),
            "stop_err": along / SLIDE_STOP - 1.0, "min_dist_m": min_dist}


def run_slide(engine: str, variant: str, dt: float, tol: float | None, duration: float) -> dict:
    n = int(round(duration / dt))
    qvel = [*(SLIDE_V0 * SLIDE_DIR), 0, 0, 0]
    if engine == "ukemi":
        m = slide_ukemi(dt, variant, tol)
        # the velocity at t = 0, as MuJoCo's qvel (the default would be the midpoint velocity
        # of the step before, which starts the slide half a step late: -v0 h / 2)
        s0 = m.make_state(qvel=qvel, velocity="instant")
        t0 = time.perf_counter()
        tr = ukemi.rollout(m, s0, nsteps=n, on_failure="return")
        wall = time.perf_counter() - t0
        out = _slide_metrics(tr.body_pos[-1, 1] - tr.body_pos[0, 1], float(tr.min_distance.min()))
        return {**out, **_solver_stats(tr), "wall": wall, "sim": n * dt}
    mj = _mujoco()
    m = mj.MjModel.from_xml_string(SLIDE_MJCF.format(dt=dt, cone=variant, mu=SLIDE_MU))
    d = mj.MjData(m)
    d.qvel[:] = qvel
    mj.mj_forward(m, d)
    pos0, least = d.qpos[:3].copy(), np.inf
    for _ in range(n):
        mj.mj_step(m, d)
        least = min(least, _mj_least(d))
    out = _slide_metrics(d.qpos[:3] - pos0, least)
    return {**out, **_mj_timing(mj, m, lambda dd: dd.qvel.__setitem__(slice(None), qvel), n),
            "sim": n * dt}


# ----------------------------------------------------------------------------- humanoid drop
def shared_models_dir() -> Path | None:
    """The project's shared robot models: $UKEMI_MODELS_DIR, else ../shared/models next to the
    repository this package was imported from; None if neither exists."""
    env = os.environ.get("UKEMI_MODELS_DIR")
    candidates = [Path(env)] if env else []
    candidates.append(Path(__file__).resolve().parents[3].parent / "shared" / "models")
    return next((c for c in candidates if c.is_dir()), None)


def humanoid_files() -> list[tuple[str, Path]]:
    """(label, MJCF path) of the humanoids to drop: gymnasium's, and the shared humanoid.xml."""
    out = [("gymnasium", Path(ukemi.gymnasium_asset_path("humanoid")))]
    shared = shared_models_dir()
    if shared is not None and (shared / "humanoid.xml").exists():
        out.append(("shared humanoid.xml", shared / "humanoid.xml"))
    return out


def load_humanoid(path: Path):
    """(ukemi model, None) or (None, the loader's reason) when ukemi cannot simulate it yet."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # fluid/solver options the engine ignores
            return ukemi.Model.from_xml_path(str(path)), None
    except (ukemi.UkemiError, OSError) as e:
        return None, f"{type(e).__name__}: {str(e).splitlines()[0]}"


def _humanoid_ukemi():
    return load_humanoid(humanoid_files()[0][1])[0]


def humanoid_qpos0(m0) -> np.ndarray:
    """Gymnasium humanoid's default pose raised so its lowest point is HUMANOID_DROP up."""
    s0 = m0.make_state()
    q = np.array(s0.qpos)
    q[2] += HUMANOID_DROP - ukemi.signed_distances(m0, s0).min()
    return q


def _drop_metrics(t: np.ndarray, least: np.ndarray, torso_z: np.ndarray, land: float) -> dict:
    rest = t >= t[-1] - 0.25
    return {"min_dist_landing_m": float(least[t <= land].min()),
            "min_dist_rest_m": float(least[rest].min()),
            "torso_z_end_m": float(torso_z[-1]), "torso_t": t, "torso_z": torso_z}


def run_humanoid(engine: str, variant: str, dt: float, tol: float | None, duration: float,
                 base=None, path: Path | None = None) -> dict:
    n = int(round(duration / dt))
    if engine == "ukemi":
        m = base.with_options(timestep=dt)
        if tol is not None:
            m = m.with_options(rtol=tol, kappa_tol=tol)
        q = humanoid_qpos0(base)
        t0 = time.perf_counter()
        tr = ukemi.rollout(m, m.make_state(qpos=q), nsteps=n, on_failure="return")
        wall = time.perf_counter() - t0
        torso = list(m.body_names).index("torso")
        floor = np.array(["floor" in pair[:2] for pair in m.contact_pairs])
        least = np.array([ukemi.signed_distances(m, m.make_state(qpos=qp))[floor].min()
                          for qp in tr.qpos])
        out = _drop_metrics(tr.time, least, tr.body_pos[:, torso, 2], 0.5 * duration)
        out["fail_t"] = tr.time[:-1][~np.isin(tr.status, ukemi.SUCCESS_STATUSES)]
        return {**out, **_solver_stats(tr), "wall": wall, "sim": n * dt}
    mj = _mujoco()
    m = mj.MjModel.from_xml_path(str(path or ukemi.gymnasium_asset_path("humanoid")))
    m.opt.timestep, m.opt.cone = dt, _mj_cone(mj, variant)
    q = humanoid_qpos0(base)
    d = mj.MjData(m)
    d.qpos[:] = q
    torso = mj.mj_name2id(m, mj.mjtObj.mjOBJ_BODY, "torso")
    floor = mj.mj_name2id(m, mj.mjtObj.mjOBJ_GEOM, "floor")
    ts, least, tz, diverged = [], [], [], None
    for k in range(n):
        mj.mj_step(m, d)  # contacts of the state the step started from
        if d.warning[mj.mjtWarning.mjWARN_BADQACC].number:
            diverged = k * dt  # MuJoCo resets the data after a bad acceleration: stop here
            break
        ts.append(d.time - dt)
        least.append(_mj_least(d, floor=floor))
        tz.append(d.xpos[torso, 2])
    out = _drop_metrics(np.array(ts), np.array(least), np.array(tz), 0.5 * duration) if ts \
        else {"min_dist_landing_m": float("nan"), "min_dist_rest_m": float("nan"),
              "torso_z_end_m": float("nan"), "torso_t": np.zeros(0), "torso_z": np.zeros(0)}
    out["diverged_t"] = diverged
    return {**out, **_mj_timing(mj, m, lambda dd: dd.qpos.__setitem__(slice(None), q), n),
            "sim": n * dt}


# ----------------------------------------------------------------------------- energy scenes
def tumble_ukemi(dt: float, tol: float | None = None):
    b = ukemi.ModelBuilder(timestep=dt, gravity=(0, 0, 0))
    b.add_body("body", 2.0, TUMBLE_INERTIA, pos=(0, 0, 1))
    b.add_joint("free", "free", "world", "body")
    m = b.compile()
    return m if tol is None else m.with_options(rtol=tol)


def pendulum_ukemi(dt: float, tol: float | None = None):
    b = ukemi.ModelBuilder(timestep=dt)
    for i in range(2):
        b.add_body(f"l{i}", 1.0, (0.09, 0.09, 0.005), pos=(0, 0, -0.5 - i))
        b.add_joint(f"j{i}", "revolute", "world" if i == 0 else f"l{i - 1}", f"l{i}",
                    axis=(0, 1, 0), parent_anchor=(0, 0, 0) if i == 0 else (0, 0, -0.5),
                    child_anchor=(0, 0, 0.5))
    m = b.compile()
    return m if tol is None else m.with_options(rtol=tol)


TUMBLE_MJCF = """<mujoco><option timestep="{dt}" gravity="0 0 0" integrator="{integ}">
<flag energy="enable"/></option><worldbody><body pos="0 0 1"><freejoint/>
<inertial pos="0 0 0" mass="2" diaginertia="{I}"/></body></worldbody></mujoco>"""

PEND_MJCF = """<mujoco><option timestep="{dt}" integrator="{integ}"><flag energy="enable"/></option>
<worldbody><body><joint type="hinge" axis="0 1 0"/>
<inertial pos="0 0 -0.5" mass="1" diaginertia="0.09 0.09 0.005"/>
<body pos="0 0 -1"><joint type="hinge" axis="0 1 0"/>
<inertial pos="0 0 -0.5" mass="1" diaginertia="0.09 0.09 0.005"/></body></body>
</worldbody></mujoco>"""


def _drift(series: np.ndarray) -> float:
    ref = series[0]
    scale = max(float(np.linalg.norm(ref)), 1e-12)
    return float(np.max(np.linalg.norm(series - ref, axis=-1) if series.ndim > 1
                        else np.abs(series - ref)) / scale)


def run_energy(scene: str, engine: str, variant: str, dt: float, tol: float | None,
               nsteps: int) -> dict:
    if engine == "ukemi":
        if scene == "tumbling body":
            m = tumble_ukemi(dt, tol)
            s = m.make_state(qvel=[0, 0, 0, *TUMBLE_ANGVEL])
        else:
            m = pendulum_ukemi(dt, tol)
            s = m.make_state(qpos=PEND_QPOS)
        t0 = time.perf_counter()
        tr = ukemi.rollout(m, s, nsteps=nsteps, on_failure="return")
        wall = time.perf_counter() - t0
        energy, mom = _ukemi_invariants(m, tr, scene)
        return {"energy_drift": _drift(energy), "momentum_drift": _drift(mom),
                **_solver_stats(tr), "wall": wall, "sim": nsteps * dt}
    mj = _mujoco()
    xml = TUMBLE_MJCF if scene == "tumbling body" else PEND_MJCF
    m = mj.MjModel.from_xml_string(xml.format(dt=dt, integ=variant,
                                              I=" ".join(map(str, TUMBLE_INERTIA))))
    d = mj.MjData(m)
    init = _mj_init_energy_scene(scene)
    init(d)
    mj.mj_forward(m, d)
    energy, mom = [], []
    for _ in range(nsteps + 1):
        energy.append(d.energy.sum())
        mom.append(_mj_angmom(d) if scene == "tumbling body" else 0.0)
        mj.mj_step(m, d)
    mom_drift = _drift(np.array(mom)) if scene == "tumbling body" else float("nan")
    return {"energy_drift": _drift(np.array(energy)), "momentum_drift": mom_drift,
            **_mj_timing(mj, m, init, nsteps), "sim": nsteps * dt}


def _ukemi_invariants(m, tr, scene: str):
    """Energy (and angular momentum for the free body) of every state of a rollout."""
    energy, mom = [], []
    for qpos, qvel in zip(tr.qpos, tr.qvel, strict=True):
        s = m.make_state(qpos=qpos, qvel=qvel)
        energy.append(s.energy())
        mom.append(s.angular_momentum() if scene == "tumbling body" else 0.0)
    return np.array(energy), np.array(mom)


def _mj_init_energy_scene(scene: str):
    def init(d):
        if scene == "tumbling body":
            d.qvel[3:] = TUMBLE_ANGVEL
        else:
            d.qpos[:] = PEND_QPOS
    return init


def _mj_angmom(d) -> np.ndarray:
    # L = R I ω_b (the body's COM is at rest in zero gravity)
    mat = d.xmat[1].reshape(3, 3)
    return mat @ (np.array(TUMBLE_INERTIA) * d.qvel[3:6])


# ----------------------------------------------------------------------------- helpers
def _solver_stats(tr) -> dict:
    return {"iters": float(np.mean(tr.iterations)) if len(tr.iterations) else 0.0,
            "failed": int(np.sum(~np.isin(tr.status, ukemi.SUCCESS_STATUSES))), "steps": int(len(tr.status)),
            "fail_kinds": sorted({str(s) for s in tr.status if s not in ukemi.SUCCESS_STATUSES})}


def _mj_least(d, floor: int | None = None) -> float:
    """Least contact distance of MuJoCo's active contacts (only those with geom ``floor``)."""
    dist = d.contact.dist[: d.ncon]
    if floor is not None:
        geom = d.contact.geom[: d.ncon]
        dist = dist[(geom[:, 0] == floor) | (geom[:, 1] == floor)]
    return float(dist.min()) if len(dist) else np.inf


def _mj_cone(mj, variant: str):
    return mj.mjtCone.mjCONE_ELLIPTIC if variant == "elliptic" else mj.mjtCone.mjCONE_PYRAMIDAL


def _mj_timing(mj, m, init, n: int) -> dict:
    """Uninstrumented MuJoCo loop (Python's per-call overhead, ~1 µs, included)."""
    d = mj.MjData(m)
    init(d)
    iters = 0
    t0 = time.perf_counter()
    for _ in range(n):
        mj.mj_step(m, d)
        iters += d.solver_niter[0]
    return {"wall": time.perf_counter() - t0, "iters": iters / max(n, 1), "failed": 0,
            "steps": n, "fail_kinds": []}
