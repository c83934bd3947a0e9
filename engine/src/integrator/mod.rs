//! Time discretisation: the variational integrator of Dojo §III-D.
pub mod variational;
