"""Table V robots (Dojo paper): time per step, iterations and failures under random controls.

Each robot runs ``steps`` steps at dt = 0.01 s (Table V's setting) from its first keyframe (or
its reference pose) with controls drawn uniformly from its control range (seeded, the same for
both engines); then ``grad_steps`` of those steps again with the full minimal-coordinate
Jacobians A, B (``ukemi.step_jacobians``; MuJoCo ``mj_step`` + centred ``mjd_transitionFD``).
MuJoCo loads the same file in the same process; its RK4 integrator, where a file asks for it,
is replaced by Euler (``mjd_transitionFD`` has no RK4). A file ukemi cannot load yet is reported
as unsupported with the loader's message, never an exception.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np

import ukemi
from ukemi.bench import scenes

TABLE_V_DT = 0.01


def robot_files() -> list[tuple[str, Path]]:
    out = [(f"gymnasium {n}", Path(ukemi.gymnasium_asset_path(n)))
           for n in ("hopper", "ant", "humanoid")]
    shared = scenes.shared_models_dir()
    if shared is not None:
        out += [(f"shared {n}", shared / f"{n}.xml") for n in ("a1", "humanoid", "panda", "x2")]
    return out


def load_ukemi(path: Path):
    """(model at dt 0.01, None) or (None, why it cannot be simulated)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # options the engine ignores (fluid, solver)
            return ukemi.Model.from_xml_path(str(path)).with_options(timestep=TABLE_V_DT), None
    except (ukemi.UkemiError, OSError) as e:
        return None, f"{type(e).__name__}: {str(e).splitlines()[0]}"


def random_ctrls(ctrlrange: np.ndarray, steps: int, seed: int = 0) -> np.ndarray:
    """(steps, nu) uniform in each finite control range, else in [-1, 1]."""
    r = np.asarray(ctrlrange, float).reshape(-1, 2)
    lo = np.where(np.isfinite(r[:, 0]), r[:, 0], -1.0)
    hi = np.where(np.isfinite(r[:, 1]), r[:, 1], 1.0)
    return lo + (hi - lo) * np.random.default_rng(seed).random((steps, len(lo)))


def _start(model):
    return model.make_state(key=model.keyframe_names[0]) if model.keyframe_names else \
        model.make_state()


def run_ukemi(model, ctrls: np.ndarray, grad_steps: int) -> dict:
    s0 = _start(model)
    t0 = time.perf_counter()
    tr = ukemi.rollout(model, s0, ctrls, on_failure="return")
    wall = time.perf_counter() - t0
    bad = ~np.isin(tr.status, ukemi.SUCCESS_STATUSES)
    grad_wall, grad_failed = 0.0, 0
    for k in range(grad_steps):
        s = model.make_state(qpos=tr.qpos[k], qvel=tr.qvel[k])
        t0 = time.perf_counter()
        try:
            ukemi.step_jacobians(model, s, ctrls[k], wrt=("state", "ctrl"))
        except ukemi.ConvergenceError:
            grad_failed += 1
        grad_wall += time.perf_counter() - t0
    return {"ms_step": 1e3 * wall / len(ctrls), "it_mean": float(np.mean(tr.iterations)),
            "it_max": int(np.max(tr.iterations)), "failed": int(bad.sum()),
            "fail_kinds": sorted({str(x) for x in tr.status[bad]}),
            "ms_step_grad": 1e3 * grad_wall / max(grad_steps, 1), "grad_failed": grad_failed,
            "least_m": float(tr.min_distance.min())}


def run_mujoco(path: Path, ctrls: np.ndarray, grad_steps: int) -> dict:
    mj = scenes._mujoco()
    m = mj.MjModel.from_xml_path(str(path))
    m.opt.timestep = TABLE_V_DT
    if m.opt.integrator == mj.mjtIntegrator.mjINT_RK4:
        m.opt.integrator = mj.mjtIntegrator.mjINT_EULER

    def reset():
        d = mj.MjData(m)
        if m.nkey:
            mj.mj_resetDataKeyframe(m, d, 0)
        return d

    d, iters = reset(), []
    t0 = time.perf_counter()
    for u in ctrls:
        d.ctrl[:] = u
        mj.mj_step(m, d)
        iters.append(int(d.solver_niter[0]))
    wall = time.perf_counter() - t0
    n = 2 * m.nv + m.na
    A, B = np.zeros((n, n)), np.zeros((n, m.nu))
    d = reset()
    t0 = time.perf_counter()
    for u in ctrls[:grad_steps]:
        d.ctrl[:] = u
        mj.mjd_transitionFD(m, d, 1e-6, 1, A, B, None, None)
        mj.mj_step(m, d)
    grad_wall = time.perf_counter() - t0
    return {"ms_step": 1e3 * wall / len(ctrls), "it_mean": float(np.mean(iters)),
            "it_max": int(np.max(iters)), "ms_step_grad": 1e3 * grad_wall / max(grad_steps, 1)}


def run(steps: int, grad_steps: int, log=print) -> list[dict]:
    rows = []
    for name, path in robot_files():
        model, why = load_ukemi(path)
        base = {"robot": name, "file": str(path), "steps": steps, "grad_steps": grad_steps}
        mj_nu = None
        if scenes._mujoco() is not None and path.exists():
            mjm = scenes._mujoco().MjModel.from_xml_path(str(path))
            mj_nu, ctrlrange = mjm.nu, np.array(mjm.actuator_ctrlrange)
            ctrlrange[~mjm.actuator_ctrllimited.astype(bool)] = (-np.inf, np.inf)
        if model is not None:
            ctrlrange = np.array(model.actuator_ctrlrange) if model.nu else np.zeros((0, 2))
        ctrls = random_ctrls(ctrlrange, steps) if (model is not None or mj_nu is not None) \
            else None
        if model is None:
            rows.append({**base, "engine": "ukemi", "unsupported": why})
            log(f"table V   {name:<18} ukemi  unsupported: {why}")
        else:
            r = {**base, "engine": "ukemi", "nv": model.nv, **run_ukemi(model, ctrls, grad_steps)}
            rows.append(r)
            log(f"table V   {name:<18} ukemi  {r['ms_step']:8.2f} ms/step  it {r['it_mean']:.1f}"
                f" (max {r['it_max']})  failed {r['failed']}/{steps}  +A,B "
                f"{r['ms_step_grad']:.2f} ms/step ({r['grad_failed']}/{grad_steps} failed)")
        if mj_nu is not None:
            r = {**base, "engine": "mujoco", "nv": int(mjm.nv),
                 **run_mujoco(path, ctrls, grad_steps)}
            rows.append(r)
            log(f"table V   {name:<18} mujoco {r['ms_step']:8.2f} ms/step  it {r['it_mean']:.1f}"
                f" (max {r['it_max']})  +A,B {r['ms_step_grad']:.2f} ms/step")
    return rows


def markdown(rows: list[dict]) -> str:
    out = ["| robot | engine | nv | ms/step | it/step mean (max) | failed/steps | "
           "ms/step with A, B | failed gradients |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "unsupported" in r:
            out.append(f"| {r['robot']} | {r['engine']} | – | unsupported: "
                       f"{r['unsupported'][:160]} | | | | |")
            continue
        kinds = f" ({', '.join(r['fail_kinds'])})" if r.get("fail_kinds") else ""
        failed = f"{r['failed']}/{r['steps']}{kinds}" if r["engine"] == "ukemi" else "–"
        gfail = f"{r['grad_failed']}/{r['grad_steps']}" if r["engine"] == "ukemi" else "–"
        out.append(f"| {r['robot']} | {r['engine']} | {r['nv']} | {r['ms_step']:.3g} | "
                   f"{r['it_mean']:.1f} ({r['it_max']}) | {failed} | {r['ms_step_grad']:.3g} | "
                   f"{gfail} |")
    return "\n".join(out) + "\n"
