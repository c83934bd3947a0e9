"""ukemi: differentiable physics for robotics.

Maximal-coordinate rigid-body dynamics with a variational integrator and joints as constraints
(the Dojo paper), a Rust core, and a functional Python API in MuJoCo's vocabulary::

    import ukemi
    b = ukemi.ModelBuilder(timestep=0.01)
    b.add_body("link", mass=1.0, inertia=(0.1, 0.1, 0.01), pos=(0, 0, 1))
    b.add_joint("hinge", kind="revolute", parent="world", child="link", axis=(0, 1, 0),
                parent_anchor=(0, 0, 1.5), child_anchor=(0, 0, 0.5))
    model = b.compile()
    state = model.make_state(qpos=[0.3])
    state, info = ukemi.step(model, state)
    traj = ukemi.rollout(model, state, nsteps=100)
"""

from __future__ import annotations

from . import _ukemi, models
from ._builder import JOINT_KINDS, ModelBuilder
from ._loaders import gymnasium_asset_path, load
from ._gradients import (
    RolloutJacobians,
    StepJacobians,
    rollout_jacobians,
    rollout_vjp,
    step_jacobians,
    step_jvp,
    step_vjp,
)
from ._simulate import (STATUS_NAMES, SUCCESS_STATUSES, Trajectory, rollout, signed_distances,
                        solver_trace, step, step_smoothed)
from ._ukemi import Model, State, StepInfo, get_num_threads, set_flat_warm_start, set_num_threads
from .errors import (
    ConvergenceError,
    InputError,
    InternalError,
    MjcfError,
    ModelError,
    ModelMismatchError,
    ShapeError,
    UkemiError,
    UnsupportedError,
    UrdfError,
)

__version__: str = _ukemi.__version__

__all__ = [
    "JOINT_KINDS",
    "STATUS_NAMES",
    "SUCCESS_STATUSES",
    "ConvergenceError",
    "InputError",
    "InternalError",
    "MjcfError",
    "Model",
    "ModelBuilder",
    "ModelError",
    "ModelMismatchError",
    "RolloutJacobians",
    "ShapeError",
    "State",
    "StepInfo",
    "StepJacobians",
    "Trajectory",
    "UkemiError",
    "UnsupportedError",
    "get_num_threads",
    "UrdfError",
    "gymnasium_asset_path",
    "load",
    "models",
    "rollout",
    "rollout_jacobians",
    "rollout_vjp",
    "set_flat_warm_start",
    "set_num_threads",
    "signed_distances",
    "step",
    "solver_trace",
    "step_smoothed",
    "step_jacobians",
    "step_jvp",
    "step_vjp",
]

# Framework layers import their framework: load them on first access (`ukemi.jax.step`).
_LAZY = ("jax", "torch", "envs")

# gymnasium environments ("ukemi/Hopper-v0", ...): registration imports gymnasium only; the env
# modules load on gymnasium.make. Skipped silently without gymnasium.
try:
    from .envs._registration import register_envs as _register_envs

    _register_envs()
except ImportError:  # pragma: no cover - gymnasium not installed
    pass


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'ukemi' has no attribute {name!r}")
