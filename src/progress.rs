//! Progress reports and cancellation, and how often the core reports: after a bounded
//! amount of *work* (the work estimate's units, [`crate::work`]), not a fixed count of
//! steps — a report is the caller's only chance to cancel, stop at its time limit or
//! shut down.

use std::ops::ControlFlow;

/// Progress reports and cancellation: `report` is called with the fraction done (0..1)
/// after about every millisecond of work by the work estimate
/// ([`WORK_BETWEEN_REPORTS`]: every step of a costly model, every few
/// thousand of a cheap one); returning `ControlFlow::Break(())` cancels.
pub trait Progress {
    fn report(&mut self, fraction: f64) -> ControlFlow<()>;
}

/// No progress reporting, never cancels.
pub struct NoProgress;

impl Progress for NoProgress {
    fn report(&mut self, _fraction: f64) -> ControlFlow<()> {
        ControlFlow::Continue(())
    }
}

impl<F: FnMut(f64) -> ControlFlow<()>> Progress for F {
    fn report(&mut self, fraction: f64) -> ControlFlow<()> {
        self(fraction)
    }
}

/// The work ([`crate::work`]'s units, about 1 ns of one core each) between two progress
/// reports, which are also the callers' only chance to cancel, stop at a time limit or
/// shut down: ≈ 1 ms, so even a step costing ten times its estimate is stopped within
/// tens of milliseconds, while a report (an indirect call, a few atomic loads and a
/// clock read in the server) stays far below 0.1 % of the work between two.
pub const WORK_BETWEEN_REPORTS: f64 = (1u64 << 20) as f64;

/// At most this many steps between progress reports, however cheap the steps.
pub const MAX_STEPS_BETWEEN_REPORTS: u64 = 1 << 14;

/// How many steps of `step_work` units make [`WORK_BETWEEN_REPORTS`] (1 to
/// [`MAX_STEPS_BETWEEN_REPORTS`]).
pub fn steps_between_reports(step_work: f64) -> u64 {
    crate::work::fitting(WORK_BETWEEN_REPORTS, step_work, MAX_STEPS_BETWEEN_REPORTS)
}

/// The work of one part of a run that many threads share — a Monte Carlo's chunk of
/// steps (every run's), a synthesis batch's part of analyses per thread: 16 times
/// [`WORK_BETWEEN_REPORTS`], ≈ 17 ms of one core, so that the part's fixed costs (a
/// plan's step, a hand-over between threads) stay small beside it.
pub const WORK_BETWEEN_PARTS: f64 = 16.0 * WORK_BETWEEN_REPORTS;
