"""Dojo paper Fig. 4: a 1 kg box resting on the floor is pushed sideways with a force F swept
from 0 to 20 N. The box's displacement after one step is zero below the friction threshold
μ m g and grows linearly above it; its gradient with respect to F jumps at the kink. ukemi's
gradients taken at a central-path parameter κ (``kappa_grad``) are smooth for large κ and
sharpen towards the hard subgradient as κ shrinks.

    .venv/bin/python examples/box_push_gradients.py                 # writes box_push_gradients.png
    .venv/bin/python examples/box_push_gradients.py --points 15     # quicker
"""

from __future__ import annotations

import argparse

import numpy as np

import ukemi


def box_on_floor(mu=0.5, h=0.01):
    b = ukemi.ModelBuilder(timestep=h)
    b.add_geom("floor", body="world", shape="plane", friction=mu)
    b.add_body("box", mass=1.0, inertia=(1 / 600, 1 / 600, 1 / 600), pos=(0, 0, 0.05))
    b.add_joint("free", kind="floating", parent="world", child="box")
    b.add_geom("box", body="box", shape="box", size=(0.05, 0.05, 0.05), friction=mu)
    b.add_actuator("push", joint="free", gear=1.0)  # force along world x
    return b.compile().with_options(rtol=1e-14, max_iter=100)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--points", type=int, default=81)
    ap.add_argument("--out", default="box_push_gradients.png")
    args = ap.parse_args()
    model = box_on_floor()
    state = model.make_state()
    for _ in range(30):  # settle onto the floor
        state, _ = ukemi.step(model, state, [0.0])
    forces = np.linspace(0.0, 20.0, args.points)
    kappas = [1e-4, 1e-6, 1e-8]
    x0 = state.qpos[0]
    disp, grads = [], {k: [] for k in kappas}
    for f in forces:
        nxt, _ = ukemi.step(model, state, [f])
        disp.append(nxt.qpos[0] - x0)
        for k in kappas:
            jac = ukemi.step_jacobians(model, state, [f], kappa_grad=k, wrt=("ctrl",))
            grads[k].append(jac.B[0, 0])
    h, m, mu = model.timestep, 1.0, 0.5
    hard = np.where(forces > mu * m * 9.81, h * h / m, 0.0)
    print(f"{'F (N)':>7s} {'dx (m)':>10s} " + " ".join(f"{'κ=' + format(k, '.0e'):>10s}" for k in kappas)
          + f" {'hard':>10s}")
    for i in range(0, len(forces), max(1, len(forces) // 10)):
        print(f"{forces[i]:7.2f} {disp[i]:10.3e} " + " ".join(f"{grads[k][i]:10.3e}" for k in kappas)
              + f" {hard[i]:10.3e}")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no plot")
        return forces, np.array(disp), {k: np.array(v) for k, v in grads.items()}
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4))
    a.plot(forces, np.array(disp) * 1e3, "k")
    a.set_xlabel("push force F (N)")
    a.set_ylabel("displacement after one step (mm)")
    for k in kappas:
        b.plot(forces, np.array(grads[k]) * 1e4, label=f"κ = {k:.0e}")
    b.plot(forces, hard * 1e4, "k--", label="hard subgradient")
    b.set_xlabel("push force F (N)")
    b.set_ylabel("d displacement / dF (1e-4 m/N)")
    b.legend()
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"wrote {args.out}")
    return forces, np.array(disp), {k: np.array(v) for k, v in grads.items()}


if __name__ == "__main__":
    main()
