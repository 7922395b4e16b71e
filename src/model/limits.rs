//! The model's explicit limits: what a model may be at most (docs/model-format.md,
//! "Limits"; served by `GET /v1/limits`).

/// Largest accepted number of steps D (beyond this a run would take hours).
pub const MAX_STEPS: u64 = 100_000_000;
/// Largest accepted state dimension N.
pub const MAX_STATES: usize = 200;
/// Largest accepted number of noise sources: L (columns of b) and M (of gamma or g).
pub const MAX_SOURCES: usize = 200;
/// Largest accepted number of trace rows.
pub const MAX_TRACE_POINTS: usize = 100_000;
/// Largest number of values (rows × series) the traces of one result may hold:
/// ≈ 32 MB in memory and ≈ 40 MB of JSON. The default 1000 rows fit every N ≤ 200.
pub const MAX_TRACE_VALUES: usize = 2_000_000;

/// The most trace rows a result with `series` series may have.
pub fn max_trace_rows(series: usize) -> usize {
    (MAX_TRACE_VALUES / series.max(1)).min(MAX_TRACE_POINTS)
}
