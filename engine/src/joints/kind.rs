//! The sixteen joint kinds: every combination of 0-3 free translations and 0-3 free rotations.
use nalgebra::Vector3;

use super::RotDofs;
use crate::math::spatial::basis_from_axis;

/// Joint kind, named by its free translations and rotations about/along `axis`
/// (Dojo.jl's prototypes). `axis = a`, and `b`, `c` complete it to a right-handed basis
/// ([`basis_from_axis`]).
///
/// | kind | free translations | free rotations |
/// |---|---|---|
/// | `Fixed` | – | – |
/// | `Prismatic` | a | – |
/// | `Planar` | b, c (plane normal a) | – |
/// | `FixedOrientation` | x, y, z | – |
/// | `Revolute` | – | about a |
/// | `Cylindrical` | a | about a |
/// | `PlanarAxis` | b, c | about a |
/// | `FreeRevolute` | x, y, z | about a |
/// | `Orbital` | – | about b then c (universal) |
/// | `PrismaticOrbital` | a | about b then c |
/// | `PlanarOrbital` | b, c | about b then c |
/// | `FreeOrbital` | x, y, z | about b then c |
/// | `Spherical` | – | ball (quaternion) |
/// | `CylindricalFree` | a | ball |
/// | `PlanarFree` | b, c | ball |
/// | `Floating` | x, y, z | ball |
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[allow(missing_docs)]
pub enum JointKind {
    Fixed,
    Prismatic,
    Planar,
    FixedOrientation,
    Revolute,
    Cylindrical,
    PlanarAxis,
    FreeRevolute,
    Orbital,
    PrismaticOrbital,
    PlanarOrbital,
    FreeOrbital,
    Spherical,
    CylindricalFree,
    PlanarFree,
    Floating,
}

impl JointKind {
    /// All sixteen kinds, ordered by (free rotations, free translations).
    pub const ALL: [JointKind; 16] = [
        JointKind::Fixed,
        JointKind::Prismatic,
        JointKind::Planar,
        JointKind::FixedOrientation,
        JointKind::Revolute,
        JointKind::Cylindrical,
        JointKind::PlanarAxis,
        JointKind::FreeRevolute,
        JointKind::Orbital,
        JointKind::PrismaticOrbital,
        JointKind::PlanarOrbital,
        JointKind::FreeOrbital,
        JointKind::Spherical,
        JointKind::CylindricalFree,
        JointKind::PlanarFree,
        JointKind::Floating,
    ];

    /// Snake-case name used in Python (`"revolute"`, `"planar_axis"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            JointKind::Fixed => "fixed",
            JointKind::Prismatic => "prismatic",
            JointKind::Planar => "planar",
            JointKind::FixedOrientation => "fixed_orientation",
            JointKind::Revolute => "revolute",
            JointKind::Cylindrical => "cylindrical",
            JointKind::PlanarAxis => "planar_axis",
            JointKind::FreeRevolute => "free_revolute",
            JointKind::Orbital => "orbital",
            JointKind::PrismaticOrbital => "prismatic_orbital",
            JointKind::PlanarOrbital => "planar_orbital",
            JointKind::FreeOrbital => "free_orbital",
            JointKind::Spherical => "spherical",
            JointKind::CylindricalFree => "cylindrical_free",
            JointKind::PlanarFree => "planar_free",
            JointKind::Floating => "floating",
        }
    }

    /// Parse a name or a common alias (`hinge`, `slide`, `ball`, `free`, `weld`, `universal`).
    pub fn from_name(name: &str) -> Option<JointKind> {
        let alias = match name {
            "hinge" => "revolute",
            "slide" => "prismatic",
            "ball" => "spherical",
            "free" => "floating",
            "weld" => "fixed",
            "universal" => "orbital",
            other => other,
        };
        JointKind::ALL.iter().copied().find(|k| k.name() == alias)
    }

    /// Number of free translations (0-3).
    pub fn ntrans(self) -> usize {
        (JointKind::ALL.iter().position(|&k| k == self).unwrap_or(0)) % 4
    }

    /// Number of free rotations (0-3).
    pub fn nrot(self) -> usize {
        (JointKind::ALL.iter().position(|&k| k == self).unwrap_or(0)) / 4
    }

    /// Translational basis (columns, free first) and rotational dofs for a unit `axis`.
    pub fn frame(self, axis: &Vector3<f64>) -> (nalgebra::Matrix3<f64>, RotDofs) {
        let m = basis_from_axis(axis);
        let (a, b, c) = (
            m.column(0).into_owned(),
            m.column(1).into_owned(),
            m.column(2).into_owned(),
        );
        // three free translations are the parent frame's x, y, z (MuJoCo's free joint)
        let trans = match self.ntrans() {
            2 => nalgebra::Matrix3::from_columns(&[b, c, a]),
            3 => nalgebra::Matrix3::identity(),
            _ => m,
        };
        let rot = match self.nrot() {
            0 => RotDofs::Locked,
            1 => RotDofs::Hinge {
                axis: a,
                perp: [b, c],
            },
            2 => RotDofs::Universal { a1: b, a2: c },
            _ => RotDofs::Ball,
        };
        (trans, rot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_counts_cover_all_combinations() {
        let mut seen = std::collections::HashSet::new();
        for k in JointKind::ALL {
            assert_eq!(JointKind::from_name(k.name()), Some(k));
            seen.insert((k.ntrans(), k.nrot()));
        }
        assert_eq!(seen.len(), 16);
        assert_eq!(JointKind::from_name("hinge"), Some(JointKind::Revolute));
        assert_eq!(JointKind::from_name("free"), Some(JointKind::Floating));
        assert_eq!(JointKind::Floating.ntrans(), 3);
        assert_eq!(JointKind::PlanarAxis.nrot(), 1);
        assert_eq!(JointKind::from_name("nope"), None);
    }
}
