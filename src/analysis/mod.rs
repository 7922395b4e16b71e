//! The analysis engine (METHOD §1.2–§1.6): Euler discretisation, the Joseph-form
//! Riccati recursion, means, the bound ("modulus") propagation, the exact-covariance
//! propagation, and the criteria accumulated on the fly. Memory does not grow with D.
//!
//! The per-step kernel is generic over a compile-time state dimension `N` (1..=12) so
//! the compiler unrolls and vectorises it; `N = 0` is the runtime-sized fallback.

//!
//! Laid out by concern: the step loop in `engine.rs`, the criteria's sums and their
//! assembly in `criteria.rs`, the warnings and numerical errors in `diagnostics.rs`,
//! the traces in `traces.rs`; here the entry points and the progress checkpoints.

use crate::analysis::result::{AnalysisResult, FinalCovariance};
use crate::analysis::steps::{Selected, select_steps};
use crate::error::Error;
use crate::exec::Memo;
use crate::model::compile::{CompiledModel, StepPlan};
use crate::progress::Progress;
use diagnostics::unconverged;
use engine::Engine;
pub use state::{SELECTION_KEY, STATE_KEY};
use std::ops::ControlFlow;

pub mod budget;
mod gains;
pub mod inputs;
pub mod kind;
pub mod mismatch;
pub mod report;
pub mod result;
mod state;
pub mod steps;
pub mod work;

mod criteria;
mod diagnostics;
mod engine;
mod traces;

pub use criteria::laplace_lambda;
pub(crate) use criteria::{Avg, SetSums, bisect_root, criteria_set};
pub use diagnostics::{BOUND_GROWTH_WARN, ROUNDING_LEVEL, bound_set_only};
pub(crate) use diagnostics::{overflowed, singular};

/// When a loop over steps reports progress: every `every` steps, `every` chosen so
/// that the steps between two reports are about [`WORK_BETWEEN_REPORTS`] by the work
/// estimate (at least 1, at most [`MAX_STEPS_BETWEEN_REPORTS`]). A step of a 200-state
/// model reports every step; one of 2 states every few thousand. The check in the
/// loop is one comparison of the step with the next report's.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Checkpoints {
    next: u64,
    every: u64,
}

impl Checkpoints {
    /// Reports for steps k = 1, 2, … of `step_work` units each.
    pub(crate) fn new(step_work: f64) -> Checkpoints {
        let every = crate::progress::steps_between_reports(step_work);
        Checkpoints { next: every, every }
    }

    /// Reports for the analysis's steps of `model` ([`crate::analysis::work::AnalysisStep`]).
    pub(crate) fn analysis(model: &CompiledModel) -> Checkpoints {
        Checkpoints::new(crate::analysis::work::AnalysisStep::of(model, None).units())
    }

    /// At the step k (called for every k = 1, 2, … in turn), reports `fraction()` done
    /// when a report is due; Err(Cancelled) when the caller cancels.
    #[inline(always)]
    pub(crate) fn at(
        &mut self,
        progress: &mut dyn Progress,
        k: u64,
        fraction: impl FnOnce() -> f64,
    ) -> Result<(), Error> {
        self.reported(progress, k, fraction).map(|_| ())
    }

    /// [`Checkpoints::at`], returning whether it reported.
    #[inline(always)]
    pub(crate) fn reported(
        &mut self,
        progress: &mut dyn Progress,
        k: u64,
        fraction: impl FnOnce() -> f64,
    ) -> Result<bool, Error> {
        if k == self.next {
            self.next += self.every;
            if let ControlFlow::Break(()) = progress.report(fraction()) {
                return Err(Error::Cancelled);
            }
            return Ok(true);
        }
        Ok(false)
    }

    /// Reports for a loop that goes on after step `k` (the first due after it).
    pub(crate) fn after(mut self, k: u64) -> Checkpoints {
        self.next = (k / self.every + 1) * self.every;
        self
    }
}

/// Compile a model with its parameter overrides and run its analysis.
pub fn analyze(
    model: &crate::model::Model,
    set: &crate::model::Overrides,
    progress: &mut dyn Progress,
) -> Result<AnalysisResult, Error> {
    let compiled = crate::model::compile(model, set)?;
    run(&compiled, progress)
}

/// Run the analysis of a compiled model.
pub fn run(model: &CompiledModel, progress: &mut dyn Progress) -> Result<AnalysisResult, Error> {
    run_resumable(model, progress, &crate::exec::Forgetful)
}

/// [`run`], keeping the step loop's state in `memo` when it asks for it
/// ([`Memo::state_due`]), and going on from a state an earlier run of the same model
/// kept there ([`crate::resume`]): the result is the one an uninterrupted run gives
/// (but for `timing`). A `"steps": "auto"` selection is kept in `memo` once made, and
/// taken from there by a run after a restart instead of made again.
pub fn run_resumable(
    model: &CompiledModel,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<AnalysisResult, Error> {
    let (steps, selection) = match model.steps {
        StepPlan::Fixed(d) => (d, None),
        StepPlan::Auto {
            tolerance,
            initial_steps,
            max_steps,
        } => {
            let kept = memo
                .recall(SELECTION_KEY)
                .and_then(|text| Selected::from_text(&text, tolerance, max_steps));
            let s = match kept {
                Some(s) => s,
                None => {
                    let s = select_steps(model, tolerance, initial_steps, max_steps, progress)?;
                    memo.keep(SELECTION_KEY, &s.to_text());
                    s
                }
            };
            (s.chosen, Some(s.selection))
        }
    };
    let mut result = dispatch(model, steps, false, progress, memo)?;
    if let Some(w) = selection.as_ref().and_then(unconverged) {
        result.warnings.insert(0, w);
    }
    result.warnings.splice(0..0, model.notes.iter().cloned());
    result.step_selection = selection;
    Ok(result)
}

/// The filter's covariance recursion alone — (2.1)–(2.7) and the mean (3.3) at every
/// step, with none of the analysis around it (no open-loop covariance, bound,
/// criteria or traces): what a Kalman filter library's covariance pass computes, for
/// timing kea against one on the same recursion (BENCHMARKS.md). Returns R_D and p_D,
/// the analysis's `final.covariance` and `final.gain` bit for bit. Needs a fixed
/// number of steps.
pub fn covariance_recursion(
    model: &CompiledModel,
    progress: &mut dyn Progress,
) -> Result<FinalCovariance, Error> {
    let StepPlan::Fixed(steps) = model.steps else {
        return Err(Error::invalid(
            "time.steps",
            "the covariance recursion alone runs a fixed number of steps, not \"auto\"",
        ));
    };
    let r = dispatch(model, steps, true, progress, &crate::exec::Forgetful)?;
    Ok(FinalCovariance {
        covariance: r.final_.covariance,
        gain: r.final_.gain,
    })
}

/// The engine compiled for the model's state dimension (1..=12, else runtime-sized).
fn dispatch(
    model: &CompiledModel,
    steps: u64,
    covariance_only: bool,
    progress: &mut dyn Progress,
    memo: &dyn Memo,
) -> Result<AnalysisResult, Error> {
    match model.n_states() {
        1 => Engine::<1>::new(model, steps, covariance_only, memo).run(progress),
        2 => Engine::<2>::new(model, steps, covariance_only, memo).run(progress),
        3 => Engine::<3>::new(model, steps, covariance_only, memo).run(progress),
        4 => Engine::<4>::new(model, steps, covariance_only, memo).run(progress),
        5 => Engine::<5>::new(model, steps, covariance_only, memo).run(progress),
        6 => Engine::<6>::new(model, steps, covariance_only, memo).run(progress),
        7 => Engine::<7>::new(model, steps, covariance_only, memo).run(progress),
        8 => Engine::<8>::new(model, steps, covariance_only, memo).run(progress),
        9 => Engine::<9>::new(model, steps, covariance_only, memo).run(progress),
        10 => Engine::<10>::new(model, steps, covariance_only, memo).run(progress),
        11 => Engine::<11>::new(model, steps, covariance_only, memo).run(progress),
        12 => Engine::<12>::new(model, steps, covariance_only, memo).run(progress),
        _ => Engine::<0>::new(model, steps, covariance_only, memo).run(progress),
    }
}

/// The builds of the engine's loop (x86-64).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Build {
    /// AVX-512 F + VL with AVX2 + FMA: the fixed-size loops in 8-lane registers, a
    /// row of up to 8 values in one (masked) operation.
    Avx512,
    /// AVX2 + FMA: the explicit 4-lane row kernels.
    Avx2,
    /// Portable code (SSE2).
    Baseline,
}

/// The widest build this CPU runs, within the ceiling a shell set
/// ([`crate::cpu::limit`]: the tests compare the builds).
#[cfg(target_arch = "x86_64")]
fn build() -> Build {
    use crate::cpu::Limit;
    let limit = crate::cpu::limit();
    if limit == Limit::Baseline
        || !(std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma"))
    {
        Build::Baseline
    } else if limit == Limit::Widest
        && std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
    {
        Build::Avx512
    } else {
        Build::Avx2
    }
}
