//! The identification's result document (docs/identification.md): the estimates with
//! their standard errors and intervals, J and its gradient at the optimum, the
//! information matrices, the identifiability verdict and every iteration.

use super::minimise::{Method, Stop};
use crate::kind::Timing;
use serde::Serialize;
use std::collections::BTreeMap;

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IdentificationResult {
    /// The estimated params, in the order of every vector and matrix below.
    pub parameters: Vec<String>,
    pub estimate: BTreeMap<String, ParamEstimate>,
    /// J(θ̂) = −ln L, the 2π constant included (METHOD §3 (2.1.3)).
    pub neg_log_likelihood: f64,
    /// ∂J/∂θ at θ̂.
    pub gradient: BTreeMap<String, f64>,
    /// The sample Fisher information at θ̂ (seed (2.3.2), Harvey's form): what the
    /// standard errors use.
    pub fisher_information: Vec<Vec<f64>>,
    /// The observed information, the Hessian of J at θ̂ (central differences of the
    /// exact gradient, one Richardson step); null where θ̂ ± h leaves the model's domain.
    pub observed_information: Option<Vec<Vec<f64>>>,
    /// The expected information at θ̂ (its expectation over data drawn from the model
    /// at θ̂ on the data's steps, with their missing measurements): with
    /// `expected_information: true` in the request, else null.
    pub expected_information: Option<Vec<Vec<f64>>>,
    /// The estimates' correlations, from the inverse sample information; null when it
    /// is singular.
    pub correlation: Option<Vec<Vec<f64>>>,
    pub identifiability: Identifiability,
    /// Does the model at θ̂ fit the data: the innovations' NIS and whiteness (null
    /// when nothing was measured).
    pub innovations: Option<super::innovations::InnovationCheck>,
    /// Every distinct optimum the starts reached (the initial values, then `starts`),
    /// lowest J first: the estimate is the first.
    pub optima: Vec<Optimum>,
    pub method: Method,
    pub converged: bool,
    pub stop: Stop,
    /// What `stop` means, in words.
    pub stop_reason: String,
    /// The initial point and every accepted step.
    pub iterations: Vec<IterationRecord>,
    /// J evaluations made (line-search trials included).
    pub evaluations: usize,
    /// D, the data's rows (grid steps), and the scalar measurements used.
    pub steps: usize,
    pub measurements: usize,
    pub timing: Timing,
    /// The innovations at θ̂ step by step, for the CSV (not in the JSON: D rows).
    #[serde(skip)]
    pub series: Option<InnovationSeries>,
}

/// Each step's t, NIS and standardized innovations (D × m; NaN where missing).
#[derive(Clone, Debug, PartialEq)]
pub struct InnovationSeries {
    pub measurements: Vec<String>,
    pub t: Vec<f64>,
    pub nis: Vec<f64>,
    pub innovations: Vec<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ParamEstimate {
    pub value: f64,
    /// √((M⁻¹)_ii) with M the sample information; null when M is singular.
    pub std_error: Option<f64>,
    /// value ± 1.96 std_error (95 %); null with the standard error.
    pub interval: Option<[f64; 2]>,
    /// The Cramér–Rao bound on the estimate's SKO at θ̂, √((I⁻¹)_ii) with I the
    /// expected information: null unless the request asks for it
    /// (`expected_information`) and I is regular.
    pub cramer_rao_sko: Option<f64>,
    pub initial: f64,
    /// The bounds as given (absent: unbounded) and whether θ̂ sits on one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    pub at_bound: bool,
}

/// Whether the data determine every estimated param: the eigenvalues of the sample
/// information at θ̂, its condition number and, when its smallest eigenvalue is below
/// 1e-9 of the largest, the direction the data cannot determine, in words.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Identifiability {
    pub identifiable: bool,
    /// Ascending.
    pub eigenvalues: Vec<f64>,
    /// λ_max / λ_min (null when λ_min ≤ 0).
    pub condition: Option<f64>,
    /// The unit eigenvector of the smallest eigenvalue, by param.
    pub weakest_direction: BTreeMap<String, f64>,
    /// The eigenvalues above 1e-9 λ_max.
    pub rank: usize,
    pub verdict: String,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct IterationRecord {
    pub neg_log_likelihood: f64,
    pub params: BTreeMap<String, f64>,
    pub gradient_norm: f64,
    /// The step length accepted (0 for the initial point).
    pub step: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Optimum {
    pub params: BTreeMap<String, f64>,
    pub neg_log_likelihood: f64,
    pub converged: bool,
    /// The starts that reached it: 0 the initial values, i the i-th of `starts`.
    pub starts: Vec<usize>,
}
