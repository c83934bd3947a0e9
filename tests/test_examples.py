"""The examples run in reduced form (the full runs are command-line options)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def run(name, *argv, tmp_path=None):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    old = sys.argv
    sys.argv = [name, *argv]
    try:
        return mod.main()
    finally:
        sys.argv = old


def test_box_push_example_reproduces_the_friction_kink(tmp_path):
    forces, disp, grads = run("box_push_gradients", "--points", "6", "--out", str(tmp_path / "b.png"))
    h, mu, g = 0.01, 0.5, 9.81
    sliding = forces > mu * g + 0.5
    # above the threshold one step moves the box by h² (F - μ m g) / m
    np.testing.assert_allclose(disp[sliding], h * h * (forces[sliding] - mu * g), rtol=1e-6)
    assert np.all(np.abs(disp[forces < mu * g - 0.5]) < 1e-9)
    assert (tmp_path / "b.png").exists()


def test_smoothing_bias_grows_with_kappa():
    """Reduced run of examples/benchmarks/smoothing_bias.py on the shared humanoid standing on
    the floor: the smoothed step departs from the hard one in proportion to κ while κ is small
    (each contact pair pushes with κ / gap), more slowly at 1e-4, and by under 1e-3 at
    κ = 1e-8."""
    path = EXAMPLES.parents[1] / "shared" / "models" / "humanoid.xml"
    if not path.exists():
        pytest.skip("../shared/models is not here")
    rows = run("benchmarks/smoothing_bias", "--models", str(path), "--kappa", "1e-8", "1e-6",
               "1e-4", "--steps", "30", "--every", "10")
    bias = {r["kappa"]: r["median"] for r in rows}
    assert 0 < bias[1e-8] < 1e-3, bias
    assert 30 < bias[1e-6] / bias[1e-8] < 300, bias
    assert 10 < bias[1e-4] / bias[1e-6] < 100, bias


def test_jax_throw_example_reduces_the_distance():
    pytest.importorskip("jax")
    err = run("jax_throw", "--iters", "4", "--steps", "60")
    assert err < 0.6  # from ~0.7 m at the initial guess


def test_torch_policy_example_lowers_the_cost(tmp_path):
    pytest.importorskip("torch")
    _, curve = run("torch_policy", "--iters", "4", "--steps", "20", "--batch", "2",
                   "--out", str(tmp_path / "p.png"))
    assert curve[-1] < curve[0]


def test_pendulum_apg_example_improves_the_return():
    pytest.importorskip("jax")
    curve = run("pendulum_apg", "--iters", "6", "--horizon", "20", "--batch", "4")
    assert curve[-1] > curve[0]


def test_sb3_train_example_runs_ukemi_and_reference(tmp_path):
    """Reduced run of examples/sb3_train.py (PPO and SAC, ukemi/Pendulum-v0 vs Pendulum-v1):
    both runs train on the same budget and the PNG is written. Learning itself is asserted in
    tests/test_envs.py::test_sb3_ppo_learns_inverted_pendulum."""
    pytest.importorskip("stable_baselines3")
    out = tmp_path / "curve.png"
    runs = run("sb3_train", "--reduced", "--envs", "ukemi/Pendulum-v0", "--out", str(out))
    assert out.exists()
    for algo in ("PPO", "SAC"):
        pair = runs["ukemi/Pendulum-v0", algo]
        assert set(pair) == {"ukemi/Pendulum-v0", "Pendulum-v1"}
        for steps, returns, final, _, _ in pair.values():
            assert len(returns) >= 1 and np.all(returns < 0) and final < 0  # Pendulum costs
