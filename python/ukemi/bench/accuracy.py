"""What accuracy costs: time step and tolerance sweeps, ukemi against MuJoCo (issue #8).

Scenes (built in :mod:`ukemi.bench.scenes`):

* ``sliding box``: a 0.2 m box launched at v0 = 2 m/s at 30° to the axes on a μ = 0.5 floor
  (Dojo Fig. 5). Errors: lateral drift off the launch direction, stopping distance against
  v0²/(2μg). ukemi's nonlinear (second-order) and linear (pyramid) cones; MuJoCo's elliptic and
  pyramidal cones on the equivalent MJCF.
* ``humanoid drop``: gymnasium's humanoid and the shared ``humanoid.xml`` (once ukemi loads
  it), zero control, lowest point 0.1 m up (Dojo Fig. 7). Least signed distance during landing
  (first half) and at the end (last 0.25 s), torso height.
* ``tumbling body`` (zero gravity, spin near the intermediate axis) and ``pendulum`` (an undamped
  double pendulum): relative energy and angular-momentum drift over ``nsteps`` steps; MuJoCo with
  its Euler and RK4 integrators.

Each row reports wall time per simulated second, mean iterations per step and solver failures
(status other than ``converged``, counted, never dropped). MuJoCo's "iterations" are its own
constraint-solver iterations. Two more studies run in the same command: gradients against
``kappa_grad`` (:mod:`ukemi.bench.smoothing`) and the Table V robots (:mod:`ukemi.bench.robots`).

    python -m ukemi.cli bench accuracy [--quick] [--out results/] [--update-benchmarks FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from ukemi.bench import report, robots, scenes, smoothing

DTS_FULL = (0.1, 0.05, 0.02, 0.01, 0.005, 0.002, 0.001)
TOLS_FULL = (1e-2, 1e-4, 1e-6, 1e-8, 1e-10)
SECTIONS = ("sweep", "kappa_grad", "robots")


@dataclass
class Plan:
    """What to run. ``quick`` is the CI configuration (under 2 minutes on 2 cores)."""

    quick: bool = False
    slide_dts: tuple = DTS_FULL
    drop_dts: tuple = DTS_FULL
    energy_dts: tuple = (0.1, 0.03, 0.01, 0.003, 0.001)
    tols: tuple = TOLS_FULL
    drop_tols: tuple = TOLS_FULL
    slide_duration: float = 1.0
    drop_duration: float = 1.5
    energy_steps: int = 10_000
    robot_steps: int = 200
    robot_grad_steps: int = 20
    sections: tuple = SECTIONS
    engines: dict = field(default_factory=dict)

    @classmethod
    def make_quick(cls) -> Plan:
        return cls(quick=True, drop_dts=(0.1, 0.05, 0.02, 0.01, 0.002),
                   drop_tols=(1e-2, 1e-8), energy_steps=2_000, robot_steps=30,
                   robot_grad_steps=3)


TOL_DT = 0.01  # time step of the tolerance sweeps
DROP = "humanoid drop"
UKEMI_VARIANTS = {"sliding box": ("nonlinear", "linear"), DROP: ("nonlinear",),
                  "tumbling body": ("-",), "pendulum": ("-",)}
MUJOCO_VARIANTS = {"sliding box": ("elliptic", "pyramidal"), DROP: ("elliptic", "pyramidal"),
                   "tumbling body": ("Euler", "RK4"), "pendulum": ("Euler", "RK4")}


def _settings(scene: str, plan: Plan, tol_sweep: bool = True):
    """(sweep, dt, tol) triples: the time-step sweep at default tolerances, then the
    tolerance sweep (rtol = kappa_tol = tol) at TOL_DT."""
    dts = {"sliding box": plan.slide_dts, DROP: plan.drop_dts}.get(scene, plan.energy_dts)
    tols = (plan.drop_tols if scene == DROP else plan.tols) if tol_sweep else ()
    return [("dt", dt, None) for dt in dts] + [("tol", TOL_DT, t) for t in tols]


def _humanoids(log) -> tuple[list, list[str]]:
    """[(label, path, ukemi model)] that load, and a note per humanoid that does not."""
    ok, notes = [], []
    for label, path in scenes.humanoid_files():
        model, why = scenes.load_humanoid(path)
        if model is None:
            notes.append(f"{label} ({path}): unsupported by ukemi today, skipped: {why}")
            log(f"humanoid drop: {notes[-1]}")
        else:
            ok.append((label, path, model))
    return ok, notes


def sweep(plan: Plan, log=print) -> tuple[list[dict], list[str]]:
    """Run every scene, engine and setting; return one row (dict) per run, and notes."""
    have_mujoco = scenes._mujoco() is not None
    humanoids, notes = _humanoids(log)
    jobs = []  # (scene label, scene kind, settings, runner(engine, variant, dt, tol))
    for scene in UKEMI_VARIANTS:
        if scene != DROP:
            jobs.append((scene, scene, _settings(scene, plan), None))
            continue
        for i, (label, path, model) in enumerate(humanoids):
            name = DROP if label == "gymnasium" else f"{DROP}, {label}"
            # the tolerance sweep runs on the first humanoid only
            jobs.append((name, DROP, _settings(DROP, plan, tol_sweep=i == 0), (model, path)))
    rows = []
    for name, kind, settings, humanoid in jobs:
        for sweep_kind, dt, tol in settings:
            runs = [("ukemi", v) for v in UKEMI_VARIANTS[kind]]
            if have_mujoco and sweep_kind == "dt":
                runs += [("mujoco", v) for v in MUJOCO_VARIANTS[kind]]
            for engine, variant in runs:
                if kind == "sliding box":
                    r = scenes.run_slide(engine, variant, dt, tol, plan.slide_duration)
                elif kind == DROP:
                    r = scenes.run_humanoid(engine, variant, dt, tol, plan.drop_duration,
                                            humanoid[0], humanoid[1])
                else:
                    r = scenes.run_energy(kind, engine, variant, dt, tol, plan.energy_steps)
                r.update(scene=name, kind=kind, engine=engine, variant=variant,
                         sweep=sweep_kind, dt=dt, tol=tol, per_sim_s=r["wall"] / r["sim"])
                rows.append(r)
                log(report.log_line(r))
    return rows, notes


def run(plan: Plan, log=print) -> dict:
    """Every section of the plan: {"sweep", "notes", "kappa_grad", "robots", "seconds"}."""
    out: dict = {"seconds": {}}
    for section in plan.sections:
        t0 = time.perf_counter()
        if section == "sweep":
            out["sweep"], out["notes"] = sweep(plan, log)
        elif section == "kappa_grad":
            out["kappa_grad"] = smoothing.run(plan.quick, log)
        elif section == "robots":
            out["robots"] = robots.run(plan.robot_steps, plan.robot_grad_steps, log)
        out["seconds"][section] = time.perf_counter() - t0
    return out


# ----------------------------------------------------------------------------- entry point
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="ukemi bench accuracy", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="reduced sweep (the CI configuration)")
    ap.add_argument("--out", default="results", help="results folder (default: results/)")
    ap.add_argument("--sections", default=",".join(SECTIONS),
                    help=f"comma-separated subset of {','.join(SECTIONS)}")
    ap.add_argument("--update-benchmarks", metavar="FILE", default=None,
                    help="replace the block between <!-- accuracy:begin --> and "
                         "<!-- accuracy:end --> in FILE (e.g. BENCHMARKS.md) with the report")
    args = ap.parse_args(argv)
    sections = tuple(s for s in args.sections.split(",") if s)
    bad = [s for s in sections if s not in SECTIONS]
    if bad:
        ap.error(f"--sections: unknown {bad}; choose from {SECTIONS}")
    plan = Plan.make_quick() if args.quick else Plan()
    plan.sections = sections
    if args.update_benchmarks:  # fail before the run, not after it
        report.check_markers(Path(args.update_benchmarks))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    result = run(plan)
    total = time.perf_counter() - t0
    cmd = "python -m ukemi.cli bench accuracy" + (" --quick" if args.quick else "")
    if sections != SECTIONS:
        cmd += f" --sections {','.join(sections)}"
    text = report.markdown(result, plan, f"{cmd} --out {args.out}", total, os.cpu_count())
    (out / "accuracy.md").write_text(text)
    (out / "accuracy.json").write_text(json.dumps(report.to_json(result), indent=1,
                                                  default=float))
    try:
        pngs = report.plot(result, out)
    except ImportError:
        pngs = []
        print("matplotlib is not installed: no plots")
    if args.update_benchmarks:
        report.update_block(Path(args.update_benchmarks), text, pngs, out)
    print(f"wrote {out / 'accuracy.md'}, {out / 'accuracy.json'}, "
          f"{', '.join(str(p) for p in pngs)} in {total:.0f} s")
    return 0
