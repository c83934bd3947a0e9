//! Nonlinear solve of one time step: Newton's method on the residual `F(z⁻, z, z⁺, j) = 0`
//! (Dojo eq. 15) with the block-sparse graph factorisation of the Newton matrix.
pub(crate) mod activation;
pub(crate) mod actuation;
pub(crate) mod armature;
pub(crate) mod central;
pub(crate) mod coupling;
pub mod dense;
pub(crate) mod friction;
pub mod graph_ldu;
pub(crate) mod inequality;
pub(crate) mod ipm;
pub(crate) mod newton;
pub(crate) mod saturation;
pub(crate) mod taper;
pub(crate) mod tendon;
#[cfg(test)]
pub(crate) mod test_rng;
