//! Nonlinear estimation (METHOD §4, seed 002): the extended Kalman filter and the
//! iterative regularised procedure — K filters over the same data, filter k an EKF
//! with R_k = V/γ_k^k driven also by the earlier filters' residuals — with the
//! iterate chosen by δ on the one-step predictions, beside two baselines: the plain
//! EKF and EKFs whose Q scale is chosen by the same δ.
//!
//! `model` (format, compile), `gamma` (the weights), `bank` (the filters stepped
//! together), `data` (CSV and inline rows, with the truth where given), `truth`
//! (data simulated from a truth model), `request`, `run`, `result`, `report`,
//! `work`, `kind`.

pub mod bank;
pub mod data;
pub mod gamma;
pub mod kind;
pub mod model;
pub mod report;
pub mod request;
pub mod result;
pub mod run;
pub mod truth;
pub mod work;

pub use model::{Compiled, NonlinearModel};
pub use request::NonlinearRequest;
pub use result::NonlinearResult;

/// The data a request runs on as CSV ([`data::to_csv`]): read, or simulated from its
/// truth (as the run will: the same bits).
pub fn data_csv(r: &NonlinearRequest) -> Result<String, crate::Error> {
    let m = &r.model;
    let grid = m.grid();
    let simulated;
    let d = match &r.source {
        request::Source::Truth(t) => {
            simulated = truth::simulate(t, "data.truth")?;
            &simulated
        }
        _ => &r.data,
    };
    Ok(data::to_csv(d, &m.names, &m.states, grid))
}
