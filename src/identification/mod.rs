//! Identification (METHOD §3, seed 003): the maximum-likelihood parameters of a
//! linear model from measured data, with a square-root information filter.
//!
//! Built so far: the discrete-time model at one θ ([`model`]), and the SRIF's
//! likelihood J(θ), its gradient and its sample information ([`srif`]). To come
//! (issue 38): the model format's discrete form, the entries' derivatives from the
//! expressions, data CSVs, the minimisers, and the kind in the registry.

pub mod minimise;
pub mod model;
pub mod srif;

pub use model::{Data, Discrete, Partial, Prior, PriorAt};
pub use srif::{
    Likelihood, Srif, likelihood, likelihood_and_gradient, likelihood_gradient_information,
};
