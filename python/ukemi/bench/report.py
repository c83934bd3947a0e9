"""Markdown, JSON and PNG output of ``ukemi bench accuracy``, and the BENCHMARKS.md block."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from ukemi.bench import robots, smoothing

BEGIN, END = "<!-- accuracy:begin -->", "<!-- accuracy:end -->"
DROP = "humanoid drop"
FIG7_DTS = (0.05, 0.02, 0.01, 0.002)  # 20, 50, 100 and 500 Hz


def primary_error(r: dict) -> float:
    """The error plotted against cost, per scene."""
    if r["kind"] == "sliding box":
        return abs(r["stop_err"])
    if r["kind"] == DROP:
        return max(-r["min_dist_landing_m"], 0.0)
    return r["energy_drift"]


ERROR_LABEL = {"sliding box": "|stopping-distance error| (relative)",
               DROP: "penetration during landing (m)",
               "tumbling body": "max relative energy drift",
               "pendulum": "max relative energy drift"}


def log_line(r: dict) -> str:
    tol = "default" if r["tol"] is None else f"{r['tol']:.0e}"
    return (f"{r['scene'][:14]:<14} {r['engine']:<6} {r['variant']:<9} dt={r['dt']:<6g} "
            f"tol={tol:<8} {r['per_sim_s']:9.4f} s/sim-s  it {r['iters']:5.2f}  failed "
            f"{r['failed']}/{r['steps']}  err {primary_error(r):.3g}")


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
    DROP: [("least floor distance, landing (m)", lambda r: _g(r["min_dist_landing_m"])),
           ("least floor distance, last 0.25 s (m)", lambda r: _g(r["min_dist_rest_m"])),
           ("torso z end (m)", lambda r: _g(r["torso_z_end_m"], ".3f"))],
    "tumbling body": [("energy drift", lambda r: _g(r["energy_drift"])),
                      ("ang. momentum drift", lambda r: _g(r["momentum_drift"]))],
    "pendulum": [("energy drift", lambda r: _g(r["energy_drift"]))],
}


def _failed(r: dict) -> str:
    if r["engine"] != "ukemi":
        return "–" if r.get("diverged_t") is None else f"diverged at t = {r['diverged_t']:g} s"
    kinds = f" ({', '.join(r['fail_kinds'])})" if r["fail_kinds"] else ""
    return f"{r['failed']}/{r['steps']}{kinds}"


def sweep_tables(rows: list[dict]) -> list[str]:
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        sel = [r for r in rows if r["scene"] == scene]
        cols = COLUMNS[sel[0]["kind"]]
        names = ["engine", "cone/integrator", "dt (s)", "tol", "s per sim-s", "it/step",
                 "failed/steps", *[c for c, _ in cols]]
        out += [f"\n**{scene}**\n", "| " + " | ".join(names) + " |", "|" + "---|" * len(names)]
        for r in sel:
            tol = "default" if r["tol"] is None else f"{r['tol']:.0e}"
            cells = [r["engine"], r["variant"], f"{r['dt']:g}", tol, _g(r["per_sim_s"], ".3g"),
                     _g(r["iters"], ".2f"), _failed(r), *[f(r) for _, f in cols]]
            out.append("| " + " | ".join(cells) + " |")
    return out


# ----------------------------------------------------------------------------- headlines
def _pick(rows, **kw):
    return [r for r in rows if all(r.get(k) == v for k, v in kw.items())]


def headlines(result: dict) -> list[str]:
    """One bullet per study with its key numbers, computed from the rows."""
    out = []
    rows = result.get("sweep", [])
    box = _pick(rows, kind="sliding box", sweep="dt", dt=0.01)
    if box:
        parts = [f"{r['engine']} {r['variant']} drift {_g(r['drift_m'], '.1e')} m, stop "
                 f"{100 * r['stop_err']:+.2f}%" for r in box]
        out.append("Sliding box at 30°, dt 0.01 (targets: drift < 1e-6 m, |error| < 0.5%): "
                   + "; ".join(parts) + ".")
    for scene in dict.fromkeys(r["scene"] for r in rows if r["kind"] == DROP):
        uk = _pick(rows, scene=scene, engine="ukemi", sweep="dt")
        mj = _pick(rows, scene=scene, engine="mujoco", variant="elliptic", sweep="dt")
        parts = [f"dt {r['dt']:g}: {r['failed']}/{r['steps']} failed, least "
                 f"{_g(r['min_dist_landing_m'], '.1e')} m" for r in uk]
        mjp = [f"{r['dt']:g}: " + (f"{_g(r['min_dist_landing_m'], '.1e')} m"
                                    if r.get("diverged_t") is None else "diverged") for r in mj]
        out.append(f"{scene.capitalize()} (target ≥ −1e-8 m at every dt), ukemi — "
                   + "; ".join(parts) + (". MuJoCo elliptic least distance — " + "; ".join(mjp)
                                         if mjp else "") + ".")
    for note in result.get("notes", []):
        out.append(f"Humanoid drop on {note}")
    tumble = _pick(rows, kind="tumbling body", sweep="dt", dt=0.01)
    if tumble:
        parts = [f"{r['engine']} {r['variant'] if r['variant'] != '-' else ''}".strip()
                 + f" {_g(r['energy_drift'], '.1e')}" for r in tumble]
        out.append("Free tumbling body, energy drift at dt 0.01: " + "; ".join(parts) + ".")
    for scene in dict.fromkeys(r["scene"] for r in result.get("kappa_grad", {}).get("rows", [])):
        ks = _pick(result["kappa_grad"]["rows"], scene=scene)
        exact = next(r for r in ks if r["kappa"] is None)
        sm = [r for r in ks if r["kappa"] is not None]
        worst = max(r["err_smooth_max"] for r in sm)
        out.append(f"kappa_grad, {scene}: κ = None matches the hard step's finite differences "
                   f"to {exact['err_hard_max']:.1e} ({exact['grad_ms']:.2f} ms/gradient); every κ "
                   f"matches its smoothed step to ≤ {worst:.1e}; the smoothing bias against the "
                   f"hard step is " + ", ".join(f"{r['err_hard_max']:.0e} at κ {r['kappa']:.0e}"
                                                for r in sm[::2])
                   + f" ({min(r['grad_ms'] for r in sm):.2f}–{max(r['grad_ms'] for r in sm):.2f}"
                   " ms/gradient).")
    rob = result.get("robots", [])
    for name in dict.fromkeys(r["robot"] for r in rob):
        uk = _pick(rob, robot=name, engine="ukemi")
        mj = _pick(rob, robot=name, engine="mujoco")
        if uk and "unsupported" in uk[0]:
            out.append(f"Table V, {name}: unsupported by ukemi today ({uk[0]['unsupported']}).")
        elif uk and mj:
            u, m = uk[0], mj[0]
            fwd, grad = u["ms_step"] / m["ms_step"], u["ms_step_grad"] / m["ms_step_grad"]
            out.append(f"Table V, {name}: ukemi {u['ms_step']:.3g} ms/step ({fwd:.0f}× MuJoCo), "
                       f"{u['it_mean']:.1f} it/step (max {u['it_max']}), {u['failed']}/"
                       f"{u['steps']} steps failed; with A, B {u['ms_step_grad']:.3g} ms/step "
                       f"({grad:.1f}× MuJoCo's mjd_transitionFD).")
    return out


def markdown(result: dict, plan, cmd: str, total: float, cores) -> str:
    secs = ", ".join(f"{k} {v:.0f} s" for k, v in result["seconds"].items())
    out = [f"`{cmd}` ({cores} cores, {total:.0f} s in all: {secs}; sliding box "
           f"{plan.slide_duration} s, humanoid drop {plan.drop_duration} s, energy scenes "
           f"{plan.energy_steps} steps; tolerance sweeps at dt = 0.01 with rtol = kappa_tol = "
           f"tol; Table V robots {plan.robot_steps} steps, {plan.robot_grad_steps} with "
           "gradients)\n"]
    out += [f"* {h}" for h in headlines(result)]
    if "sweep" in result:
        out += sweep_tables(result["sweep"])
    if "kappa_grad" in result:
        out += ["\n**gradients against kappa_grad** (error: ‖J − J_fd‖_F / max ‖J_fd‖_F over "
                "the scene's points; box push J = d(next state)/dF, hopper J = [A B]; a kink is a "
                "point whose one-sided differences disagree)\n",
                smoothing.markdown(result["kappa_grad"])]
    if "robots" in result:
        out += [f"\n**Table V robots** (dt {robots.TABLE_V_DT}, random controls; ms/step from "
                "one ukemi.rollout / a loop of mj_step; with A, B: ukemi.step_jacobians / mj_step "
                "+ mjd_transitionFD)\n", robots.markdown(result["robots"])]
    return "\n".join(out) + "\n"


def to_json(result: dict) -> dict:
    drop = ("torso_t", "torso_z", "fail_t")
    out = dict(result)
    if "sweep" in result:
        out["sweep"] = [{k: v for k, v in r.items() if k not in drop} for r in result["sweep"]]
    return out


# ----------------------------------------------------------------------------- BENCHMARKS.md
def check_markers(path: Path) -> str:
    text = path.read_text()
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise SystemExit(f"{path}: needs exactly one {BEGIN} ... {END} block")
    return text


def update_block(path: Path, body: str, pngs: list[Path], out: Path) -> None:
    """Replace the marked block of ``path`` with ``body`` (and name the plots)."""
    text = check_markers(path)
    names = ", ".join(f"`{p.name}`" for p in pngs)
    block = (f"{BEGIN}\n<!-- generated by ukemi bench accuracy --update-benchmarks; "
             f"edits inside this block are overwritten -->\n\n{body}\nPlots ({out}/): {names}\n"
             f"{END}")
    new = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _: block, text, flags=re.S)
    path.write_text(new)
    print(f"updated the accuracy block of {path}")


# ----------------------------------------------------------------------------- plots
def plot(result: dict, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    rows = result.get("sweep", [])
    for scene in dict.fromkeys(r["scene"] for r in rows):
        paths.append(_plot_pareto(plt, [r for r in rows if r["scene"] == scene], scene, out))
    if any(r["kind"] == DROP for r in rows):
        paths.append(_plot_fig7(plt, [r for r in rows if r["kind"] == DROP], out))
    if "kappa_grad" in result:
        paths.append(smoothing.plot(result["kappa_grad"], out))
    return paths


def _slug(scene: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", scene.lower()).strip("_")


def _plot_pareto(plt, rows: list[dict], scene: str, out: Path) -> Path:
    """Error against wall time per simulated second: one curve per engine, variant, sweep."""
    fig, ax = plt.subplots(figsize=(6, 4.5))
    groups: dict = {}
    for r in rows:
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
    ax.set_ylabel(ERROR_LABEL[rows[0]["kind"]] + " (floored at 1e-16)")
    ax.set_title(f"{scene}: error vs cost (✗n = n unconverged steps)", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    p = out / f"accuracy_{_slug(scene)}.png"
    fig.tight_layout()
    fig.savefig(p, dpi=120)
    plt.close(fig)
    return p


def _plot_fig7(plt, rows: list[dict], out: Path) -> Path:
    """Dojo Fig. 7: torso height at 20, 50, 100 and 500 Hz, one panel per humanoid; ukemi solid
    (x: unconverged steps), MuJoCo's elliptic cone dotted."""
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    fig, axes = plt.subplots(1, len(scenes), figsize=(6.5 * len(scenes), 4.2), squeeze=False)
    for ax, scene in zip(axes[0], scenes, strict=True):
        zs = []
        for i, dt in enumerate(FIG7_DTS):
            color = f"C{i}"
            for r in _pick(rows, scene=scene, sweep="dt", dt=dt):
                if r["engine"] == "ukemi":
                    ax.plot(r["torso_t"], r["torso_z"], "-", color=color,
                            label=f"ukemi {1 / dt:.0f} Hz ({r['failed']} failed)")
                    ft = np.asarray(r.get("fail_t", []))
                    if len(ft):
                        zf = np.interp(ft, r["torso_t"], r["torso_z"])
                        ax.plot(ft, zf, "x", color=color, ms=5)
                    zs.append(np.asarray(r["torso_z"]))
                elif r["variant"] == "elliptic":
                    ax.plot(r["torso_t"], r["torso_z"], ":", color=color,
                            label=f"MuJoCo elliptic {1 / dt:.0f} Hz")
        if zs:  # MuJoCo diverges at large steps: keep ukemi's range in view
            lo, hi = min(z.min() for z in zs), max(z.max() for z in zs)
            ax.set_ylim(lo - 0.2 * (hi - lo) - 0.05, hi + 0.2 * (hi - lo) + 0.05)
        ax.set(xlabel="time (s)", ylabel="torso height (m)", title=f"{scene} (Dojo Fig. 7)")
        ax.legend(fontsize=6)
        ax.grid(True, alpha=0.3)
    p = out / "accuracy_humanoid_fig7.png"
    fig.tight_layout()
    fig.savefig(p, dpi=120)
    plt.close(fig)
    return p

