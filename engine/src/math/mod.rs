//! Small fixed-size geometry: quaternions (Dojo Appendix A) and spatial helpers.
pub mod quat;
pub mod spatial;
