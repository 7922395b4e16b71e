//! The analysis result (JSON via serde). Field names follow METHOD.md's vocabulary:
//! a-priori (η, `eta`), measured (ζ, `zeta`), filtered (χ, `chi`); criteria sets
//! `bound` (the seed's modulus procedure) and `covariance` (exact second moments).

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AnalysisResult {
    /// Number of steps D actually used.
    pub steps: u64,
    /// Δt = (t_end − t0)/D.
    pub dt: f64,
    pub t0: f64,
    pub t_end: f64,
    /// Present when `time.steps` was `"auto"`: the history of the selection.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub step_selection: Option<StepSelection>,
    pub states: Vec<String>,
    pub measurements: Vec<String>,
    /// State↔measurement pairs used by the YZ and ZX criteria.
    pub pairs: Vec<PairOut>,
    /// y_B,i = sup_k |y_i,k| (1.5).
    pub y_max: Vec<f64>,
    /// ẏ_B,i = sup |ẏ_i| (1.4), from the continuous right-hand side on the grid.
    pub ydot_max: Vec<f64>,
    /// z_B,j = Σ_i |C_ji| y_B,i (3.21).
    pub z_max: Vec<f64>,
    /// The confidence P and λ = Φ⁻¹((1+P)/2) (3.14).
    pub confidence: f64,
    pub lambda: f64,
    pub criteria: CriteriaSets,
    #[serde(rename = "final")]
    pub final_: Final,
    pub steady_state: Option<SteadyState>,
    pub traces: Traces,
    /// The error budget, when the request asked for it (`"budget": true`).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub budget: Option<super::budget::Budget>,
    /// The mismatched filter, when the request gave a `truth`.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub mismatch: Option<Box<Mismatch>>,
    pub timing: Timing,
    /// Things the user should know (e.g. the shortcut was not applicable).
    pub warnings: Vec<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairOut {
    pub state: String,
    pub measurement: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepSelection {
    pub tolerance: f64,
    pub max_steps: u64,
    /// Whether the tolerance was met before the cap.
    pub converged: bool,
    pub history: Vec<StepTrial>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepTrial {
    pub steps: u64,
    /// Time-averaged max_i |y_D − y_2D| / max|y| against the next refinement 2D
    /// (null when 2D would exceed the cap, or when a solution overflowed: Euler
    /// unstable at this D, or the mean itself diverging).
    pub difference: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CriteriaSets {
    pub bound: CriteriaSet,
    pub covariance: CriteriaSet,
    /// Filled by a Monte Carlo run only.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub monte_carlo: Option<CriteriaSet>,
    /// From a mismatched filter's actual SKOs (a request's `truth`).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub actual: Option<CriteriaSet>,
}

/// One set of criteria: averaged per state (3.24) and weighted (3.25).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CriteriaSet {
    pub per_state: Vec<StateCriteria>,
    pub weighted: Weighted,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StateCriteria {
    pub state: String,
    /// The paired measurement, if any.
    pub measurement: Option<String>,
    pub yz: Option<f64>,
    pub zx: Option<f64>,
    pub yx: Option<f64>,
    /// For each criterion that is null: why.
    #[serde(skip_serializing_if = "BTreeMap::is_empty", default)]
    pub undefined: BTreeMap<String, String>,
    /// Steps left out of each average because a denominator was zero.
    pub excluded_steps: ExcludedSteps,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ExcludedSteps {
    pub yz: u64,
    pub zx: u64,
    pub yx: u64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Weighted {
    pub yz: Option<f64>,
    pub zx: Option<f64>,
    pub yx: Option<f64>,
    /// The weights used (N entries each; 0 for states where a criterion is undefined).
    pub weights: WeightsOut,
    #[serde(skip_serializing_if = "BTreeMap::is_empty", default)]
    pub undefined: BTreeMap<String, String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WeightsOut {
    pub yz: Vec<f64>,
    pub zx: Vec<f64>,
    pub yx: Vec<f64>,
}

/// Values at the last step D.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Final {
    /// R_D, the filtered (a-posteriori) covariance (2.7).
    pub covariance: Vec<Vec<f64>>,
    /// p_D, the gain (2.5), N×n.
    pub gain: Vec<Vec<f64>>,
    /// r_D, the predicted covariance (2.1).
    pub predicted_covariance: Vec<Vec<f64>>,
    /// Bound SKOs η_D, ζ_D, χ_D (3.16)–(3.19); null (NaN) where the bound overflowed.
    #[serde(deserialize_with = "nullable")]
    pub eta: Vec<f64>,
    pub zeta: Vec<f64>,
    #[serde(deserialize_with = "nullable")]
    pub chi: Vec<f64>,
    /// sqrt(diag R_D): the potential accuracy.
    pub potential_sko: Vec<f64>,
    /// sqrt(diag P^Y_D): open-loop (a-priori) SKO from exact covariance; null (NaN)
    /// where it overflowed.
    #[serde(deserialize_with = "nullable")]
    pub open_loop_sko: Vec<f64>,
    /// sqrt(diag Rv_D): measured SKO from exact covariance.
    pub measured_sko: Vec<f64>,
    /// Absolute error bounds ΔY = λη, ΔZ = λζ, ΔX = λχ (3.14).
    #[serde(deserialize_with = "nullable")]
    pub delta_y: Vec<f64>,
    pub delta_z: Vec<f64>,
    #[serde(deserialize_with = "nullable")]
    pub delta_x: Vec<f64>,
}

/// Numbers where JSON may have null: serde_json writes a non-finite f64 as null, so a
/// result read back (the browser's CSV, a stored job) gets NaN there again.
fn nullable<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    let v: Vec<Option<f64>> = Deserialize::deserialize(d)?;
    Ok(v.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SteadyState {
    /// The first step from which R_k and p_k no longer change (to rounding).
    pub reached_at_step: u64,
    pub t: f64,
    pub covariance: Vec<Vec<f64>>,
    pub gain: Vec<Vec<f64>>,
    /// Whether the recursion was cut short there (the shortcut).
    pub shortcut_used: bool,
}

/// Decimated traces: each bucket of steps contributes two rows carrying, for every
/// series, its minimum and maximum over the bucket in time order, so extremes survive.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Traces {
    /// Steps per bucket (1 = no decimation).
    pub bucket_steps: u64,
    pub t: Vec<f64>,
    pub states: Vec<StateTrace>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StateTrace {
    pub state: String,
    /// Mean state y.
    pub y: Vec<f64>,
    /// Bound SKOs (modulus procedure): a-priori η, measured ζ (paired), filtered χ;
    /// null where the bound overflowed, or (ζ) the measurement was unavailable for a
    /// whole trace bucket.
    pub eta: Vec<Option<f64>>,
    pub zeta: Option<Vec<Option<f64>>>,
    pub chi: Vec<Option<f64>>,
    /// Exact SKOs: potential sqrt(R_ii), open-loop sqrt(P^Y_ii) (null where it
    /// overflowed), measured sqrt(Rv_jj) (null where unavailable).
    pub potential_sko: Vec<Option<f64>>,
    pub open_loop_sko: Vec<Option<f64>>,
    pub measured_sko: Option<Vec<Option<f64>>>,
    /// Relative errors (3.20) of the bound set: D^Y, D^Z, D^X (null where the SKO is,
    /// or y_B, z_B is 0).
    pub rel_y: Vec<Option<f64>>,
    pub rel_z: Option<Vec<Option<f64>>>,
    pub rel_x: Vec<Option<f64>>,
    /// Local criteria (3.23), bound set (null where a denominator is zero).
    pub local_yz: Option<Vec<Option<f64>>>,
    pub local_zx: Option<Vec<Option<f64>>>,
    pub local_yx: Vec<Option<f64>>,
}

pub use crate::kind::Timing;

/// R_D and p_D of the filter's covariance recursion run alone
/// ([`crate::analysis::covariance_recursion`]): the analysis's `final.covariance` and
/// `final.gain`, bit for bit.
#[derive(Clone, Debug, PartialEq)]
pub struct FinalCovariance {
    /// R_D, the filtered covariance (2.7), N×N.
    pub covariance: Vec<Vec<f64>>,
    /// p_D, the gain (2.5), N×n.
    pub gain: Vec<Vec<f64>>,
}

/// The mismatched filter's result (a request's `truth`; [`crate::analysis::mismatch`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mismatch {
    /// `noise` where only the noise levels and the initial SKOs differ (A, C, u and y0
    /// the same at every step), else `structure`.
    pub differs_in: String,
    pub states: Vec<MismatchState>,
    /// The covariance set of the filter designed on the truth (the truth's analysis).
    pub optimal: CriteriaSet,
    /// Per state over time: actual, believed, optimal SKOs, at `t`.
    pub traces: MismatchTraces,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MismatchState {
    pub state: String,
    /// √(diag Cov e_D): the actual SKO of the filter's error at t_D.
    pub actual_sko: f64,
    /// E(x̂ − x)_D: the mean of the filtered error at t_D, in the Monte Carlo's sign
    /// X − Y (0 unless y0, u, a or C differ).
    pub bias: f64,
    /// √(R_D)_ii of the design: what the filter believes.
    pub believed_sko: f64,
    /// The potential SKO of the filter designed on the truth.
    pub optimal_sko: f64,
    /// actual_sko / optimal_sko: what the mismatch costs (≥ 1 up to rounding for
    /// zero bias).
    pub loss: Option<f64>,
    /// actual_sko / believed_sko: > 1, the filter is optimistic.
    pub actual_over_believed: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MismatchTraces {
    pub t: Vec<f64>,
    pub states: Vec<MismatchTrace>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MismatchTrace {
    pub state: String,
    pub actual_sko: Vec<f64>,
    pub believed_sko: Vec<f64>,
    pub optimal_sko: Vec<f64>,
}
