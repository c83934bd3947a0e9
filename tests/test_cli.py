"""`ukemi bench accuracy --quick` runs end to end and writes its table, data and plots, and its
sliding-box row meets the drift target the issue sets (< 1e-6 m at dt 0.01)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


def test_bench_accuracy_quick_writes_results(tmp_path):
    pytest.importorskip("matplotlib")
    pytest.importorskip("mujoco")
    out = tmp_path / "results"
    r = subprocess.run([sys.executable, "-m", "ukemi.cli", "bench", "accuracy", "--quick",
                        "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (out / "accuracy.md").exists()
    assert list(out.glob("*.png"))
    rows = json.loads((out / "accuracy.json").read_text())
    box = [r for r in rows if r["scene"] == "sliding box" and r["engine"] == "ukemi"
           and r["variant"] == "nonlinear" and r["sweep"] == "dt" and r["dt"] == 0.01]
    assert box, "no ukemi sliding-box row at dt 0.01"
    assert box[0]["failed"] == 0
    assert abs(box[0]["drift_m"]) < 1e-6  # exact cone: no sideways drift (MuJoCo elliptic: 3.8 mm)


def test_cli_rejects_unknown_commands():
    r = subprocess.run([sys.executable, "-m", "ukemi.cli", "frobnicate"], capture_output=True,
                       text=True)
    assert r.returncode != 0
