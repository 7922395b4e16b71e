//! Step-size selection (METHOD §1.2, text before (1.3)): solve the mean equation
//! (3.3) with D, 2D, 4D, … and stop when the time-averaged difference between
//! successive solutions, compared on the coarser grid, is below the tolerance
//! (relative to max|y|), or at the cap. Both solutions run in lockstep, so memory
//! does not grow with D.

use crate::analysis::result::{StepSelection, StepTrial};
use crate::error::Error;
use crate::expr::TimeMatrix;
use crate::model::compile::CompiledModel;
use crate::progress::Progress;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Selected {
    pub chosen: u64,
    pub selection: StepSelection,
}

impl Selected {
    /// The selection as a [`crate::exec::Memo`] value (its differences are finite:
    /// JSON gives them back exactly).
    pub(crate) fn to_text(&self) -> String {
        serde_json::to_string(self).expect("a selection serialises")
    }

    /// The selection in `text` if it was made with this tolerance and cap.
    pub(crate) fn from_text(text: &str, tolerance: f64, max_steps: u64) -> Option<Selected> {
        let s: Selected = serde_json::from_str(text).ok()?;
        let ours = s.selection.tolerance.to_bits() == tolerance.to_bits()
            && s.selection.max_steps == max_steps
            && s.chosen <= max_steps;
        ours.then_some(s)
    }
}

/// One Euler step k of the mean (3.3) on the grid t0 + iΔt, from t_{k−1}:
/// the expressions are evaluated for several grid points at a time
/// (`TimeMatrix::update_grid`, the same values as one by one).
fn mean_step(
    a: &mut TimeMatrix,
    u: &mut TimeMatrix,
    y: &mut [f64],
    tmp: &mut [f64],
    t0: f64,
    dt: f64,
    k: u64,
) -> Result<(), Error> {
    let n = y.len();
    let err = |(p, t): (&str, f64)| Error::Numerical {
        step: k,
        t,
        path: p.to_string(),
        message: "the expression is not finite here".into(),
    };
    a.update_grid(t0, dt, k - 1).map_err(err)?;
    u.update_grid(t0, dt, k - 1).map_err(err)?;
    for i in 0..n {
        let mut s = 0.0;
        for j in 0..n {
            s += a.values[i * n + j] * y[j];
        }
        tmp[i] = y[i] + (s + u.values[i]) * dt;
    }
    y.copy_from_slice(tmp);
    Ok(())
}

pub fn select_steps(
    m: &CompiledModel,
    tolerance: f64,
    initial: u64,
    max: u64,
    progress: &mut dyn Progress,
) -> Result<Selected, Error> {
    let n = m.n_states();
    let span = m.t_end - m.t0;
    let mut history = Vec::new();
    let mut d = initial.min(max);
    loop {
        if 2 * d > max {
            // Cannot refine further within the cap: use the finest allowed.
            history.push(StepTrial {
                steps: d,
                difference: None,
            });
            return Ok(Selected {
                chosen: d,
                selection: StepSelection {
                    tolerance,
                    max_steps: max,
                    converged: false,
                    history,
                },
            });
        }
        let (mut ac, mut uc) = (m.a.clone(), m.u.clone());
        let (mut af, mut uf) = (m.a.clone(), m.u.clone());
        let mut yc = m.y0.clone();
        let mut yf = m.y0.clone();
        let mut tmp = vec![0.0; n];
        let dtc = span / d as f64;
        let dtf = dtc / 2.0;
        let mut sum = 0.0;
        let mut ymax = yc.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        let mut overflowed = false;
        // (A trial's step is three mean steps, cheaper than the analysis's: reports
        // come at most as far apart as the analysis's.)
        let mut checkpoints = crate::analysis::Checkpoints::analysis(m);
        for k in 1..=d {
            mean_step(&mut ac, &mut uc, &mut yc, &mut tmp, m.t0, dtc, k)?;
            for h in 0..2u64 {
                let kf = 2 * k - 1 + h;
                mean_step(&mut af, &mut uf, &mut yf, &mut tmp, m.t0, dtf, kf)?;
            }
            let mut worst = 0.0f64;
            for i in 0..n {
                worst = worst.max((yc[i] - yf[i]).abs());
                ymax = ymax.max(yf[i].abs()).max(yc[i].abs());
            }
            sum += worst;
            // A solution that overflowed (∞, or NaN, which `max` skips) has not
            // converged. Typically Euler is unstable at this Δt (|1 + aΔt| > 1 for a
            // stiff a) and stable on a finer grid, so 2D is tried; a model whose mean
            // itself diverges overflows at every D, and the analysis at the D
            // finally taken says so.
            if !(sum + ymax).is_finite() || yc.iter().chain(&yf).any(|v| !v.is_finite()) {
                overflowed = true;
                break;
            }
            checkpoints.at(progress, k, || 0.0)?;
        }
        if overflowed {
            history.push(StepTrial {
                steps: d,
                difference: None,
            });
            d *= 2;
            continue;
        }
        let diff = if ymax > 0.0 {
            sum / d as f64 / ymax
        } else {
            0.0
        };
        history.push(StepTrial {
            steps: d,
            difference: Some(diff),
        });
        if diff <= tolerance {
            return Ok(Selected {
                chosen: d,
                selection: StepSelection {
                    tolerance,
                    max_steps: max,
                    converged: true,
                    history,
                },
            });
        }
        d *= 2;
    }
}
