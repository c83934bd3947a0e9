//! Joints as constraints between a parent and a child body (Dojo §III-C, eqs. 13-15).
//!
//! A joint has a translational part (0-3 free axes of the anchor displacement, expressed in the
//! parent's joint frame) and a rotational part (0-3 free rotations of the child relative to its
//! reference orientation). The constrained directions become impulse unknowns of the Newton solve;
//! the free directions are the joint's minimal coordinates (`qpos`, `qvel`), on which springs,
//! dampers and inputs act. The sixteen combinations are the [`JointKind`] variants.
pub mod coordinates;
pub mod coupling;
pub mod geometry;
pub mod hinges;
mod kind;
pub mod offsets;
pub mod tendon;

pub use kind::JointKind;

use nalgebra::{Matrix3, Vector3};

use crate::math::quat::Quat;

/// Free rotational degrees of freedom of a joint, axes in the joint frame (the child's reference
/// frame). `q_child = q_parent ⊗ offset ⊗ q_joint`.
#[derive(Clone, Debug, PartialEq)]
pub enum RotDofs {
    /// No relative rotation: 3 constraint rows `V q_joint = 0`.
    Locked,
    /// One hinge about `axis`; 2 constraint rows `[b c]ᵀ V q_joint = 0` (b, c ⟂ axis).
    Hinge {
        /// Rotation axis (unit).
        axis: Vector3<f64>,
        /// The two unit axes perpendicular to `axis` (constrained directions).
        perp: [Vector3<f64>; 2],
    },
    /// Two hinges in sequence (a Cardan/universal joint): `q_joint = q(a1, θ1) ⊗ q(a2, θ2)`;
    /// one constraint row `a1ᵀ R(q_joint) a2 = a1ᵀ a2` (zero for the kinds' orthogonal axes; MJCF
    /// shoulders use non-orthogonal ones).
    Universal {
        /// First axis (attached to the parent side).
        a1: Vector3<f64>,
        /// Second axis (attached to the child).
        a2: Vector3<f64>,
    },
    /// Free rotation, coordinates a unit quaternion (MuJoCo's ball joint), no constraint row.
    Ball,
    /// Three hinges in sequence (MuJoCo's three hinge joints about one point):
    /// `q_joint = q(a1, θ1) ⊗ q(a2, θ2) ⊗ q(a3, θ3)`, axes possibly non-orthogonal; no constraint
    /// row. The coordinates are the three angles, solved from `q_joint` (closed form for
    /// orthogonal triads, refined by Newton's method). NOTE: like every Euler-angle chart this one
    /// is singular where the motion subspace `[R₃ᵀR₂ᵀa1, R₃ᵀa2, a3]` loses rank (θ2 = ±π/2 for an
    /// orthogonal triad: gimbal lock); there the angle rates are unbounded and the angles are
    /// reported on the branch with |θ2| ≤ π/2.
    Hinges3 {
        /// Unit axes in sequence (first attached to the parent side).
        axes: [Vector3<f64>; 3],
    },
}

impl RotDofs {
    /// Number of free rotational velocity coordinates.
    pub fn nfree(&self) -> usize {
        match self {
            RotDofs::Locked => 0,
            RotDofs::Hinge { .. } => 1,
            RotDofs::Universal { .. } => 2,
            RotDofs::Ball | RotDofs::Hinges3 { .. } => 3,
        }
    }
    /// Number of rotational position coordinates (4 for a quaternion).
    pub fn nq(&self) -> usize {
        match self {
            RotDofs::Ball => 4,
            other => other.nfree(),
        }
    }
    /// Number of rotational constraint rows.
    pub fn ncon(&self) -> usize {
        3 - self.nfree()
    }
}

/// A compiled joint. Anchors are in the bodies' centre-of-mass frames (metres); the world's
/// "frame" is the world itself.
#[derive(Clone, Debug)]
pub struct Joint {
    /// Unique name.
    pub name: String,
    /// Kind (one of sixteen).
    pub kind: JointKind,
    /// Parent body index (0 = world).
    pub parent: usize,
    /// Child body index (0 = world, allowed for loop joints only).
    pub child: usize,
    /// Anchor in the parent's COM frame.
    pub parent_anchor: Vector3<f64>,
    /// Anchor in the child's COM frame.
    pub child_anchor: Vector3<f64>,
    /// Child orientation relative to the parent at zero rotational coordinates.
    pub offset: Quat,
    /// Columns: translational axes in the joint frame; the first `ntrans` are free.
    pub trans_basis: Matrix3<f64>,
    /// `trans_basisᵀ⁻¹` (equal to `trans_basis` when it is orthonormal): translation coordinates
    /// are `trans_dualᵀ Δ`, so non-orthogonal free slide axes are measured along their own axes.
    pub trans_dual: Matrix3<f64>,
    /// Number of free translational axes.
    pub ntrans: usize,
    /// Free rotations.
    pub rot: RotDofs,
    /// Closes a kinematic loop: not part of the spanning tree, has no `qpos`/`qvel`.
    pub is_loop: bool,
    /// Spring stiffness per free dof (N/m or N·m/rad).
    pub stiffness: Vec<f64>,
    /// Damping per free dof (N·s/m or N·m·s/rad).
    pub damping: Vec<f64>,
    /// Spring rest position in `qpos` units (a quaternion for ball rotations).
    pub spring_ref: Vec<f64>,
    /// Limits `(free dof, lower, upper)` on coordinates (m or rad), solved as inequality
    /// constraints in the interior-point solve.
    pub limits: Vec<(usize, f64, f64)>,
    /// Per position coordinate, the `qpos` value of the reference configuration (MuJoCo's joint
    /// `ref`); 0 for quaternion entries. Coordinates are reported as the measured displacement plus
    /// this offset. Empty means all zero.
    pub qpos_ref: Vec<f64>,
    /// Rotor inertia per free dof (MuJoCo's `armature`, kg or kg·m²); empty means none.
    pub armature: Vec<f64>,
    /// Dry friction per free dof (MuJoCo's `frictionloss`, N or N·m): the largest force the
    /// joint resists motion with, solved as a complementarity problem in the interior-point
    /// solve (`solver::friction`). Empty means none.
    pub frictionloss: Vec<f64>,
    /// Hinges about different anchors: `p_{i+1} - p_i` for consecutive hinges, joint frame (m);
    /// empty when all hinges share one anchor. The child anchor is then the last hinge's
    /// ([`offsets`]).
    pub hinge_offsets: Vec<Vector3<f64>>,
    /// First index in `qpos` (tree joints only).
    pub qpos_adr: usize,
    /// First index in `qvel` (tree joints only).
    pub qvel_adr: usize,
}

impl Joint {
    /// Free dofs = velocity coordinates.
    pub fn nfree(&self) -> usize {
        self.ntrans + self.rot.nfree()
    }
    /// Position coordinates.
    pub fn nq(&self) -> usize {
        self.ntrans + self.rot.nq()
    }
    /// Constraint rows (impulse unknowns).
    pub fn ncon(&self) -> usize {
        (3 - self.ntrans) + self.rot.ncon()
    }
    /// Whether any spring acts.
    pub fn has_spring(&self) -> bool {
        self.stiffness.iter().any(|&k| k != 0.0)
    }
    /// Whether any damper acts.
    pub fn has_damper(&self) -> bool {
        self.damping.iter().any(|&d| d != 0.0)
    }
    /// Whether the joint's angle winds on past ±π (MuJoCo's `qpos` does): a single hinge
    /// without a limit on it, not closing a loop. Its turns are kept in the state
    /// ([`crate::State`]'s winding); a limited angle is reported on the branch centred on its
    /// range instead, and two or three hinges in one joint in (-π, π].
    pub fn winds(&self) -> bool {
        matches!(self.rot, RotDofs::Hinge { .. })
            && !self.is_loop
            && !self.limits.iter().any(|&(dof, _, _)| dof == self.ntrans)
    }
    /// The free dofs with dry friction, with their `frictionloss` (`!= 0`: a compiled
    /// friction is > 0, and the partials' differences may take it below zero without
    /// changing which dofs have a friction node).
    pub fn friction_dofs(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.frictionloss
            .iter()
            .copied()
            .enumerate()
            .filter(|&(_, f)| f != 0.0)
    }
    /// Number of free dofs with dry friction.
    pub fn nfriction(&self) -> usize {
        self.friction_dofs().count()
    }
    /// Whether any dof has armature (rotor inertia).
    pub fn has_armature(&self) -> bool {
        self.armature.iter().any(|&a| a != 0.0)
    }
    /// Reference offset of position coordinate `i` (see [`Joint::qpos_ref`]).
    pub fn qpos_ref_at(&self, i: usize) -> f64 {
        self.qpos_ref.get(i).copied().unwrap_or(0.0)
    }
}
