//! The sensitivity result (JSON via serde).

use crate::kind::Timing;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SensitivityResult {
    /// h: every param p was analysed at p e^h and p e^−h.
    pub relative_step: f64,
    /// The criterion the params are listed by (largest |S| first; undefined last).
    pub rank_by: String,
    /// D of every analysis (the base one's, also for `"auto"`).
    pub steps: u64,
    /// The base analysis's weighted criteria (3.25).
    pub base: Criteria,
    /// Per param, ranked.
    pub params: Vec<ParamSensitivity>,
    /// Analyses run: 1 + 2 per param not at 0.
    pub analyses: u64,
    /// The base analysis's warnings.
    pub warnings: Vec<String>,
    pub timing: Timing,
}

/// The weighted criteria of both sets (or their sensitivities).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Criteria {
    pub covariance: Three,
    pub bound: Three,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Three {
    pub yz: Option<f64>,
    pub zx: Option<f64>,
    pub yx: Option<f64>,
}

impl Criteria {
    /// From [`super::CRITERIA`]'s order.
    pub(crate) fn from_array(v: [Option<f64>; 6]) -> Criteria {
        Criteria {
            covariance: Three {
                yx: v[0],
                zx: v[1],
                yz: v[2],
            },
            bound: Three {
                yx: v[3],
                zx: v[4],
                yz: v[5],
            },
        }
    }

    /// The criterion `k` of [`super::CRITERIA`].
    pub fn get(&self, k: usize) -> Option<f64> {
        let (c, b) = (&self.covariance, &self.bound);
        [c.yx, c.zx, c.yz, b.yx, b.zx, b.yz]
            .get(k)
            .copied()
            .flatten()
    }
}

/// One param's sensitivities.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamSensitivity {
    pub name: String,
    /// Its value (the request's `set`, else the model's).
    pub value: f64,
    /// p e^−h and p e^h, the values analysed.
    pub low: Option<f64>,
    pub high: Option<f64>,
    /// S = d ln F / d ln p per weighted criterion: null where F is not > 0 at either
    /// value (or the param is 0).
    pub sensitivity: Criteria,
    /// Why the param has no sensitivities at all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub undefined: Option<String>,
}

impl ParamSensitivity {
    pub(crate) fn new(name: &str, value: f64, h: f64, s: [Option<f64>; 6]) -> Self {
        ParamSensitivity {
            name: name.to_string(),
            value,
            low: Some(value * (-h).exp()),
            high: Some(value * h.exp()),
            sensitivity: Criteria::from_array(s),
            undefined: None,
        }
    }

    pub(crate) fn undefined(name: &str, value: f64, why: &str) -> Self {
        ParamSensitivity {
            name: name.to_string(),
            value,
            low: None,
            high: None,
            sensitivity: Criteria::default(),
            undefined: Some(why.to_string()),
        }
    }
}
