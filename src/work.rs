//! A run's work estimate, in units of about a nanosecond of one core ([`Work`]): what
//! the server's limits, the command line's `--max-work` and the web page compare, and
//! what spaces the core's progress reports. Each kind estimates its own
//! (`analysis::work`, `monte_carlo::work`, `synthesis::work`).

/// The estimated work at which a run is refused by default: `kea serve --max-work` and
/// the command line's `--max-work` (≈ 17 minutes of one core). The web page asks before
/// it runs more than this in the browser.
pub const DEFAULT_MAX_WORK: f64 = 1e12;

/// A run's estimated work, in units of about a nanosecond of one core: what the
/// limits compare.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Work {
    pub units: f64,
    /// How it was computed, for messages (e.g. "D = 1000 steps × 272 (N³ + 16N² + 200 =
    /// 272 (N = 2))").
    pub explain: String,
    /// The request member that drives it, for an error's path: `model.time.steps`
    /// (an analysis), `runs` (a Monte Carlo), `mode` (a synthesis).
    pub path: String,
}

/// How many items of `each` units fit in `budget` units: 1 to `max` (1 also where
/// `each` exceeds the budget, or is NaN). What spaces the progress reports, the Monte
/// Carlo's chunks and a synthesis batch's parts.
pub fn fitting(budget: f64, each: f64, max: u64) -> u64 {
    let n = budget / each;
    if n >= 1.0 { (n as u64).min(max) } else { 1 }
}
