//! Mass properties of MJCF geoms and bodies (MuJoCo's formulas for solid primitives, density
//! default 1000 kg/m³, `mass=` overriding the density) and their sum about the body's COM.
use nalgebra::{Matrix3, Vector3};

use crate::math::quat::{self, Quat};

/// Volume and principal inertia per unit density of a primitive (MuJoCo's geom sizes).
/// `None` for shapes without volume (planes).
pub(super) fn unit_inertia(kind: &str, size: &[f64]) -> Option<(f64, Vector3<f64>)> {
    use std::f64::consts::PI;
    match kind {
        "sphere" => {
            let r = size[0];
            let v = 4.0 / 3.0 * PI * r.powi(3);
            Some((v, Vector3::repeat(0.4 * v * r * r)))
        }
        "capsule" => {
            // cylinder of height h plus two hemispheres (their COMs 3r/8 beyond the cylinder)
            let (r, h) = (size[0], 2.0 * size[1]);
            let vs = 4.0 / 3.0 * PI * r.powi(3);
            let vc = PI * r * r * h;
            let ixy = vc * (3.0 * r * r + h * h) / 12.0
                + vs * (0.4 * r * r + 0.375 * r * h + 0.25 * h * h);
            let iz = (0.5 * vc + 0.4 * vs) * r * r;
            Some((vs + vc, Vector3::new(ixy, ixy, iz)))
        }
        "cylinder" => {
            let (r, h) = (size[0], 2.0 * size[1]);
            let v = PI * r * r * h;
            let ixy = v * (3.0 * r * r + h * h) / 12.0;
            Some((v, Vector3::new(ixy, ixy, 0.5 * v * r * r)))
        }
        "box" => {
            let (a, b, c) = (size[0], size[1], size[2]);
            let v = 8.0 * a * b * c;
            Some((
                v,
                Vector3::new(b * b + c * c, a * a + c * c, a * a + b * b) * (v / 3.0),
            ))
        }
        "ellipsoid" => {
            let (a, b, c) = (size[0], size[1], size[2]);
            let v = 4.0 / 3.0 * PI * a * b * c;
            Some((
                v,
                Vector3::new(b * b + c * c, a * a + c * c, a * a + b * b) * (v / 5.0),
            ))
        }
        _ => None,
    }
}

/// Mass, COM and inertia about the COM (body frame) accumulated from parts.
#[derive(Clone, Debug, Default)]
pub(super) struct MassProps {
    pub mass: f64,
    /// Σ m c
    first: Vector3<f64>,
    /// Σ (I_c + m (|c|² 1 − c cᵀ)) about the body origin
    second: Matrix3<f64>,
}

impl MassProps {
    /// Add a part of `mass` with principal `inertia` at `pos`, principal axes `quat`.
    pub fn add(&mut self, mass: f64, inertia: &Vector3<f64>, pos: &Vector3<f64>, q: &Quat) {
        let r = quat::rotation(q);
        let i = r * Matrix3::from_diagonal(inertia) * r.transpose();
        self.mass += mass;
        self.first += pos * mass;
        self.second +=
            i + (Matrix3::identity() * pos.norm_squared() - pos * pos.transpose()) * mass;
    }

    /// COM and inertia about it (body frame); zeros if massless.
    pub fn com_inertia(&self) -> (Vector3<f64>, Matrix3<f64>) {
        if self.mass <= 0.0 {
            return (Vector3::zeros(), Matrix3::zeros());
        }
        let c = self.first / self.mass;
        let shift = (Matrix3::identity() * c.norm_squared() - c * c.transpose()) * self.mass;
        let i = self.second - shift;
        (c, (i + i.transpose()) * 0.5)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn capsule_tends_to_sphere_and_cylinder_limits() {
        let (v, i) = unit_inertia("capsule", &[0.3, 1e-12]).unwrap();
        let (vs, is) = unit_inertia("sphere", &[0.3]).unwrap();
        assert!((v - vs).abs() < 1e-12 && (i - is).norm() < 1e-12);
        // long capsule ≈ cylinder
        let (v, i) = unit_inertia("capsule", &[1e-4, 1.0]).unwrap();
        let (vc, ic) = unit_inertia("cylinder", &[1e-4, 1.0]).unwrap();
        assert!((v - vc).abs() / vc < 1e-3 && (i[0] - ic[0]).abs() / ic[0] < 1e-3);
    }

    #[test]
    fn parallel_axis_theorem() {
        let mut m = MassProps::default();
        let q = quat::identity();
        m.add(
            2.0,
            &Vector3::new(1.0, 1.0, 1.0),
            &Vector3::new(1.0, 0.0, 0.0),
            &q,
        );
        m.add(
            2.0,
            &Vector3::new(1.0, 1.0, 1.0),
            &Vector3::new(-1.0, 0.0, 0.0),
            &q,
        );
        let (c, i) = m.com_inertia();
        assert!(c.norm() < 1e-15);
        assert!((i - Matrix3::from_diagonal(&Vector3::new(2.0, 6.0, 6.0))).norm() < 1e-12);
    }
}
