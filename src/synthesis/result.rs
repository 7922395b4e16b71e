//! The synthesis result (METHOD §1.7): the status, the message, the answer and its
//! verification, and each mode's details (the points visited, the bracket, the table).

use super::request::{GridParam, Target};
use crate::analysis::result::Timing;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SynthesisResult {
    /// The target as run; its criteria set is written as `criteria` and again as `set`,
    /// the member's former name, for readers of earlier results
    /// ([`target_with_former_name`]).
    #[serde(with = "target_with_former_name")]
    pub target: Target,
    pub status: Status,
    /// One or two sentences: the answer, or why there is none and what to do.
    pub message: String,
    /// The point found (seed_search, bisect) or the cheapest qualifying cell (grid).
    pub answer: Option<Point>,
    pub verification: Option<Verification>,
    pub details: Details,
    /// Analyses run, verification included.
    pub analyses: u64,
    /// Of `analyses`, those not run again but recalled from an earlier run of the same
    /// request that was interrupted (a server's job re-queued by a shutdown or a crash,
    /// [`crate::exec::Memo`]). Absent when 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub recalled_analyses: u64,
    /// Steps D of each analysis.
    pub steps: u64,
    /// Filled by the caller (the core has no clock).
    pub timing: Timing,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// An answer was found and verified.
    Found,
    /// No point meets the target (the seed's failure: widen the ranges or lower it).
    NotFound,
    /// Bisection: both ends meet the target, the boundary lies outside the range.
    WholeRangeMeets,
    /// Bisection: the criterion is not monotonic in the param; no answer is given.
    NonMonotonic,
    /// Grid without a cost order: the table is the answer.
    Table,
}

/// One analysed point: the params set, the three criteria of the target's set and
/// scope, the targeted value and whether it meets the threshold.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Point {
    pub params: BTreeMap<String, f64>,
    pub yz: Option<f64>,
    pub zx: Option<f64>,
    pub yx: Option<f64>,
    /// The targeted criterion (null when undefined, see `note`).
    pub value: Option<f64>,
    pub meets: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// The answer re-analysed; for bisection also a point 1 % looser, which must miss.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Verification {
    pub point: Point,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub looser: Option<Point>,
    /// The answer meets the target (and the looser point, if any, misses it).
    pub passed: bool,
    /// The warnings of the answer's analysis that concern the target's set: a bound
    /// set that grew far beyond the covariance's (its criteria then describe |A|'s
    /// growth, not the filter; left out for a covariance target), lost precision, … —
    /// what the Analysis of that point would say.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Details {
    SeedSearch(SeedSearchOut),
    Bisect(BisectOut),
    Grid(GridOut),
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeedSearchOut {
    /// Each param's values in the order visited.
    pub levels: Vec<GridParam>,
    /// Points of the search space.
    pub points_total: usize,
    /// The points in the seed's order, up to and including the one found.
    pub visited: Vec<Point>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BisectOut {
    pub param: String,
    /// Which end of the range meets the target.
    pub meets_side: Option<Side>,
    /// The final bracket [meets, misses] (ordered as values).
    pub bracket: Option<[f64; 2]>,
    pub iterations: u32,
    /// Every analysed point of the search, sorted by the param.
    pub evaluations: Vec<Point>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    Low,
    High,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridOut {
    pub params: Vec<GridParam>,
    /// Row-major: the first param varies slowest.
    pub cells: Vec<GridCell>,
    /// Index of the cheapest qualifying cell (with a cost order).
    pub cheapest: Option<Vec<usize>>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridCell {
    /// Index into each param's values.
    pub index: Vec<usize>,
    pub point: Point,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// [`SynthesisResult::target`]'s JSON: the target, and `set` beside its `criteria`, the
/// same value under the member's former name. Read back, `criteria` is taken, or a lone
/// `set` (a result of an earlier version).
mod target_with_former_name {
    use super::super::request::{CriteriaSetName, Target};
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize)]
    struct Written<'a> {
        #[serde(flatten)]
        target: &'a Target,
        set: CriteriaSetName,
    }

    pub fn serialize<S: Serializer>(target: &Target, s: S) -> Result<S::Ok, S::Error> {
        let set = target.criteria;
        Written { target, set }.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Target, D::Error> {
        let mut members = serde_json::Map::deserialize(d)?;
        if members.contains_key("criteria") {
            members.remove("set");
        }
        Target::deserialize(serde_json::Value::Object(members)).map_err(serde::de::Error::custom)
    }
}
