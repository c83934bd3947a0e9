"""Gradients through contact against κ (``kappa_grad``): what smoothing costs in bias and time.

For each κ in 1e-2 … 1e-8 and None (the exact derivative of the hard step), on two scenes:

* ``box push`` (Dojo Fig. 4): a 1 kg box resting on a μ = 0.5 floor pushed along x by F; the
  Jacobian is B = d(next state)/dF. The hard map has a kink at F = μ m g (stick → slip).
* ``hopper``: gymnasium's hopper at dt 0.01 under random controls, at states along its fall
  with feet, limbs or torso on the floor (contact and joint limits); the Jacobian is [A B].

Errors are Frobenius norms relative to the largest finite-difference Jacobian of the scene:
against central differences of the hard step at points away from kinks (a point counts as a
kink when its forward and backward differences disagree), and against central differences of
the smoothed step at the same κ (``ukemi.step_smoothed``: the hard step moved to the central
path at κ, the map whose derivative ``kappa_grad = κ`` returns).
"""

from __future__ import annotations

import time
import warnings

import numpy as np

import ukemi

KAPPAS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, None)
PUSH_MU, PUSH_MASS, G = 0.5, 1.0, 9.81
PUSH_KINK = PUSH_MU * PUSH_MASS * G  # N
EPS = 1e-6  # finite-difference step (N, m, rad, m/s, ctrl units)
KINK_TOL = 1e-4  # |forward − backward difference| / scale that marks a kink


def box_push_model():
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_geom("floor", body="world", shape="plane", friction=PUSH_MU)
    b.add_body("box", mass=PUSH_MASS, inertia=(1 / 600,) * 3, pos=(0, 0, 0.05))
    b.add_joint("free", kind="floating", parent="world", child="box")
    b.add_geom("box", body="box", shape="box", size=(0.05,) * 3, friction=PUSH_MU)
    b.add_actuator("push", joint="free", gear=1.0)  # force along world x
    return b.compile().with_options(rtol=1e-13, warm_start=False)


def hopper_model():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gymnasium's solver options
        m = ukemi.Model.from_xml_path(ukemi.gymnasium_asset_path("hopper"))
    return m.with_options(timestep=0.01, rtol=1e-13, warm_start=False)


def _quat_mul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _free_root(model) -> bool:
    """True for a floating first joint (qpos[3:7] a quaternion), False for no quaternion."""
    kinds = list(model.joint_kinds)
    if kinds[0] == "floating" and model.nq == model.nv + 1:
        return True
    if model.nq == model.nv:
        return False
    raise NotImplementedError("tangents of this model's quaternions are not handled here")


def perturb(model, state, d: np.ndarray):
    """State displaced by the minimal tangent ``d`` (2 nv,): MuJoCo's convention, a floating
    root's rotation applied in the body frame."""
    nv = model.nv
    q, v = np.array(state.qpos), np.array(state.qvel) + d[nv:]
    dq = d[:nv]
    if not _free_root(model):
        return model.make_state(qpos=q + dq, qvel=v)
    phi = dq[3:6]
    ang = float(np.linalg.norm(phi))
    e = np.array([1.0, 0, 0, 0]) if ang == 0 else \
        np.r_[np.cos(ang / 2), np.sin(ang / 2) * phi / ang]
    q[:3] += dq[:3]
    q[3:7] = _quat_mul(q[3:7], e)
    q[7:] += dq[6:]
    return model.make_state(qpos=q, qvel=v)


def difference(model, base, other) -> np.ndarray:
    """Minimal tangent (2 nv,) from state ``base`` to ``other``."""
    nv = model.nv
    q0, q1 = np.array(base.qpos), np.array(other.qpos)
    out = np.zeros(2 * nv)
    out[nv:] = np.array(other.qvel) - np.array(base.qvel)
    if not _free_root(model):
        out[:nv] = q1 - q0
        return out
    c = _quat_mul(q0[3:7] * np.array([1, -1, -1, -1]), q1[3:7])
    c = -c if c[0] < 0 else c
    s = float(np.linalg.norm(c[1:]))
    out[:3] = q1[:3] - q0[:3]
    out[3:6] = 2 * np.arctan2(s, c[0]) * c[1:] / s if s > 0 else 2 * c[1:]
    out[6:nv] = q1[7:] - q0[7:]
    return out


# ----------------------------------------------------------------------------- Jacobians
class Point:
    """One linearisation point: a state and controls, with the inputs studied (``cols``: the
    state tangent's columns and/or the controls)."""

    def __init__(self, model, state, ctrl, with_state: bool, label: str):
        self.model, self.ctrl, self.label = model, np.asarray(ctrl, float), label
        self.state = model.make_state(qpos=state.qpos, qvel=state.qvel)  # as the gradients do
        self.with_state = with_state
        self.ny = 2 * model.nv

    def _next(self, model, d: np.ndarray, du: np.ndarray, kappa):
        """Next state (hard, or smoothed at ``kappa``) and whether its solve converged."""
        s = perturb(model, self.state, d) if d.any() else self.state
        if kappa is None:
            nxt, info = ukemi.step(model, s, self.ctrl + du, on_failure="return")
            return nxt, info.converged
        try:
            return ukemi.step_smoothed(model, s, self.ctrl + du, kappa=kappa)[0], True
        except ukemi.ConvergenceError:
            return None, False

    def fd(self, model, kappa=None):
        """Central, forward and backward differences of ``model``'s step (smoothed at
        ``kappa``): (J, J+, J−, ok)."""
        base, ok = self._next(model, np.zeros(self.ny), np.zeros(self.model.nu), kappa)
        if base is None:
            return None, None, None, False
        ncol = (self.ny if self.with_state else 0) + self.model.nu
        jp, jm = np.zeros((self.ny, ncol)), np.zeros((self.ny, ncol))
        for i in range(ncol):
            d, du = np.zeros(self.ny), np.zeros(self.model.nu)
            if self.with_state and i < self.ny:
                d[i] = EPS
            else:
                du[i - (self.ny if self.with_state else 0)] = EPS
            plus, ok_p = self._next(model, d, du, kappa)
            minus, ok_m = self._next(model, -d, -du, kappa)
            ok = ok and ok_p and ok_m
            if kappa is not None and not ok:
                return None, None, None, False
            jp[:, i] = difference(self.model, base, plus) / EPS
            jm[:, i] = -difference(self.model, base, minus) / EPS
        return 0.5 * (jp + jm), jp, jm, ok

    def jacobian(self, kappa, repeats: int = 3):
        """(J, seconds per call (median of ``repeats``)) of the engine at ``kappa``; J is None
        when the gradient solve did not converge."""
        wrt = ("state", "ctrl") if self.with_state else ("ctrl",)
        times, jac = [], None
        for _ in range(repeats):
            t0 = time.perf_counter()
            try:
                jac = ukemi.step_jacobians(self.model, self.state, self.ctrl, kappa_grad=kappa,
                                           wrt=wrt)
            except ukemi.ConvergenceError:
                return None, float("nan")
            times.append(time.perf_counter() - t0)
        J = np.hstack([jac.A, jac.B]) if self.with_state else jac.B
        return J, float(np.median(times))


def box_push_points(forces) -> list[Point]:
    m = box_push_model()
    s = m.make_state()
    for _ in range(30):  # settle onto the floor
        s, _ = ukemi.step(m, s, [0.0])
    return [Point(m, s, [f], False, f"F={f:g} N") for f in forces]


def hopper_points(at_steps) -> list[Point]:
    m = hopper_model()
    ctrls = 0.5 * np.random.default_rng(1).uniform(-1, 1, (max(at_steps) + 1, m.nu))
    tr = ukemi.rollout(m, m.make_state(), ctrls, on_failure="return")
    return [Point(m, m.make_state(qpos=tr.qpos[k], qvel=tr.qvel[k]), ctrls[k], True,
                  f"step {k}") for k in at_steps]


# ----------------------------------------------------------------------------- the sweep
def sweep_scene(scene: str, points: list[Point], kappas=KAPPAS, log=print) -> list[dict]:
    """One row per κ: errors against the hard and the smoothed step, time per gradient."""
    hard = [p.fd(p.model) for p in points]
    scale = max(float(np.linalg.norm(h[0])) for h in hard)
    kink = [not h[3] or np.linalg.norm(h[1] - h[2]) / scale > KINK_TOL for h in hard]
    rows = []
    for kappa in kappas:
        e_hard, e_smooth, times, failed, unsolved = [], [], [], 0, 0
        for p, h, at_kink in zip(points, hard, kink, strict=True):
            J, secs = p.jacobian(kappa)
            if J is None:
                failed += 1
                continue
            times.append(secs)
            if not at_kink:
                e_hard.append(np.linalg.norm(J - h[0]) / scale)
            if kappa is None:  # the smoothed step is the hard one: compared above
                continue
            Js, _, _, ok = p.fd(p.model, kappa)
            if ok:
                e_smooth.append(np.linalg.norm(J - Js) / scale)
            else:
                unsolved += 1
        row = {"scene": scene, "kappa": kappa, "points": len(points), "kinks": int(sum(kink)),
               "err_hard_max": _max(e_hard), "err_hard_median": _median(e_hard),
               "err_smooth_max": _max(e_smooth), "grad_ms": 1e3 * _median(times),
               "failed": failed, "smooth_unsolved": unsolved}
        rows.append(row)
        log(f"kappa_grad {scene:<9} κ={_k(kappa):<6} vs hard {row['err_hard_max']:.2e} "
            f"vs smoothed {row['err_smooth_max']:.2e}  {row['grad_ms']:.2f} ms/gradient  "
            f"kinks {row['kinks']}/{len(points)} failed {failed}")
    return rows


def box_push_curve(forces, kappas=KAPPAS) -> dict:
    """dx⁺/dF against F per κ (Fig. 4), and the hard subgradient h²/m above the threshold."""
    pts = box_push_points(forces)
    curves = {}
    for kappa in kappas:
        js = [p.jacobian(kappa, repeats=1)[0] for p in pts]
        curves[_k(kappa)] = [float("nan") if j is None else float(j[0, 0]) for j in js]
    h = pts[0].model.timestep
    hard = [h * h / PUSH_MASS if f > PUSH_KINK else 0.0 for f in forces]
    return {"forces": list(map(float, forces)), "curves": curves, "hard": hard}


def run(quick: bool, log=print) -> dict:
    """The sweep on both scenes plus the Fig. 4 curve (fewer points when ``quick``)."""
    forces = (1.0, 3.0, PUSH_KINK, 7.0, 12.0) if quick else (
        1.0, 2.0, 3.0, 4.0, PUSH_KINK, 5.5, 7.0, 10.0, 15.0)
    hop = (50, 90, 120) if quick else (20, 50, 60, 70, 90, 110, 120)
    rows = sweep_scene("box push", box_push_points(forces), log=log)
    rows += sweep_scene("hopper", hopper_points(hop), log=log)
    curve = box_push_curve(np.linspace(0.0, 20.0, 21 if quick else 61))
    return {"rows": rows, "curve": curve}


def _max(x) -> float:
    return float(np.max(x)) if len(x) else float("nan")


def _median(x) -> float:
    return float(np.median(x)) if len(x) else float("nan")


def _k(kappa) -> str:
    return "None" if kappa is None else f"{kappa:.0e}"


# ----------------------------------------------------------------------------- report
def markdown(result: dict) -> str:
    out = ["| scene | kappa_grad | error vs hard step, max (median) | points (kinks) | "
           "error vs smoothed step, max | ms per gradient | failed |", "|---" * 7 + "|"]
    for r in result["rows"]:
        smooth = "– (is the hard step)" if r["kappa"] is None else _e(r["err_smooth_max"])
        if r["smooth_unsolved"]:
            smooth += f" ({r['smooth_unsolved']} not reproduced)"
        out.append(f"| {r['scene']} | {_k(r['kappa'])} | {_e(r['err_hard_max'])} "
                   f"({_e(r['err_hard_median'])}) | {r['points']} ({r['kinks']}) | {smooth} | "
                   f"{r['grad_ms']:.2f} | {r['failed']}/{r['points']} |")
    return "\n".join(out) + "\n"


def _e(x: float) -> str:
    return "–" if x != x else f"{x:.1e}"


def plot(result: dict, out):
    """kappa_grad.png: Fig. 4's gradient curves, errors against κ, time per gradient."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b, c) = plt.subplots(1, 3, figsize=(15, 4.2))
    cur = result["curve"]
    for name, ys in cur["curves"].items():
        a.plot(cur["forces"], np.array(ys) * 1e4, label=f"κ = {name}")
    a.plot(cur["forces"], np.array(cur["hard"]) * 1e4, "k--", label="hard subgradient h²/m")
    a.set(xlabel="push force F (N)", ylabel="dx⁺/dF (1e-4 m/N)",
          title="box push (Dojo Fig. 4): gradient vs F")
    a.legend(fontsize=7)
    for scene, mark in (("box push", "o"), ("hopper", "s")):
        rows = [r for r in result["rows"] if r["scene"] == scene]
        exact = next(r for r in rows if r["kappa"] is None)
        sm = [r for r in rows if r["kappa"] is not None]
        ks = [r["kappa"] for r in sm]
        b.loglog(ks, [r["err_hard_max"] for r in sm], mark + "-", label=f"{scene}: vs hard step")
        b.loglog(ks, [max(r["err_smooth_max"], 1e-16) for r in sm], mark + ":",
                 label=f"{scene}: vs smoothed step")
        b.axhline(exact["err_hard_max"], ls="--", lw=0.8, color=b.lines[-2].get_color(),
                  label=f"{scene}: κ = None vs hard")
        c.semilogx(ks, [r["grad_ms"] for r in sm], mark + "-", label=scene)
        c.axhline(exact["grad_ms"], ls="--", lw=0.8, color=c.lines[-1].get_color(),
                  label=f"{scene}: κ = None")
    b.set(xlabel="kappa_grad κ", ylabel="‖J − J_fd‖ / max ‖J_fd‖",
          title="gradient error (max over points)")
    b.legend(fontsize=7)
    c.set(xlabel="kappa_grad κ", ylabel="ms per gradient (median)", title="time per gradient")
    c.legend(fontsize=7)
    for ax in (b, c):
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    path = out / "kappa_grad.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
