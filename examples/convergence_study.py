"""Convergence of the interior-point solve per iteration (the Dojo paper's Figs. 9-10).

For three robots landing on the floor (gymnasium's hopper, the zoo quadruped and ant), one
contact step each is solved cold at a loose (1e-4) and a tight (default, 1e-11) complementarity
tolerance with ``ukemi.solver_trace``; the residual, the complementarity violation and the
Newton matrix's condition number are plotted against the iteration.

    python examples/convergence_study.py [--out docs/convergence.png]
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

import ukemi


def landing_state(model):
    """Drop from 5 cm until the first step with a contact impulse; that step's start state."""
    s0 = model.make_state()
    q = np.array(s0.qpos)
    q[2] += 0.05 - ukemi.signed_distances(model, s0).min()
    s = model.make_state(qpos=q)
    for _ in range(200):
        nxt, _ = ukemi.step(model, s)
        if np.abs(nxt.contact_impulse).max() > 1e-6:
            return s
        s = nxt
    return s


def robots():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hopper = ukemi.Model.from_xml_path(ukemi.gymnasium_asset_path("hopper"))
    return {"hopper": hopper, "quadruped": ukemi.models.quadruped(), "ant": ukemi.models.ant()}


def study():
    rows = []
    for name, model in robots().items():
        model = model.with_options(timestep=0.01, warm_start=False)
        s = landing_state(model)
        for label, tol in (("loose 1e-4", 1e-4), ("tight 1e-11", None)):
            m = model if tol is None else model.with_options(kappa_tol=tol, rtol=tol)
            _, info, trace = ukemi.solver_trace(m, s, condition=True)
            rows.append((name, label, info, trace))
            print(f"{name:10s} {label:12s} {info.status:18s} {info.iterations:3d} iterations, "
                  f"condition {np.nanmin(trace['condition']):.1e} .. "
                  f"{np.nanmax(trace['condition']):.1e}")
    return rows


def plot(rows, out):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = sorted({r[0] for r in rows})
    fig, axes = plt.subplots(3, len(names), figsize=(4 * len(names), 8), sharex="col")
    for j, name in enumerate(names):
        for _, label, _, t in (r for r in rows if r[0] == name):
            it = np.arange(1, len(t["residual"]) + 1)
            axes[0, j].semilogy(it, t["residual"], ".-", label=label)
            axes[1, j].semilogy(it, t["complementarity"], ".-", label=label)
            axes[2, j].semilogy(it, t["condition"], ".-", label=label)
        axes[0, j].set_title(name)
        axes[2, j].set_xlabel("iteration")
    axes[0, 0].set_ylabel("residual (∞-norm)")
    axes[1, 0].set_ylabel("complementarity")
    axes[2, 0].set_ylabel("cond(Newton matrix)")
    axes[0, 0].legend()
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="convergence.png")
    args = p.parse_args()
    plot(study(), args.out)
