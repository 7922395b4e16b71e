//! Does the identified model fit the data? The innovations at θ̂ (recorded by the SRIF,
//! [`super::srif::Srif::recording`]): their NIS against its χ² band, and per
//! measurement a whiteness test (Ljung–Box) on the standardized innovations — under
//! the model they are white with unit variance (METHOD §1.8's consistency checks, for
//! data that are not simulated).

use crate::monte_carlo::bands::{BAND_PROBABILITY, chi2_band, chi2_quantile};
use serde::Serialize;

/// The most lags of the whiteness test (fewer for short records: a quarter of them).
pub const MAX_LAGS: usize = 20;

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InnovationCheck {
    /// Σ NIS / Σ m_k over the steps with measurements: 1 for a model that fits.
    pub nis_mean: f64,
    /// Its two-sided 95 % χ² band, χ²_{Σm}(0.025, 0.975) / Σm.
    pub nis_band: [f64; 2],
    pub nis_consistent: bool,
    /// Σ m_k, the χ² degrees of freedom.
    pub degrees_of_freedom: usize,
    /// Per measurement, in the model's order.
    pub whiteness: Vec<Whiteness>,
}

/// The Ljung–Box test of one measurement's standardized innovations: Q = n(n + 2)
/// Σ_{k=1..L} ρ_k² / (n − k) against χ²_L's 95 % quantile, ρ_k the sample
/// autocorrelation at lag k over the pairs where both are measured.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Whiteness {
    pub measurement: String,
    /// The innovations used (n) and the lags (L).
    pub count: usize,
    pub lags: usize,
    /// ρ_1 … ρ_L.
    pub autocorrelation: Vec<f64>,
    pub ljung_box: f64,
    pub critical: f64,
    pub white: bool,
    /// The standardized innovations' sample mean and variance (0 and 1 for a model
    /// that fits).
    pub mean: f64,
    pub variance: f64,
}

/// The checks from the recorded innovations (D × m) and NIS (D).
pub fn check(innovations: &[f64], nis: &[f64], names: &[String]) -> InnovationCheck {
    let m = names.len();
    let total: f64 = nis.iter().filter(|x| !x.is_nan()).sum();
    let dof = innovations.iter().filter(|x| !x.is_nan()).count();
    let nis_mean = total / dof as f64;
    let nis_band = chi2_band(dof as f64, dof as f64);
    InnovationCheck {
        nis_mean,
        nis_band,
        nis_consistent: nis_band[0] <= nis_mean && nis_mean <= nis_band[1],
        degrees_of_freedom: dof,
        whiteness: (0..m)
            .map(|j| {
                let series: Vec<f64> = innovations.iter().skip(j).step_by(m).copied().collect();
                whiteness(&series, &names[j])
            })
            .collect(),
    }
}

fn whiteness(x: &[f64], name: &str) -> Whiteness {
    let present: Vec<f64> = x.iter().copied().filter(|v| !v.is_nan()).collect();
    let n = present.len();
    let mean = present.iter().sum::<f64>() / n as f64;
    let c0: f64 = present.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>();
    let lags = MAX_LAGS.min(n / 4);
    let autocorrelation: Vec<f64> = (1..=lags)
        .map(|k| {
            let ck: f64 = (0..x.len().saturating_sub(k))
                .filter(|&t| !x[t].is_nan() && !x[t + k].is_nan())
                .map(|t| (x[t] - mean) * (x[t + k] - mean))
                .sum();
            ck / c0
        })
        .collect();
    let nf = n as f64;
    let ljung_box = nf
        * (nf + 2.0)
        * autocorrelation
            .iter()
            .enumerate()
            .map(|(i, r)| r * r / (nf - (i + 1) as f64))
            .sum::<f64>();
    let critical = if lags > 0 {
        chi2_quantile(lags as f64, BAND_PROBABILITY)
    } else {
        f64::NAN
    };
    Whiteness {
        measurement: name.to_string(),
        count: n,
        lags,
        autocorrelation,
        ljung_box,
        critical,
        white: lags > 0 && ljung_box <= critical,
        mean,
        variance: c0 / nf,
    }
}
