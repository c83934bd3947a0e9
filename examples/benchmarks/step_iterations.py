"""Per-step iterations and milliseconds of a model under random controls (uniform in the
control range), e.g. to see which steps of a robot fall back to every contact candidate.

    PYTHONPATH=python .venv/bin/python examples/benchmarks/step_iterations.py \\
        ../shared/models/humanoid.xml --steps 30 [--option activation_margin=inf]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import ukemi


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("model")
    p.add_argument("--steps", type=int, default=30)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--qpos0", action="store_true",
                   help="start from qpos0 instead of the first keyframe (as table5.py does)")
    p.add_argument("--option", action="append", default=[],
                   help="NAME=VALUE passed to model.with_options (repeatable)")
    a = p.parse_args()
    opts = {k: (v == "true" if v in ("true", "false") else float(v)) for k, v in (o.split("=", 1) for o in a.option)}
    m = ukemi.load(a.model).with_options(**opts)
    rng = np.random.default_rng(a.seed)
    key = m.keyframe_names[0] if m.keyframe_names and not a.qpos0 else None
    s = m.make_state(key=key) if key else m.make_state()
    cr, rows = m.actuator_ctrlrange, []
    for _ in range(a.steps):
        u = rng.uniform(cr[:, 0], cr[:, 1])
        t0 = time.perf_counter()
        s, info = ukemi.step(m, s, u, on_failure="return")
        rows.append((info.iterations, 1e3 * (time.perf_counter() - t0), info.status, info.subdivisions))
    its = np.array([r[0] for r in rows])
    ms = np.array([r[1] for r in rows])
    print(f"{a.model}: {m.ncontact} candidates, {ms.mean():.1f} ms/step, iterations median "
          f"{np.median(its):.0f} max {its.max()}, failed {sum(r[2] not in ukemi.SUCCESS_STATUSES for r in rows)}, "
          f"subdivided {sum(r[3] > 1 for r in rows)}")
    print("iterations per step:", " ".join(str(i) for i in its))


if __name__ == "__main__":
    main()
