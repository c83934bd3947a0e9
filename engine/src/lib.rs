//! # ukemi engine
//!
//! A differentiable rigid-body engine in maximal coordinates after the Dojo paper: each body's
//! pose and velocity are unknowns, joints are constraints with impulse multipliers, time is
//! discretised by a variational integrator, and one step is a nonlinear solve whose Newton matrix
//! is factored on the mechanism graph in linear time for trees.
//!
//! ## Conventions
//! SI units, radians, quaternions `(w, x, y, z)` body-to-world. Body state is the COM pose and
//! the *midpoint* velocities `v_{k-1/2}` (world) and `ω_{k-1/2}` (body frame). Minimal
//! coordinates follow MuJoCo's `qpos`/`qvel` (see [`joints::coordinates`]).
//!
//! ## Notation (code ↔ Dojo paper)
//! | code | paper | meaning |
//! |---|---|---|
//! | `timestep`, `h` | h | time step |
//! | `com_pos`, `quat` | p, q | body configuration x = (p, q) |
//! | `com_linvel`, `angvel_b` | v, ω (ψ = hω/2) | midpoint velocities, eqs. 16-18 |
//! | `step_map` | eq. 18 | `q⁺ = q ⊗ [sqrt(1-|ψ|²), ψ]` |
//! | `momentum_residual` | eqs. 16-17 | discrete Euler-Lagrange equations |
//! | `JointFrame::constraint` | k, eq. 13 | joint constraint at the next configuration |
//! | `JointFrame::constraint_jacobian` | K (A, B) | impulse map |
//! | `joint_impulse` | j | joint impulses |
//! | `BlockPattern`, `BlockMatrix` | §III-C | graph-ordered block LDU |
#![warn(missing_docs)]
#![cfg_attr(not(test), deny(clippy::unwrap_used, clippy::expect_used))]

pub mod batch;
pub mod contact;
pub mod error;
pub mod gradients;
pub mod integrator;
pub mod joints;
pub mod legendre;
pub mod math;
pub mod mechanics;
pub mod mjcf;
pub mod model;
pub mod solver;
pub mod state;
pub mod step;
pub mod urdf;

pub use contact::ContactModel;
pub use contact::geometry::Shape;
pub use error::{Error, Result};
pub use gradients::{
    Adjoints, Coordinates, Jacobians, Linearization, PartialsMethod, PhaseTimes, Wrt, step_smoothed,
};
pub use joints::coordinates::{qpos, qvel, set_minimal};
pub use joints::{Joint, JointKind};
pub use legendre::set_instant_velocity;
pub use model::{
    ActuatorSpec, BodySpec, GeomSpec, JointSpec, Keyframe, Model, ModelBuilder, Options, PairSpec,
};
pub use state::{IterationRecord, SolveStatus, State, StepReport, Workspace};
pub use step::{AppliedForces, rollout, step, step_with};
