"""What accuracy costs: time step and tolerance sweeps, ukemi against MuJoCo (issue #8).

Scenes (built in :mod:`ukemi.bench.scenes`):

* ``sliding box``: a 0.2 m box launched at v0 = 2 m/s at 30° to the axes on a μ = 0.5 floor
  (Dojo Fig. 5). Errors: lateral drift off the launch direction, stopping distance against
  v0²/(2μg). ukemi's nonlinear (second-order) and linear (pyramid) cones; MuJoCo's elliptic and
  pyramidal cones on the equivalent MJCF.
* ``humanoid drop``: gymnasium's humanoid, zero control, lowest point 0.1 m up (Dojo Fig. 7).
  Least signed distance during landing (first half) and at the end (last 0.25 s), torso height.
* ``tumbling body`` (zero gravity, spin near the intermediate axis) and ``pendulum`` (an undamped
  double pendulum): relative energy and angular-momentum drift over ``nsteps`` steps; MuJoCo with
  its Euler and RK4 integrators.

Each row reports wall time per simulated second, mean iterations per step and solver failures
(status other than ``converged``, counted, never dropped). MuJoCo's "iterations" are its own
constraint-solver iterations.

    python -m ukemi.cli bench accuracy [--quick] [--out results/]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ukemi.bench import scenes

DTS_FULL = (0.1, 0.05, 0.02, 0.01, 0.005, 0.002, 0.001)
TOLS_FULL = (1e-2, 1e-4, 1e-6, 1e-8, 1e-10)


@dataclass
class Plan:
    """What to sweep. ``quick`` is the CI configuration (a few minutes on 2 cores)."""

    slide_dts: tuple = DTS_FULL
    drop_dts: tuple = DTS_FULL
    energy_dts: tuple = (0.1, 0.03, 0.01, 0.003, 0.001)
    tols: tuple = TOLS_FULL
    drop_tols: tuple = TOLS_FULL
    slide_duration: float = 1.0
    drop_duration: float = 1.5
    energy_steps: int = 10_000
    engines: dict = field(default_factory=dict)

    @classmethod
    def quick(cls) -> Plan:
        return cls(drop_dts=(0.1, 0.05, 0.02, 0.01, 0.005), energy_steps=2_000)


TOL_DT = 0.01  # time step of the tolerance sweeps
UKEMI_VARIANTS = {"sliding box": ("nonlinear", "linear"), "humanoid drop": ("nonlinear",),
                  "tumbling body": ("-",), "pendulum": ("-",)}
MUJOCO_VARIANTS = {"sliding box": ("elliptic", "pyramidal"),
                   "humanoid drop": ("elliptic", "pyramidal"),
                   "tumbling body": ("Euler", "RK4"), "pendulum": ("Euler", "RK4")}


def _run_one(scene: str, engine: str, variant: str, dt: float, tol, plan: Plan, base) -> dict:
    if scene == "sliding box":
        return scenes.run_slide(engine, variant, dt, tol, plan.slide_duration)
    if scene == "humanoid drop":
        return scenes.run_humanoid(engine, variant, dt, tol, plan.drop_duration, base)
    return scenes.run_energy(scene, engine, variant, dt, tol, plan.energy_steps)


def _settings(scene: str, plan: Plan):
    """(sweep, dt, tol) triples: the time-step sweep at default tolerances, then the
    tolerance sweep (rtol = kappa_tol = tol) at TOL_DT."""
    dts = {"sliding box": plan.slide_dts, "humanoid drop": plan.drop_dts}.get(scene,
                                                                              plan.energy_dts)
    tols = plan.drop_tols if scene == "humanoid drop" else plan.tols
    return [("dt", dt, None) for dt in dts] + [("tol", TOL_DT, t) for t in tols]


def sweep(plan: Plan, log=print) -> list[dict]:
    """Run every scene, engine and setting; return one row (dict) per run."""
    have_mujoco = scenes._mujoco() is not None
    base = scenes._humanoid_ukemi()
    rows = []
    for scene in UKEMI_VARIANTS:
        for kind, dt, tol in _settings(scene, plan):
            runs = [("ukemi", v) for v in UKEMI_VARIANTS[scene]]
            if have_mujoco and kind == "dt":
                runs += [("mujoco", v) for v in MUJOCO_VARIANTS[scene]]
            for engine, variant in runs:
                r = _run_one(scene, engine, variant, dt, tol, plan, base)
                r.update(scene=scene, engine=engine, variant=variant, sweep=kind, dt=dt,
                         tol=tol, per_sim_s=r["wall"] / r["sim"])
                rows.append(r)
                log(_log_line(r))
    return rows


def _log_line(r: dict) -> str:
    tol = "default" if r["tol"] is None else f"{r['tol']:.0e}"
    return (f"{r['scene']:<14} {r['engine']:<6} {r['variant']:<9} dt={r['dt']:<6g} tol={tol:<8}"
            f" {r['per_sim_s']:9.4f} s/sim-s  it {r['iters']:5.2f}  failed {r['failed']}/"
            f"{r['steps']}  err {primary_error(r):.3g}")


def primary_error(r: dict) -> float:
    """The error plotted against cost, per scene."""
    if r["scene"] == "sliding box":
        return abs(r["stop_err"])
    if r["scene"] == "humanoid drop":
        return max(-r["min_dist_landing_m"], 0.0)
    return r["energy_drift"]


ERROR_LABEL = {"sliding box": "|stopping-distance error| (relative)",
               "humanoid drop": "penetration during landing (m)",
               "tumbling body": "max relative energy drift",
               "pendulum": "max relative energy drift"}


# ----------------------------------------------------------------------------- Markdown
def _g(x, fmt=".2e") -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    if isinstance(x, float) and math.isinf(x):
        return "no contact"
    return format(x, fmt)


COLUMNS = {
    "sliding box": [("lateral drift (m)", lambda r: _g(r["drift_m"])),
                    ("stop-distance error", lambda r: f"{100 * r['stop_err']:+.2f}%"),
                    ("least distance (m)", lambda r: _g(r["min_dist_m"]))],
    "humanoid drop": [("least floor distance, landing (m)",
                       lambda r: _g(r["min_dist_landing_m"])),
                      ("least floor distance, last 0.25 s (m)",
                       lambda r: _g(r["min_dist_rest_m"])),
                      ("torso z end (m)", lambda r: _g(r["torso_z_end_m"], ".3f"))],
    "tumbling body": [("energy drift", lambda r: _g(r["energy_drift"])),
                      ("ang. momentum drift", lambda r: _g(r["momentum_drift"]))],
    "pendulum": [("energy drift", lambda r: _g(r["energy_drift"]))],
}


def _failed(r: dict) -> str:
    if r["engine"] != "ukemi":
        return "–"
    kinds = f" ({', '.join(r['fail_kinds'])})" if r["fail_kinds"] else ""
    return f"{r['failed']}/{r['steps']}{kinds}"


def markdown(rows: list[dict], header: str = "") -> str:
    out = [header] if header else []
    for scene, cols in COLUMNS.items():
        sel = [r for r in rows if r["scene"] == scene]
        if not sel:
            continue
        names = ["engine", "cone/integrator", "dt (s)", "tol", "s per sim-s", "it/step",
                 "failed/steps", *[c for c, _ in cols]]
        out += [f"\n**{scene}**\n", "| " + " | ".join(names) + " |",
                "|" + "---|" * len(names)]
        for r in sel:
            tol = "default" if r["tol"] is None else f"{r['tol']:.0e}"
            cells = [r["engine"], r["variant"], f"{r['dt']:g}", tol, _g(r["per_sim_s"], ".3g"),
                     _g(r["iters"], ".2f"), _failed(r), *[f(r) for _, f in cols]]
            out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------- plots
def plot(rows: list[dict], out: Path) -> list[Path]:
    """One PNG per scene (error against wall time per simulated second, one curve per engine and
    cone/integrator and sweep) plus the humanoid's torso height per time step."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for scene in UKEMI_VARIANTS:
        fig, ax = plt.subplots(figsize=(6, 4.5))
        groups = {}
        for r in rows:
            if r["scene"] == scene:
                groups.setdefault((r["engine"], r["variant"], r["sweep"]), []).append(r)
        for (engine, variant, kind), rs in groups.items():
            x = [r["per_sim_s"] for r in rs]
            y = [max(primary_error(r), 1e-16) for r in rs]
            label = f"{engine} {variant if variant != '-' else ''} ({kind} sweep)"
            ax.loglog(x, y, "o-" if kind == "dt" else "s--", label=label)
            for r, xi, yi in zip(rs, x, y, strict=True):
                tag = f"{r['dt']:g}" if kind == "dt" else f"{r['tol']:.0e}"
                tag += f" ✗{r['failed']}" if r.get("failed") else ""
                ax.annotate(tag, (xi, yi), fontsize=6, alpha=0.7)
        ax.set_xlabel("wall time per simulated second (s)")
        ax.set_ylabel(ERROR_LABEL[scene] + " (floored at 1e-16)")
        ax.set_title(f"{scene}: error vs cost (✗n = n unconverged steps)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        p = out / f"accuracy_{scene.replace(' ', '_')}.png"
        fig.tight_layout()
        fig.savefig(p, dpi=120)
        plt.close(fig)
        paths.append(p)
    paths.append(_plot_torso(rows, out, plt))
    return paths


def _plot_torso(rows, out: Path, plt) -> Path:
    fig, ax = plt.subplots(figsize=(6, 4))
    for r in rows:
        if r["scene"] == "humanoid drop" and r["sweep"] == "dt":
            ls = "-" if r["engine"] == "ukemi" else ":"
            ax.plot(r["torso_t"], r["torso_z"], ls,
                    label=f"{r['engine']} {r['variant']} dt={r['dt']:g}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("torso height (m)")
    ax.set_title("humanoid drop: torso height (Dojo Fig. 7)")
    ax.legend(fontsize=6, ncol=2)
    p = out / "accuracy_humanoid_torso.png"
    fig.tight_layout()
    fig.savefig(p, dpi=120)
    plt.close(fig)
    return p


# ----------------------------------------------------------------------------- entry point
def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="ukemi bench accuracy", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="reduced sweep (the CI configuration)")
    ap.add_argument("--out", default="results", help="results folder (default: results/)")
    args = ap.parse_args(argv)
    plan = Plan.quick() if args.quick else Plan()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = sweep(plan)
    total = time.perf_counter() - t0
    cmd = "python -m ukemi.cli bench accuracy" + (" --quick" if args.quick else "")
    header = (f"`{cmd} --out {args.out}` ({os.cpu_count()} cores, {total:.0f} s in all; "
              f"sliding box {plan.slide_duration} s, humanoid drop {plan.drop_duration} s, "
              f"energy scenes {plan.energy_steps} steps; tolerance sweeps at dt = {TOL_DT} "
              f"with rtol = kappa_tol = tol)\n")
    (out / "accuracy.md").write_text(markdown(rows, header))
    slim = [{k: v for k, v in r.items() if k not in ("torso_t", "torso_z")} for r in rows]
    (out / "accuracy.json").write_text(json.dumps(slim, indent=1, default=float))
    try:
        pngs = plot(rows, out)
    except ImportError:
        pngs = []
        print("matplotlib is not installed: no plots")
    print(f"wrote {out / 'accuracy.md'}, {out / 'accuracy.json'}, "
          f"{', '.join(str(p) for p in pngs)} in {total:.0f} s")
    return 0
