"""Drop gymnasium's humanoid (lowest point 0.1 m above the floor, zero control) for 1 s at
several step rates and report solver failures and the least signed distance per rate
(issue #4's acceptance: no failure, least distance ≥ -1e-8 m). Printed, not asserted.

    .venv/bin/python examples/benchmarks/humanoid_drop.py 20 50 100 500 1000
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

import ukemi

# e.g. `ACTIVATION=0.01` runs with contact activation (Options::activation_margin)
OPTS = {}

def main(rates):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m0 = ukemi.Model.from_xml_path(ukemi.gymnasium_asset_path("humanoid"))
    s0 = m0.make_state()
    d0 = ukemi.signed_distances(m0, s0).min()
    for hz in rates:
        m = m0.with_options(timestep=1.0 / hz, **OPTS)
        q = np.array(s0.qpos)
        q[2] += 0.1 - d0
        s = m.make_state(qpos=q)
        t0, fails, least = time.perf_counter(), 0, np.inf
        for _ in range(hz):
            s, info = ukemi.step(m, s, np.zeros(m.nu), on_failure="return")
            fails += not info.converged
            least = min(least, ukemi.signed_distances(m, s).min())
        print(f"{hz:5d} Hz: {hz} steps, {fails} unconverged, least signed distance {least:.2e} m, "
              f"{time.perf_counter() - t0:.1f} s", flush=True)


if __name__ == "__main__":
    import os

    if os.environ.get("ACTIVATION"):
        OPTS["activation_margin"] = float(os.environ["ACTIVATION"])
    main([int(a) for a in sys.argv[1:]] or [20, 50, 100])
