//! The numerical kernels the kinds share: small allocation-free matrix operations
//! ([`linalg`]) and their row kernels in portable and AVX2 form (`lanes`), the
//! Joseph-form Riccati update and the doubling algorithm for the stationary solution
//! ([`riccati`]), and the traces' decimation that keeps extremes ([`decimate`]).

pub mod decimate;
pub mod householder;
pub(crate) mod lanes;
pub mod linalg;
pub mod riccati;
