//! The model format: what a user submits (JSON, serde), before validation.
//!
//! Every matrix entry is a [`Value`]: a number or an expression string in `t` and the
//! model's `params`. Validation (`crate::model::compile`) turns a [`Model`] into a
//! `CompiledModel` or a list of errors naming the exact field path.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The version of the model format this build reads and writes.
pub const MODEL_FORMAT_VERSION: u32 = 1;

pub use crate::expr::Value;

/// A complete model (METHOD §1.1): dynamic system, measurements, criteria, options.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Model {
    /// Format version; absent means the current one.
    #[serde(default = "default_version")]
    pub kea_model: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// Named numbers usable in every expression.
    #[serde(default)]
    pub params: BTreeMap<String, f64>,
    pub time: Time,
    pub system: System,
    pub measurement: Measurement,
    #[serde(default)]
    pub criteria: Criteria,
    #[serde(default)]
    pub options: Options,
}

fn default_version() -> u32 {
    MODEL_FORMAT_VERSION
}

/// The time grid (METHOD §1.2): `t0`, `t_end` and the number of steps D.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Time {
    pub t0: f64,
    pub t_end: f64,
    /// An integer D, or the string `"auto"` (step-size selection, METHOD §1.2).
    pub steps: Steps,
    /// Settings of `steps: "auto"`; ignored for an integer `steps`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub auto: Option<AutoSteps>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Steps {
    Fixed(u64),
    Auto(String),
}

/// By hand, for errors that say what is expected (serde's untagged derive says "data
/// did not match any variant"). A whole number written as a float (`1e6`, `1000.0`)
/// is D; one over the limit of steps is refused here, as written (`1e30`, not
/// saturated to u64's largest).
impl<'de> Deserialize<'de> for Steps {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        struct V;
        impl serde::de::Visitor<'_> for V {
            type Value = Steps;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a positive whole number of steps D, or \"auto\"")
            }
            fn visit_u64<E>(self, x: u64) -> Result<Steps, E> {
                Ok(Steps::Fixed(x))
            }
            fn visit_i64<E: Error>(self, x: i64) -> Result<Steps, E> {
                u64::try_from(x).map(Steps::Fixed).map_err(|_| {
                    E::custom(format!(
                        "expected a positive whole number of steps D, or \"auto\"; got {x}"
                    ))
                })
            }
            fn visit_f64<E: Error>(self, x: f64) -> Result<Steps, E> {
                if x >= 0.0 && x.fract() == 0.0 && x <= crate::model::limits::MAX_STEPS as f64 {
                    Ok(Steps::Fixed(x as u64))
                } else if x.fract() == 0.0 && x > 0.0 {
                    Err(E::custom(format!(
                        "{x:e} steps is more than the limit of {}",
                        crate::model::limits::MAX_STEPS
                    )))
                } else {
                    Err(E::custom(format!(
                        "expected a positive whole number of steps D, or \"auto\"; got {x}"
                    )))
                }
            }
            fn visit_str<E>(self, s: &str) -> Result<Steps, E> {
                Ok(Steps::Auto(s.to_string()))
            }
        }
        d.deserialize_any(V)
    }
}

/// Step-size selection: D, 2D, 4D, … until successive mean solutions agree.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AutoSteps {
    /// Time-averaged |Δy| between successive solutions, relative to max|y|.
    #[serde(default = "default_auto_tolerance")]
    pub tolerance: f64,
    /// The first D tried.
    #[serde(default = "default_auto_initial")]
    pub initial_steps: u64,
    /// The cap: never more steps than this.
    #[serde(default = "default_auto_max")]
    pub max_steps: u64,
}

impl Default for AutoSteps {
    fn default() -> Self {
        AutoSteps {
            tolerance: default_auto_tolerance(),
            initial_steps: default_auto_initial(),
            max_steps: default_auto_max(),
        }
    }
}

fn default_auto_tolerance() -> f64 {
    1e-9
}
fn default_auto_initial() -> u64 {
    1000
}
fn default_auto_max() -> u64 {
    4_096_000
}

/// The dynamic system dY/dt = a(t) Y + u(t) + b(t) F (1.1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct System {
    /// State names; their count is N.
    pub states: Vec<String>,
    /// N×N, the continuous model's a(t); absent in a discrete model (`transition`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub a: Vec<Vec<Value>>,
    /// Φ (N×N) of a discrete-time model, in place of `a`: x_k = Φ x_{k−1} + u + b F,
    /// F ~ N(0, W), with no Δt scaling (METHOD §3 (1.4.1)). Read by the identification.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transition: Option<Vec<Vec<Value>>>,
    /// Where the initial state (y0, η0) sits; absent: at t0 ([`PriorAt::T0`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior_at: Option<PriorAt>,
    /// N; zero when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u: Option<Vec<Value>>,
    /// N×L.
    pub b: Vec<Vec<Value>>,
    /// Initial mean (N); zero when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub y0: Option<Vec<Value>>,
    /// Initial SKOs η0 (N); zero when absent. R0 = diag(η0²).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eta0: Option<Vec<Value>>,
    /// Model-error SKOs φ (L), W = diag(φ²) (1.17) — or give `W`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phi: Option<Vec<Value>>,
    /// Full model-error covariance W (L×L), instead of `phi`.
    #[serde(default, rename = "W", skip_serializing_if = "Option::is_none")]
    pub w: Option<Vec<Vec<Value>>>,
}

/// Where the initial state x ~ N(y0, diag η0²) sits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PriorAt {
    /// At t0, one transition before the first measurement at t_1 (kea's convention,
    /// as in the analysis).
    #[default]
    T0,
    /// At the first measurement itself: x_1 ~ N(y0, diag η0²) (statsmodels' and Durbin
    /// and Koopman's convention, and the identification references'). Discrete models
    /// only.
    FirstMeasurement,
}

/// The measurements Z = C y + Γ(t) Φ (1.2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Measurement {
    /// Measurement names; their count is n ≤ N.
    pub names: Vec<String>,
    /// n×N, constant (expressions may use params, not `t`).
    pub c: Vec<Vec<Value>>,
    /// n×M noise matrix Γ(t).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gamma: Option<Vec<Vec<Value>>>,
    /// The seed's form N×M: Z = c (y + g Φ), i.e. Γ = c g. Give `gamma` or `g`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub g: Option<Vec<Vec<Value>>>,
    /// Measurement-error SKOs ψ (M), V = diag(ψ²) (1.18) — or give `V`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psi: Option<Vec<Value>>,
    /// Full measurement-error covariance V (M×M), instead of `psi`.
    #[serde(default, rename = "V", skip_serializing_if = "Option::is_none")]
    pub v: Option<Vec<Vec<Value>>>,
    /// When each measurement is available (n entries, null = always); absent = always.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub schedule: Option<Vec<Option<Schedule>>>,
    /// Explicit state↔measurement pairs; when absent they are inferred from C.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pairs: Option<Vec<Pair>>,
}

/// `every`: a whole number of steps from 1 (0 is refused with the schedule's rules).
fn every_steps<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<u64>, D::Error> {
    crate::json::whole_in::<_, u64, 1, { u64::MAX }>(d).map(Some)
}

/// Availability of one measurement: exactly one of `every`, `when`, `unavailable`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    /// Available at every k-th step (k ≡ offset mod every).
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "every_steps"
    )]
    pub every: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset: Option<u64>,
    /// Available where this expression in t (and params) is > 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub when: Option<Value>,
    /// Unavailable inside these closed intervals [t_from, t_to].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unavailable: Option<Vec<[f64; 2]>>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pair {
    pub state: String,
    pub measurement: String,
}

/// Weights and confidence of the criteria (3.25), (3.26), (3.14).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Criteria {
    #[serde(default)]
    pub weights: Weights,
    /// Confidence probability P for the Laplace coefficient λ = Φ⁻¹((1+P)/2).
    #[serde(default = "default_confidence")]
    pub confidence: f64,
}

impl Default for Criteria {
    fn default() -> Self {
        Criteria {
            weights: Weights::default(),
            confidence: default_confidence(),
        }
    }
}

fn default_confidence() -> f64 {
    0.95
}

/// Per-state weights k_i of each criterion (N entries each, summing to 1).
/// Absent: equal weights over the states where the criterion is defined.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Weights {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub yz: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zx: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub yx: Option<Vec<f64>>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Options {
    /// Rows kept in the decimated traces (each bucket keeps its extremes); 0: no traces.
    #[serde(default = "default_trace_points")]
    pub trace_points: usize,
    /// For time-invariant models: stop the Riccati recursion once it is stationary.
    #[serde(default = "default_true")]
    pub steady_state_shortcut: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            trace_points: default_trace_points(),
            steady_state_shortcut: true,
        }
    }
}

fn default_trace_points() -> usize {
    1000
}
fn default_true() -> bool {
    true
}

#[cfg(test)]
mod tests {
    use super::Model;

    /// Numbers are read correctly rounded (serde_json's `float_roundtrip`): a model's
    /// decimals are the nearest f64, and a result written as JSON and read back (a
    /// download, the browser's traces CSV) is the f64 that was written. The default
    /// parser is one unit in the last place off for some of these.
    #[test]
    fn numbers_read_back_exactly() {
        for text in [
            "1.7731769618770617e-6",
            "130.65331632653061",
            "0.1",
            "2.8000000000000003",
        ] {
            let v: f64 = serde_json::from_str(text).unwrap();
            assert_eq!(
                v.to_bits(),
                text.parse::<f64>().unwrap().to_bits(),
                "{text}"
            );
        }
        // Written and read back: every bit pattern of a pseudo-random sample.
        let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
        for _ in 0..200_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let v = f64::from_bits(x);
            if !v.is_finite() {
                continue;
            }
            let back: f64 = serde_json::from_str(&serde_json::to_string(&v).unwrap()).unwrap();
            assert_eq!(back.to_bits(), v.to_bits(), "{v:e}");
        }
        // And in a model.
        let m: Model = serde_json::from_str(
            r#"{"time": {"t0": 0, "t_end": 1, "steps": 10},
                "system": {"states": ["x"], "a": [[-1]], "b": [[1]], "phi": [1.7731769618770617e-6],
                           "y0": [1], "eta0": [0.1]},
                "measurement": {"names": ["z"], "c": [[1]], "gamma": [[1]], "psi": [0.1]}}"#,
        )
        .unwrap();
        let json = serde_json::to_value(&m).unwrap();
        assert_eq!(
            json["system"]["phi"][0].as_f64(),
            Some(1.7731769618770617e-6)
        );
    }
}
