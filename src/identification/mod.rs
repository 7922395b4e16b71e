//! Identification (METHOD §3, seed 003): the maximum-likelihood parameters of a
//! linear discrete-time model from measured data, with a square-root information
//! filter.
//!
//! From the bottom up: the model at one θ ([`model`]) and from kea's model format with
//! the entries' derivatives ([`discrete`]); the measurements ([`data`]); the SRIF's
//! likelihood, gradient and sample information ([`srif`]), the expected information
//! from the same arrays ([`expected`]); the minimisers
//! ([`minimise`]); the request ([`request`]), the fit and its statistics ([`fit`]),
//! the result ([`result`]), its report ([`report`]), its work estimate ([`work`]) and
//! the kind ([`kind`]).

pub mod data;
pub mod discrete;
pub mod expected;
pub mod fit;
pub mod innovations;
pub mod kind;
pub mod minimise;
pub mod model;
pub mod report;
pub mod request;
pub mod result;
pub mod simulate;
pub mod srif;
pub mod work;

pub use data::{Grid, from_csv, from_rows, to_csv};
pub use expected::expected_information;
pub use model::{Data, Discrete, Partial, Prior, PriorAt};
pub use srif::{
    Likelihood, Srif, likelihood, likelihood_and_gradient, likelihood_gradient_information,
};
