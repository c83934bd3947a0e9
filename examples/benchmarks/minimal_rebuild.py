"""How far `step_jacobians(..., coordinates="minimal")` moves from `ukemi.step`: in minimal
coordinates a state is first rebuilt from `(qpos, qvel)` (MuJoCo's state), which drops the
part of the maximal velocities a contact step leaves outside the joints' motion subspaces
(the variational integrator's O(h) discrete velocities). This prints, over a Table V run
(dt = 0.01, table5.py's random controls), the largest `qvel` difference between the two next
states per step (median and max), for each shared robot. Numbers are printed, not asserted.

    .venv/bin/python examples/benchmarks/minimal_rebuild.py --steps 150
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

import ukemi

sys.path.insert(0, str(Path(__file__).parent))
import table5  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    for name, path in table5.models():
        if "shared/" not in name or not path.exists():
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = ukemi.Model.from_xml_path(str(path)).with_options(timestep=0.01)
        r = np.array(model.actuator_ctrlrange)
        lo = np.where(np.isfinite(r[:, 0]), r[:, 0], -1.0)
        hi = np.where(np.isfinite(r[:, 1]), r[:, 1], 1.0)
        ctrls = table5.random_ctrls(lo, hi, args.steps, rng)
        s = model.make_state(key=model.keyframe_names[0]) if model.keyframe_names else model.make_state()
        dv = []
        for u in ctrls:
            a, _ = ukemi.step(model, s, u, on_failure="return")
            try:
                b = ukemi.step_jacobians(model, s, u, wrt=("state", "ctrl")).next_state
                dv.append(np.abs(np.asarray(a.qvel) - np.asarray(b.qvel)).max())
            except ukemi.ConvergenceError:
                pass
            s = a
        dv = np.array(dv)
        print(f"{name:18s} qvel difference per step: median {np.median(dv):.3f}, max {dv.max():.3f} "
              f"(rad/s or m/s; {len(dv)} steps)")


if __name__ == "__main__":
    main()
