//! The identification in words: the estimates' table with standard errors and 95 %
//! intervals, J, the verdict, how the minimiser stopped.

use super::result::IdentificationResult;
use crate::text::{CELL, cell, num, short};

/// The plain-text report (`kea identify`'s).
pub fn text(r: &IdentificationResult) -> String {
    let w = r
        .parameters
        .iter()
        .map(String::len)
        .max()
        .unwrap_or(5)
        .max(5);
    let mut out = format!(
        "{:<w$}  {:>CELL$}  {:>CELL$}  {:>CELL$}  {:>CELL$}  {:>CELL$}\n",
        "param", "estimate", "std error", "95% low", "95% high", "initial"
    );
    for name in &r.parameters {
        let e = &r.estimate[name];
        let bound = if e.at_bound { "  (at a bound)" } else { "" };
        out += &format!(
            "{name:<w$}  {:>CELL$}  {:>CELL$}  {:>CELL$}  {:>CELL$}  {:>CELL$}{bound}\n",
            cell(Some(e.value)),
            cell(e.std_error),
            cell(e.interval.map(|i| i[0])),
            cell(e.interval.map(|i| i[1])),
            cell(Some(e.initial)),
        );
    }
    let grad = r
        .parameters
        .iter()
        .map(|n| format!("{n} {}", num(r.gradient[n])))
        .collect::<Vec<_>>()
        .join(", ");
    out += &format!(
        "\nJ = −ln L = {} over {} measurements ({} steps); gradient: {grad}\n",
        short(r.neg_log_likelihood),
        r.measurements,
        r.steps
    );
    out += &format!("{}\n", r.identifiability.verdict);
    out += &format!(
        "{}: {} after {} iterations ({} evaluations of J): {}\n",
        method_name(r),
        if r.converged {
            "converged"
        } else {
            "did not converge"
        },
        r.iterations.len().saturating_sub(1),
        r.evaluations,
        r.stop_reason
    );
    out
}

fn method_name(r: &IdentificationResult) -> &'static str {
    match r.method {
        super::minimise::Method::Scoring => "Fisher scoring",
        super::minimise::Method::Gradient => "gradient descent",
        super::minimise::Method::Conjugate => "conjugate directions",
    }
}
