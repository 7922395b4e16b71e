//! Does the identified model fit the data? The innovations at θ̂ (recorded by the SRIF,
//! [`super::srif::Srif::recording`]): their NIS against its χ² band, and per
//! measurement a whiteness test (Ljung–Box) on the standardized innovations — under
//! the model they are white with unit variance (METHOD §1.8's consistency checks, for
//! data that are not simulated).

use crate::monte_carlo::bands::{BAND_PROBABILITY, chi2_band, chi2_quantile};
use serde::Serialize;

/// The most lags of the whiteness test (fewer for short records: a quarter of them).
pub const MAX_LAGS: usize = 20;
/// The most steps of [`InnovationTrace`].
pub const TRACE_POINTS: usize = 1000;

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
    /// The innovations over time, for a plot.
    pub trace: InnovationTrace,
}

/// At most [`TRACE_POINTS`] steps of the innovations: the steps cut into equal runs of
/// `bucket` steps, and of each run the step with the largest NIS (an outlier is never
/// decimated away); null where a measurement is missing. The whole series is the
/// kind's CSV.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InnovationTrace {
    pub bucket: usize,
    pub t: Vec<f64>,
    pub nis: Vec<f64>,
    /// Per measurement (the model's order), ν/√S at each of those steps.
    pub innovations: Vec<Vec<Option<f64>>>,
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

/// The checks from the recorded innovations (D × m) and NIS (D) at the steps `t`.
pub fn check(innovations: &[f64], nis: &[f64], names: &[String], t: &[f64]) -> InnovationCheck {
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
        trace: trace(innovations, nis, m, t),
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

/// [`InnovationTrace`]: of each run of `bucket` steps, the step with the largest NIS.
fn trace(innovations: &[f64], nis: &[f64], m: usize, t: &[f64]) -> InnovationTrace {
    let bucket = nis.len().div_ceil(TRACE_POINTS).max(1);
    let steps: Vec<usize> = (0..nis.len())
        .step_by(bucket)
        .filter_map(|start| {
            (start..(start + bucket).min(nis.len()))
                .filter(|&k| !nis[k].is_nan())
                .max_by(|&a, &b| nis[a].total_cmp(&nis[b]).then(b.cmp(&a)))
        })
        .collect();
    let value = |x: f64| (!x.is_nan()).then_some(x);
    InnovationTrace {
        bucket,
        t: steps.iter().map(|&k| t[k]).collect(),
        nis: steps.iter().map(|&k| nis[k]).collect(),
        innovations: (0..m)
            .map(|j| {
                steps
                    .iter()
                    .map(|&k| value(innovations[k * m + j]))
                    .collect()
            })
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 2500 steps in runs of 3: 834 points, each run's largest NIS (the outlier kept),
    /// a run with nothing measured left out, a missing measurement null.
    #[test]
    fn the_trace_keeps_each_runs_largest_nis() {
        let d = 2500;
        let t: Vec<f64> = (1..=d).map(|k| k as f64 * 0.5).collect();
        let mut nis: Vec<f64> = (0..d).map(|k| (k % 3) as f64 * 0.1 + 0.5).collect();
        let mut innovations: Vec<f64> = (0..2 * d).map(|k| k as f64).collect();
        nis[1000] = 40.0; // an outlier at the start of its run (999..1002)
        for k in 3..6 {
            nis[k] = f64::NAN; // a run with nothing measured
            innovations[2 * k] = f64::NAN;
            innovations[2 * k + 1] = f64::NAN;
        }
        innovations[2 * 8 + 1] = f64::NAN; // step 8, the largest of its run: one missing
        let tr = trace(&innovations, &nis, 2, &t);
        assert_eq!(tr.bucket, 3);
        assert_eq!(tr.t.len(), 833);
        assert!(tr.t.len() <= TRACE_POINTS);
        let at =
            tr.t.iter()
                .position(|&x| x == 1001.0 * 0.5)
                .expect("the outlier");
        assert_eq!(tr.nis[at], 40.0);
        assert_eq!(tr.t[0], 3.0 * 0.5); // step 2 of run 0..3 (NIS 0.7)
        assert_eq!(tr.t[1], 9.0 * 0.5); // run 3..6 is empty: the next is step 8
        assert_eq!(tr.innovations[0][1], Some(16.0));
        assert_eq!(tr.innovations[1][1], None);
    }
}
