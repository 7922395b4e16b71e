//! The Monte Carlo's result (METHOD §1.8): the three criteria sets side by side,
//! consistency (average NEES and NIS with their χ² bands, a verdict per state), the
//! sample and potential SKOs at the last step, and the traces.

use super::request::MonteCarloRequest;
use crate::analysis::result::{CriteriaSets, Timing};
use serde::{Deserialize, Serialize};

/// The Monte Carlo result (JSON via serde).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MonteCarloResult {
    pub request: MonteCarloRequest,
    pub steps: u64,
    pub dt: f64,
    pub t0: f64,
    pub t_end: f64,
    pub states: Vec<String>,
    pub measurements: Vec<String>,
    /// y_B and z_B (1.5), (3.21) of the analysis, used by every criteria set.
    pub y_max: Vec<f64>,
    pub z_max: Vec<f64>,
    /// The three criteria sets side by side: `bound`, `covariance`, `monte_carlo`.
    pub criteria: CriteriaSets,
    pub consistency: Consistency,
    /// Sample and potential SKOs at the last step D.
    #[serde(rename = "final")]
    pub final_: MonteCarloFinal,
    pub traces: MonteCarloTraces,
    pub timing: Timing,
    pub warnings: Vec<String>,
}

/// Consistency of the potential accuracy with the simulated one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Consistency {
    /// Probability of the χ² acceptance bands (two-sided).
    pub band_probability: f64,
    /// Average NEES (1/R) Σ e_kᵀ R_k⁻¹ e_k of the filtered error.
    pub nees: ConsistencyStat,
    /// Average NIS (1/R) Σ ν_kᵀ q_k⁻¹ ν_k of the innovations (available measurements).
    pub nis: ConsistencyStat,
    pub per_state: Vec<StateVerdict>,
    /// With a truth (a mismatched filter): per state, the sample variance of the
    /// filtered error about its sample mean against the *actual* error variance of
    /// the filter designed on the model (band χ²_{R−1} / (R − 1)); its bias, the
    /// sample mean less the actual bias, in actual SKOs. `per_state` then judges what
    /// the filter believes (R_ii).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub per_state_actual: Option<Vec<StateVerdict>>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConsistencyStat {
    /// Degrees of freedom of one run at one step (N for NEES; the number of
    /// available measurements for NIS, here at the last step).
    pub dof: f64,
    /// The statistic averaged over runs and over the steps where it is defined.
    pub time_average: Option<f64>,
    /// The acceptance band of the run-average at one step: χ²_{R·dof} quantiles / R.
    pub band: [f64; 2],
    /// Fraction of the steps whose run-average lies inside its band (≈ the band
    /// probability when consistent; steps are correlated, so it varies).
    pub fraction_in_band: Option<f64>,
    /// Steps where it is undefined (R_k or q_k singular, or nothing measured).
    pub undefined_steps: u64,
    pub verdict: Verdict,
}

/// Per state: the sample variance of the filtered error against R_ii.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StateVerdict {
    pub state: String,
    /// Time average of (sample variance / R_ii) over the steps with R_ii > 0.
    pub variance_ratio: Option<f64>,
    /// The band of one step's ratio for R runs: χ²_R quantiles / R. The time average
    /// of correlated steps is at least as tight, so this band is conservative.
    pub band: [f64; 2],
    /// Fraction of the steps whose ratio lies inside the band.
    pub fraction_in_band: Option<f64>,
    /// Sample mean of the filtered error over runs and steps, in units of sqrt(R_ii)
    /// (a bias check; ≈ 0 when consistent).
    pub normalised_bias: Option<f64>,
    pub verdict: Verdict,
}

/// Plain verdict: is the potential (Riccati) accuracy believable?
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    /// The real errors agree with the potential ones.
    Consistent,
    /// The real errors are larger than the potential ones: the Riccati promises more.
    Optimistic,
    /// The real errors are smaller than the potential ones.
    Pessimistic,
    /// Nothing to judge (no step where the statistic is defined).
    Undefined,
}

impl Verdict {
    pub(super) fn of(value: Option<f64>, band: [f64; 2]) -> Verdict {
        match value {
            None => Verdict::Undefined,
            Some(v) if v > band[1] => Verdict::Optimistic,
            Some(v) if v < band[0] => Verdict::Pessimistic,
            Some(_) => Verdict::Consistent,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MonteCarloFinal {
    /// Sample SKOs at step D: a-priori (Y − y), measured (paired; null if the
    /// measurement is not available at D), filtered (X − truth).
    pub a_priori_sko: Vec<f64>,
    pub measured_sko: Vec<Option<f64>>,
    pub filtered_sko: Vec<f64>,
    /// sqrt(diag R_D) and the bound χ_D (3.19).
    pub potential_sko: Vec<f64>,
    pub chi: Vec<f64>,
    /// With a truth: the filter's actual error SKO (about its mean) and bias at D.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub actual_sko: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub actual_bias: Option<Vec<f64>>,
}

/// Traces: each row is the average over a bucket of `bucket_steps` steps (variances
/// are averaged, then square-rooted), at the bucket's last time.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MonteCarloTraces {
    pub bucket_steps: u64,
    pub t: Vec<f64>,
    pub states: Vec<MonteCarloStateTrace>,
    /// Average NEES per row (null where undefined) and its per-step band.
    pub nees: Vec<Option<f64>>,
    pub nis: Vec<Option<f64>>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MonteCarloStateTrace {
    pub state: String,
    /// Sample SKO of the a-priori error Y − y.
    pub a_priori_sko: Vec<f64>,
    /// Exact open-loop SKO sqrt(P^Y_ii) (what a_priori_sko estimates).
    pub open_loop_sko: Vec<f64>,
    /// Sample SKO of the paired measurement's error ΓΦ (null rows: not available).
    pub measured_sko: Option<Vec<Option<f64>>>,
    /// Sample SKO and sample mean of the filtered error X − truth.
    pub filtered_sko: Vec<f64>,
    pub filtered_mean: Vec<f64>,
    /// Potential SKO sqrt(R_ii) and the bound χ (3.19).
    pub potential_sko: Vec<f64>,
    pub chi: Vec<f64>,
    /// With a truth: the filter's actual error SKO (about its mean) and bias.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub actual_sko: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub actual_bias: Option<Vec<f64>>,
}
