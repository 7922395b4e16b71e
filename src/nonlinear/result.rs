//! What a nonlinear run gives (its JSON is the result document).

use crate::kind::Timing;
use serde::Serialize;

/// One filter's figures over the run.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Summary {
    /// The iterate's number i (from 1); absent for a baseline.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub i: Option<usize>,
    /// δ on the one-step predictions: the mean of (y − h(x⁻))² over every measured
    /// value (METHOD §4's choice).
    pub delta: f64,
    /// The same on the posteriors, y − h(x⁺) (falls with the gain: not a choice).
    pub delta_posterior: f64,
    /// δ per measurement.
    pub delta_by_measurement: Vec<Option<f64>>,
    /// With a truth: per state, the RMS of x⁺ − x_true over the steps where it is known.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rms: Option<Vec<Option<f64>>>,
    /// The same of the predictions x⁻.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rms_prior: Option<Vec<Option<f64>>>,
}

/// One scale of the Q-scale baseline: an EKF with W × `scale`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ScalePoint {
    pub scale: f64,
    #[serde(flatten)]
    pub summary: Summary,
}

/// The Q-scale baseline: an EKF per scale, the scale chosen by the same δ.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct QScale {
    pub grid: Vec<ScalePoint>,
    /// The index into `grid` of the least δ (absent for an empty grid).
    pub chosen: Option<usize>,
    /// With a truth: per state, the index of the least RMS (what no user can know).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub best_rms: Option<Vec<Option<usize>>>,
}

/// A filter's state at a checkpoint.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Snapshot {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub i: Option<usize>,
    pub prior: Vec<f64>,
    pub posterior: Vec<f64>,
    /// P⁺ (N×N): the error covariance for the EKF and filter 1 only (METHOD §4).
    pub p_posterior: Vec<Vec<f64>>,
}

/// Every filter's state at step n.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Checkpoint {
    pub n: usize,
    pub t: f64,
    pub ekf: Snapshot,
    pub iterates: Vec<Snapshot>,
}

/// The decimated traces: one entry per trace point, per state or measurement.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Traces {
    /// The step n of each point (0: t0, the initial state).
    pub n: Vec<usize>,
    pub t: Vec<f64>,
    /// [measurement][point]; null where not measured (and at t0).
    pub measurements: Vec<Vec<Option<f64>>>,
    /// [state][point] with a truth; null where unknown.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth: Option<Vec<Vec<Option<f64>>>>,
    /// The plain EKF's estimate x⁺ and its SKO √P⁺ᵢᵢ, [state][point].
    pub ekf: Vec<Vec<f64>>,
    pub ekf_sko: Vec<Vec<f64>>,
    /// The estimate x⁺ of each iterate, [iterate][state][point].
    pub iterates: Vec<Vec<Vec<f64>>>,
    /// Filter 1's SKO √P⁺ᵢᵢ, [state][point] (its ±2σ band). No band is given for
    /// k ≥ 2: their P is not the error covariance of their estimate.
    pub iterate_1_sko: Vec<Vec<f64>>,
    /// The EKF at the chosen Q scale, [state][point] (absent without a grid).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub q_scaled: Option<Vec<Vec<f64>>>,
    /// Each iterate's one-step prediction residual y − h(x⁻), [iterate][measurement][point].
    pub residuals: Vec<Vec<Vec<Option<f64>>>>,
}

/// The result of a nonlinear run.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NonlinearResult {
    pub states: Vec<String>,
    pub measurements: Vec<String>,
    pub steps: usize,
    pub dt: f64,
    pub alpha: Vec<f64>,
    /// Row k−1: γ_1^k … γ_k^k.
    pub gamma: Vec<Vec<f64>>,
    /// Row k−1: the residual weights w_i^k = γ_i^k/γ_k^k.
    pub weights: Vec<Vec<f64>>,
    /// Filter k's measurement noise R_k = V/γ_k^k: its diagonal, per filter.
    pub r: Vec<Vec<f64>>,
    pub earlier_residuals: super::bank::Residuals,
    pub iterates: Vec<Summary>,
    /// The iterate of least δ (from 1).
    pub i_star: usize,
    /// The last iterate before δ first increases (K when it never does).
    pub i_stop_first_increase: usize,
    /// The iterate of least δ on the posteriors (for comparison: always the last).
    pub i_star_posterior: usize,
    /// With a truth: per state, the iterate of least RMS (what no user can know).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub best_rms: Option<Vec<Option<usize>>>,
    /// The plain EKF: W and V as the model gives them.
    pub ekf: Summary,
    pub q_scale: QScale,
    pub checkpoints: Vec<Checkpoint>,
    pub traces: Traces,
    /// CSV columns that were not used (e.g. a row counter).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub ignored_columns: Vec<String>,
    /// How many values of each measurement were used.
    pub measured: Vec<u64>,
    pub timing: Timing,
}
