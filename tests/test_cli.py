"""`ukemi bench accuracy`: a small plan runs every section in process and its report, data and
plots are written; its rows carry physics the issue sets targets for (sliding-box drift,
gradients against finite differences), and robots ukemi cannot load yet are reported, not
raised. The CLI itself runs one short section end to end. (The full `--quick` run takes about
a minute and a half on 2 cores: BENCHMARKS.md.)"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from ukemi.bench import accuracy, report


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    pytest.importorskip("matplotlib")
    pytest.importorskip("mujoco")
    out = tmp_path_factory.mktemp("results")
    plan = accuracy.Plan(quick=True, slide_dts=(0.01,), drop_dts=(0.05,), energy_dts=(0.01,),
                         tols=(1e-6,), drop_tols=(), drop_duration=0.5, energy_steps=200,
                         robot_steps=5, robot_grad_steps=1)
    result = accuracy.run(plan, log=lambda _: None)
    (out / "accuracy.md").write_text(report.markdown(result, plan, "test", 0.0, 2))
    (out / "accuracy.json").write_text(json.dumps(report.to_json(result), default=float))
    report.plot(result, out)
    return out, json.loads((out / "accuracy.json").read_text())


def test_report_has_every_section_and_plot(quick_run):
    out, _ = quick_run
    text = (out / "accuracy.md").read_text()
    for heading in ("**sliding box**", "**humanoid drop**", "**gradients against kappa_grad**",
                    "**Table V robots**"):
        assert heading in text
    names = {p.name for p in out.glob("*.png")}
    assert {"accuracy_sliding_box.png", "accuracy_humanoid_fig7.png", "kappa_grad.png"} <= names


def test_cli_runs_a_section_end_to_end(tmp_path):
    pytest.importorskip("matplotlib")
    r = subprocess.run([sys.executable, "-m", "ukemi.cli", "bench", "accuracy", "--quick",
                        "--sections", "kappa_grad", "--out", str(tmp_path)], capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = json.loads((tmp_path / "accuracy.json").read_text())["kappa_grad"]["rows"]
    assert {r["scene"] for r in rows} == {"box push", "hopper"}
    assert (tmp_path / "kappa_grad.png").exists()


def test_sliding_box_has_no_lateral_drift(quick_run):
    _, res = quick_run
    box = [r for r in res["sweep"] if r["scene"] == "sliding box" and r["engine"] == "ukemi"
           and r["variant"] == "nonlinear" and r["sweep"] == "dt" and r["dt"] == 0.01]
    assert box, "no ukemi sliding-box row at dt 0.01"
    assert box[0]["failed"] == 0
    assert abs(box[0]["drift_m"]) < 1e-6  # exact cone: no sideways drift (MuJoCo elliptic: 3.8 mm)


def test_fig7_rates_are_in_both_plans():
    for plan in (accuracy.Plan(), accuracy.Plan.make_quick()):
        assert set(report.FIG7_DTS) <= set(plan.drop_dts)  # 20, 50, 100 and 500 Hz


def test_kappa_grad_rows_match_finite_differences(quick_run):
    _, res = quick_run
    for scene in ("box push", "hopper"):
        rows = {r["kappa"]: r for r in res["kappa_grad"]["rows"] if r["scene"] == scene}
        assert rows[None]["failed"] == 0
        assert rows[None]["err_hard_max"] < 1e-4  # exact derivative = FD of the hard step
        for k in (1e-2, 1e-4, 1e-6, 1e-8):
            assert rows[k]["err_smooth_max"] < 1e-5, (scene, k)  # = FD of the smoothed step
        # the smoothing bias vanishes with κ (first order: two decades per 1e-2 in κ)
        assert rows[1e-8]["err_hard_max"] < 0.1 * rows[1e-6]["err_hard_max"]


def test_table_v_reports_every_robot(quick_run):
    _, res = quick_run
    rows = res["robots"]
    robots = {r["robot"] for r in rows}
    assert {"gymnasium hopper", "gymnasium ant", "gymnasium humanoid"} <= robots
    for r in rows:
        if "unsupported" in r:
            assert r["engine"] == "ukemi" and r["unsupported"]  # the loader's reason
        else:
            assert r["ms_step"] > 0 and 0 <= r.get("failed", 0) <= r["steps"]
    assert any(r["engine"] == "mujoco" for r in rows)


def test_update_block_replaces_only_the_marked_block(tmp_path):
    f = tmp_path / "BENCH.md"
    f.write_text(f"# head\nkeep\n{report.BEGIN}\nold table\n{report.END}\ntail\n")
    report.update_block(f, "new table\n", [tmp_path / "a.png"], tmp_path)
    text = f.read_text()
    assert text.startswith("# head\nkeep\n") and text.endswith(f"{report.END}\ntail\n")
    assert "new table" in text and "old table" not in text and "`a.png`" in text
    report.update_block(f, "newer\n", [], tmp_path)  # idempotent: one block stays
    assert f.read_text().count(report.BEGIN) == 1 and "new table" not in f.read_text()


def test_update_without_markers_fails_before_running(tmp_path):
    f = tmp_path / "BENCH.md"
    f.write_text("no markers\n")
    r = subprocess.run([sys.executable, "-m", "ukemi.cli", "bench", "accuracy", "--quick",
                        "--out", str(tmp_path / "r"), "--update-benchmarks", str(f)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode != 0 and "accuracy:begin" in r.stderr


def test_cli_rejects_unknown_commands():
    r = subprocess.run([sys.executable, "-m", "ukemi.cli", "frobnicate"], capture_output=True,
                       text=True)
    assert r.returncode != 0
