//! The criteria's weights: one per state, finite and ≥ 0, 0 where the criterion is
//! undefined (a state with no paired measurement), summing to 1.

use super::Errors;
use crate::text::num;

/// Weights must sum to 1 within this.
const WEIGHT_TOL: f64 = 1e-9;

pub(super) fn weights(
    w: Option<&[f64]>,
    n: usize,
    defined: Option<&[bool]>,
    path: &str,
    states: &[String],
    errs: &mut Errors,
) -> Option<Vec<f64>> {
    let w = w?;
    if w.len() != n {
        errs.at(
            path,
            format!("has {} weights, expected one per state ({n})", w.len()),
        );
        return None;
    }
    let mut ok = true;
    for (i, x) in w.iter().enumerate() {
        if !(x.is_finite() && *x >= 0.0) {
            errs.at(
                &format!("{path}[{i}]"),
                format!("a weight must be a finite number ≥ 0, got {}", num(*x)),
            );
            ok = false;
        } else if *x > 0.0 && defined.is_some_and(|d| !d[i]) {
            errs.at(
                &format!("{path}[{i}]"),
                format!(
                    "state \"{}\" has no paired measurement, so this criterion is undefined for it: its weight must be 0",
                    states[i]
                ),
            );
            ok = false;
        }
    }
    let sum: f64 = w.iter().sum();
    if ok && (sum - 1.0).abs() > WEIGHT_TOL {
        errs.at(
            path,
            format!(
                "weights must sum to 1 (within {WEIGHT_TOL:e}), they sum to {}",
                num(sum)
            ),
        );
        ok = false;
    }
    ok.then(|| w.to_vec())
}
