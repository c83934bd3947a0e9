"""Base class of ukemi's gymnasium environments: MuJoCo's ``MujocoEnv`` contract on ukemi physics.

The env keeps the full engine state between steps (one row of a ``ukemi._ukemi.EnvStates``:
positions, the variational integrator's midpoint velocities and the solver's warm start), so a
trajectory under a fixed action sequence is exactly ``ukemi.rollout``'s with each action's
control repeated ``frame_skip`` times (tests/test_envs.py). ``reset`` and
``set_state(qpos, qvel)`` make a fresh state from MuJoCo-layout coordinates (as
``model.make_state(qpos, qvel)``); ``qpos``, ``qvel`` and ``state_vector()`` read it as in
gymnasium's ``MujocoEnv``, ``state`` is a copy of the full ``ukemi.State``. One env step holds
the action as the control for ``frame_skip`` engine steps, so ``dt = timestep * frame_skip``.

Solver failures: an env step whose solve fails at any substep (status ``max_iterations``,
``line_search_failed`` or ``non_finite``) **truncates** the episode. The state stays at the last
converged state, the observation is that state's, the reward is 0.0, ``truncated=True``,
``terminated=False``, ``info["solver_status"]`` names the failure and a
:class:`SolverFailureWarning` is issued (``warn_on_solver_failure=False`` silences it).
Truncation, not termination, because the failure is the simulator's, not the task's: value
bootstrapping from the last valid observation stays correct. Every step's ``info`` carries
``"solver_status"`` (``"converged"`` normally).

Contact forces: every step's ``info["contact_forces"]`` is an (ncontact, 3) array, one row per
contact candidate of the model (a fixed list, ``model.contact_pairs``; inactive candidates
read ~0): the force of the env step's last engine step, ``contact_impulse / timestep`` (N),
in the candidate's contact frame (normal, tangent 1, tangent 2) — the normal component is
>= 0 and the tangential part lies in the friction cone. Models without contacts give (0, 3).
A failed step reports zeros. ``body_contact_wrench`` holds the same forces summed per body.

Joint limits: ukemi's joint limits are hard (an inequality in the solve), MuJoCo's are soft
(a spring-damper that lets a joint sit beyond its range and pushes it back over several
steps). gymnasium's reset noise puts joints beyond their ranges (Hopper's and Walker2d's knees
start at their upper limit 0 ± 0.005 rad; Ant's ankles start at 0, outside [30°, 70°]), which
ukemi would correct within one step at a large velocity (0.005 rad / 0.002 s = 2.5 rad/s on
Hopper). So ``reset`` clips the noisy ``qpos`` into the joint ranges
(``clip_reset_to_joint_limits=False`` keeps gymnasium's exact reset distribution).
"""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from .. import _ukemi
from .._simulate import SUCCESS
from . import _render
from ._assets import asset_path, load_model, mjcf_info, rotate
from ._physics import step_rows


def planar_locomotion_reward(env, x_velocity: float, y_velocity: float, action):
    """MuJoCo v5's Ant/Humanoid reward: forward velocity + healthy bonus − control cost −
    contact cost, with their termination rule and info keys. ``env`` provides the v5 weights
    (``_forward_reward_weight``, ``_healthy_reward``, ``_ctrl_cost_weight``), ``is_healthy``,
    ``contact_cost`` and ``_terminate_when_unhealthy``."""
    forward_reward = env._forward_reward_weight * x_velocity
    healthy_reward = env.is_healthy * env._healthy_reward
    ctrl_cost = env._ctrl_cost_weight * float(np.sum(np.square(action)))
    contact_cost = env.contact_cost
    terminated = (not env.is_healthy) and env._terminate_when_unhealthy
    qpos = env.qpos
    info = {"x_position": qpos[0], "y_position": qpos[1],
            "distance_from_origin": float(np.linalg.norm(qpos[0:2])),
            "x_velocity": x_velocity, "y_velocity": y_velocity,
            "reward_survive": healthy_reward, "reward_forward": forward_reward,
            "reward_ctrl": -ctrl_cost, "reward_contact": -contact_cost}
    return forward_reward + healthy_reward - ctrl_cost - contact_cost, terminated, info


class SolverFailureWarning(RuntimeWarning):
    """An env step's solve did not converge; the episode was truncated."""


class UkemiMujocoEnv(gymnasium.Env):
    """Common machinery: model loading, stepping, reset, rendering. Subclasses define the task.

    Args:
        xml_file: A gymnasium asset name (``"hopper.xml"``) or a path to an MJCF file.
        frame_skip: Engine steps per env step.
        timestep: Engine time step (s); None keeps the MJCF's. ``dt = timestep * frame_skip``.
        solver_options: Keyword arguments of ``ukemi.Model.with_options`` (``rtol``,
            ``kappa_tol``, ``max_iter``, ``max_ls``, ``undercut``, ``warm_start``,
            ``regularization``).
        render_mode: None or ``"rgb_array"`` (a simple software renderer, no OpenGL).
        width, height: Image size of ``render()`` in pixels.
        warn_on_solver_failure: Issue a :class:`SolverFailureWarning` when a step fails.
        clip_reset_to_joint_limits: Clip the reset ``qpos`` into the joint ranges (module
            docstring).

    Subclasses implement ``_get_obs()``, ``_reset_model()`` and ``_reward(before, action)``.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 50}
    #: renderer camera: projection plane and tracked body (None: fixed at the origin)
    _view: tuple[str, int | None, float] = ("xz", None, 1.0)

    def __init__(
        self,
        xml_file: str,
        frame_skip: int,
        *,
        timestep: float | None = None,
        solver_options: dict[str, Any] | None = None,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 480,
        warn_on_solver_failure: bool = True,
        clip_reset_to_joint_limits: bool = True,
    ) -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"`render_mode` must be None or 'rgb_array', got {render_mode!r}")
        if int(frame_skip) < 1:
            raise ValueError(f"`frame_skip` must be >= 1, got {frame_skip!r}")
        self.fullpath = str(asset_path(xml_file))
        options = tuple(sorted((solver_options or {}).items()))
        self.model = load_model(self.fullpath, timestep, options)
        self.frame_skip = int(frame_skip)
        self.render_mode = render_mode
        self.width, self.height = int(width), int(height)
        self.warn_on_solver_failure = warn_on_solver_failure
        self.clip_reset_to_joint_limits = clip_reset_to_joint_limits
        self._info = mjcf_info(self.fullpath)
        self._body_index = {n: i for i, n in enumerate(self.model.body_names)}
        self.init_qpos = np.array(self.model.qpos0, dtype=np.float64)
        self.init_qvel = np.zeros(self.model.nv)
        # the full engine state lives in row `_row` of `_states` (the vector env shares one)
        self._states, self._row = _ukemi.EnvStates(self.model, 1), 0
        self._set_x(np.concatenate([self.init_qpos, self.init_qvel]))
        self._clear_contacts()
        low, high = np.asarray(self.model.actuator_ctrlrange, dtype=np.float32).T
        self.action_space = spaces.Box(low=low, high=high, dtype=np.float32)
        self.metadata = {"render_modes": ["rgb_array"], "render_fps": int(np.round(1.0 / self.dt))}
        n = self._get_obs().size
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(n,), dtype=np.float64)

    # -- MujocoEnv-compatible state access -------------------------------------------------
    @property
    def dt(self) -> float:
        """Time of one env step (s): ``timestep * frame_skip``."""
        return self.model.timestep * self.frame_skip

    @property
    def qpos(self) -> np.ndarray:
        """Generalized positions (nq,), MuJoCo's layout (read-only view)."""
        v = self._x[: self.model.nq]
        v.flags.writeable = False
        return v

    @property
    def qvel(self) -> np.ndarray:
        """Generalized velocities (nv,), MuJoCo's layout (read-only view)."""
        v = self._x[self.model.nq :]
        v.flags.writeable = False
        return v

    def state_vector(self) -> np.ndarray:
        """``[qpos, qvel]`` (nq + nv,), a copy."""
        return self._x.copy()

    def set_state(self, qpos, qvel) -> None:
        """Set the state from MuJoCo-layout ``qpos`` (nq,) and ``qvel`` (nv,)."""
        qpos, qvel = np.asarray(qpos, np.float64), np.asarray(qvel, np.float64)
        if qpos.shape != (self.model.nq,) or qvel.shape != (self.model.nv,):
            raise ValueError(f"set_state: expected qpos ({self.model.nq},) and qvel ({self.model.nv},), "
                             f"got {qpos.shape} and {qvel.shape}")
        self._set_x(np.concatenate([qpos, qvel]))

    def _clear_contacts(self) -> None:
        self._contact_force = np.zeros((self.model.ncontact, 3))
        self._body_wrench = np.zeros((self.model.nbody, 6))

    @property
    def contact_forces(self) -> np.ndarray:
        """Last env step's force per contact candidate, contact frame (normal, t1, t2), N;
        (ncontact, 3). Zero after a reset."""
        return self._contact_force.copy()

    @property
    def body_contact_wrench(self) -> np.ndarray:
        """Last env step's external contact wrench on each body, world frame: torque about the
        world origin (N·m) then force (N); (nbody, 6), world row zero. Zero after a reset."""
        return self._body_wrench.copy()

    def _set_x(self, x: np.ndarray) -> None:
        """A fresh engine state at ``x = [qpos, qvel]`` (reference warm start)."""
        x = np.array(x, dtype=np.float64)
        nq = self.model.nq
        self._states.reset(self._row, x[:nq], x[nq:])
        self._x, self._state = x, None

    def _accept(self, x_next: np.ndarray) -> None:
        """Take the stepped row's ``[qpos, qvel]`` as the env's (the row already holds it)."""
        self._x, self._state = x_next, None

    def _attach(self, states, row: int) -> None:
        """Move this env's full state into row ``row`` of ``states`` and step it there."""
        states.set_state(row, self._states.state(self._row))
        self._states, self._row = states, int(row)

    @property
    def state(self):
        """The full ``ukemi.State`` (a copy, cached until the next step or reset)."""
        if self._state is None:
            self._state = self._states.state(self._row)
        return self._state

    def body_xpos(self, name: str) -> np.ndarray:
        """World position of a body frame (MuJoCo's ``data.body(name).xpos``), (3,)."""
        return self.state.body_pos[self._body_index[name]]

    def site_xpos(self, name: str) -> np.ndarray:
        """World position of an MJCF site (MuJoCo's ``data.site(name).xpos``), (3,)."""
        body, local = self._info.sites[name]
        s = self.state
        return s.body_pos[body] + rotate(s.body_quat[body], local)

    # -- gymnasium API ----------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self._set_x(np.concatenate([self.init_qpos, self.init_qvel]))
        self._clear_contacts()
        self._reset_model()
        if self.clip_reset_to_joint_limits:
            self._set_x(np.concatenate([self._clip_to_joint_limits(self.qpos), self.qvel]))
        return self._get_obs(), self._reset_info()

    def step(self, action):
        action = self._check_action(action)
        before = self._snapshot()
        phys = step_rows(self._states, [self._row], self._ctrl(action)[None], self.frame_skip)
        return self._after_physics(action, before, *(p[0] for p in phys))

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        return _render.render_frame(self)

    def _clip_to_joint_limits(self, qpos: np.ndarray) -> np.ndarray:
        """``qpos`` with every limited hinge/slide coordinate clipped into its range."""
        m, qpos = self.model, np.array(qpos)
        ranges = np.asarray(m.dof_range)
        if m.nq == m.nv:
            return np.clip(qpos, ranges[:, 0], ranges[:, 1])
        if m.nq == m.nv + 1 and m.joint_kinds[0] == "floating":  # free joint first (Ant)
            qpos[7:] = np.clip(qpos[7:], ranges[6:, 0], ranges[6:, 1])
        return qpos

    # -- pieces shared with the vector env --------------------------------------------------
    def _check_action(self, action) -> np.ndarray:
        a = np.asarray(action, dtype=np.float64)
        shape = self.action_space.shape
        if a.shape != shape:
            raise ValueError(f"Action dimension mismatch. Expected {shape}, found {a.shape}")
        return a

    def _ctrl(self, action: np.ndarray) -> np.ndarray:
        """Engine controls (nu,) for a checked action (default: the action itself)."""
        return action

    def _after_physics(self, action: np.ndarray, before: Any, x_next: np.ndarray, status: str,
                       contact_force: np.ndarray, body_wrench: np.ndarray):
        if status not in SUCCESS:
            if self.warn_on_solver_failure:
                warnings.warn(f"{type(self).__name__}: the solve failed ({status}) at t-step of "
                              f"{self.dt:g} s; episode truncated at the last converged state",
                              SolverFailureWarning, stacklevel=3)
            self._clear_contacts()
            return self._get_obs(), 0.0, False, True, {"solver_status": status,
                                                       "contact_forces": self.contact_forces}
        self._accept(x_next)
        self._contact_force, self._body_wrench = contact_force, body_wrench
        reward, terminated, info = self._reward(before, action)
        info["solver_status"] = status
        info["contact_forces"] = self.contact_forces
        return self._get_obs(), float(reward), bool(terminated), False, info

    # -- task hooks -------------------------------------------------------------------------
    def _snapshot(self) -> Any:
        """What the reward needs from the state before the step (default: qpos copy)."""
        return self._x[: self.model.nq].copy()

    def _get_obs(self) -> np.ndarray:
        raise NotImplementedError

    def _reset_model(self) -> None:
        raise NotImplementedError

    def _reward(self, before: Any, action: np.ndarray) -> tuple[float, bool, dict[str, Any]]:
        raise NotImplementedError

    def _reset_info(self) -> dict[str, Any]:
        return {}

    def _uniform(self, scale: float, n: int) -> np.ndarray:
        return self.np_random.uniform(low=-scale, high=scale, size=n)
