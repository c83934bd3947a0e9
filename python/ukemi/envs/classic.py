"""gymnasium's classic-control Pendulum and a continuous CartPole on ukemi rigid bodies.

The MJCF files in ``ukemi/envs/assets/`` give the bodies gymnasium's equations describe (a
uniform rod for the pendulum, a cart and uniform pole for the cart-pole; see the comments in
the files). What differs is the integrator: gymnasium steps its ODE with explicit (CartPole)
or semi-implicit (Pendulum) Euler in generalized coordinates; ukemi takes one variational-
integrator step of the rigid bodies in maximal coordinates with the joint as a constraint.
Both are first-order accurate in the step, so trajectories agree to O(dt) over a fixed time
(measured in tests/test_envs.py: for the pendulum, one step agrees to O(dt²·ω³) and 0.5 s of
swinging to 0.005–0.28 in the observation at dt = 0.05, halving with dt). Velocities in the observation are ukemi's midpoint
velocities ``(q_k − q_{k−1}) / h`` — for the pendulum exactly gymnasium's ``newthdot``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from .base import UkemiMujocoEnv

ASSETS = Path(__file__).resolve().parent / "assets"


def angle_normalize(x):
    """Wrap an angle into [−π, π) (gymnasium's ``angle_normalize``)."""
    return ((x + np.pi) % (2 * np.pi)) - np.pi


class PendulumEnv(UkemiMujocoEnv):
    """Swing up a pendulum (gymnasium ``Pendulum-v1`` semantics on ukemi physics).

    Same as Pendulum-v1: observation ``[cos θ, sin θ, θ̇]`` float32 in Box([−1, −1, −8],
    [1, 1, 8]), action Box(−2, 2, (1,)) torque (N·m, clipped), reward
    ``−(angle_normalize(θ)² + 0.1 θ̇² + 0.001 u²)`` of the state *before* the step, never
    terminated, 200-step limit, reset θ ~ U(−π, π), θ̇ ~ U(−1, 1) (``options`` ``x_init`` and
    ``y_init`` set the bounds), m = 1 kg, l = 1 m, g = 10 m/s², dt = 0.05 s.

    Differences: the body is a uniform rod (the inertia gymnasium's equation implies) stepped
    by ukemi's variational integrator. gymnasium clips θ̇ to ±``max_speed`` inside its
    update; here the angular velocity of the new state is clipped after the engine step (the
    position of that step moved at the unclipped speed). With |u| ≤ 2 the speed passes 8
    rad/s only in fast swing-ups.
    """

    _view = ("xz", None, 1.3)

    def __init__(self, xml_file: str = str(ASSETS / "pendulum.xml"), frame_skip: int = 1,
                 max_speed: float = 8.0, max_torque: float = 2.0, **kwargs: Any) -> None:
        self.max_speed, self.max_torque = float(max_speed), float(max_torque)
        super().__init__(xml_file, frame_skip, **kwargs)
        self.action_space = spaces.Box(-self.max_torque, self.max_torque, (1,), np.float32)
        high = np.array([1.0, 1.0, self.max_speed], dtype=np.float32)
        self.observation_space = spaces.Box(-high, high, dtype=np.float32)

    def _get_obs(self) -> np.ndarray:
        theta, theta_dot = self._x
        return np.array([np.cos(theta), np.sin(theta), theta_dot], dtype=np.float32)

    def _ctrl(self, action: np.ndarray) -> np.ndarray:
        return np.clip(action, -self.max_torque, self.max_torque)

    def _snapshot(self) -> np.ndarray:
        return self._x.copy()

    def _accept(self, x_next: np.ndarray) -> None:
        if abs(x_next[1]) <= self.max_speed:
            return super()._accept(x_next)
        # clipping the speed changes the state: a fresh one at the clipped velocity
        x_next = x_next.copy()
        x_next[1] = np.clip(x_next[1], -self.max_speed, self.max_speed)
        self._set_x(x_next)

    def _reward(self, before, action):
        theta, theta_dot = before
        u = float(self._ctrl(action)[0])
        cost = angle_normalize(theta) ** 2 + 0.1 * theta_dot**2 + 0.001 * u**2
        return -cost, False, {}

    def _reset_model(self) -> None:
        options = getattr(self, "_reset_options", None) or {}
        high = np.array([float(options.get("x_init", np.pi)), float(options.get("y_init", 1.0))])
        self.set_state(*self.np_random.uniform(low=-high, high=high)[:, None])

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        self._reset_options = options
        return super().reset(seed=seed, options=options)


class CartPoleEnv(UkemiMujocoEnv):
    """Balance a pole on a cart with a continuous force (gymnasium ``CartPole-v1`` on ukemi).

    As CartPole-v1: observation ``[x, ẋ, θ, θ̇]`` float32 in Box(±[4.8, ∞, 0.418, ∞]),
    reward 1 per step (the terminating step included), terminated when |x| > 2.4 m or
    |θ| > 12°, 500-step limit, reset of all four uniform in ±0.05, dt = 0.02 s, cart 1 kg,
    pole 0.1 kg and 1 m, g = 9.8. Difference: the action is continuous, Box(−1, 1, (1,)),
    a force of ``force_mag · a`` newtons (``force_mag`` = 10 as gymnasium's bang-bang force).
    """

    _view = ("xz", None, 2.6)

    def __init__(self, xml_file: str = str(ASSETS / "cartpole.xml"), frame_skip: int = 1,
                 x_threshold: float = 2.4, theta_threshold: float = 12 * 2 * np.pi / 360,
                 reset_noise_scale: float = 0.05, **kwargs: Any) -> None:
        self.x_threshold, self.theta_threshold = float(x_threshold), float(theta_threshold)
        self._reset_noise_scale = reset_noise_scale
        super().__init__(xml_file, frame_skip, **kwargs)
        high = np.array([2 * self.x_threshold, np.inf, 2 * self.theta_threshold, np.inf], np.float32)
        self.observation_space = spaces.Box(-high, high, dtype=np.float32)

    @property
    def force_mag(self) -> float:
        """Force (N) per unit action: the motor's gear."""
        return float(self.model.actuator_gear[0])

    def _get_obs(self) -> np.ndarray:
        x, theta, x_dot, theta_dot = self._x
        return np.array([x, x_dot, theta, theta_dot], dtype=np.float32)

    def _reward(self, before, action):
        x, theta = self.qpos
        terminated = bool(abs(x) > self.x_threshold or abs(theta) > self.theta_threshold)
        return 1.0, terminated, {}

    def _reset_model(self) -> None:
        x, x_dot, theta, theta_dot = self._uniform(self._reset_noise_scale, 4)
        self.set_state([x, theta], [x_dot, theta_dot])
