//! The identification in words: the estimates' table with standard errors and 95 %
//! intervals, J, the verdict, how the minimiser stopped.

use super::result::IdentificationResult;
use crate::text::{CELL, cell, short};

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
        .map(|n| format!("{n} {:.2e}", r.gradient[n]))
        .collect::<Vec<_>>()
        .join(", ");
    out += &format!(
        "\nJ = −ln L = {} over {} measurements ({} steps); gradient: {grad}\n",
        short(r.neg_log_likelihood),
        r.measurements,
        r.steps
    );
    out += &format!("{}\n", r.identifiability.verdict);
    if r.expected_information.is_some() {
        let bounds = r
            .parameters
            .iter()
            .map(|n| format!("{n} {}", cell(r.estimate[n].cramer_rao_sko).trim()))
            .collect::<Vec<_>>()
            .join(", ");
        out += &format!("Cramér–Rao bound on the SKOs (expected information): {bounds}\n");
    }
    if let Some(i) = &r.innovations {
        out += &format!(
            "innovations: NIS mean {} (95 % band [{}, {}]): {}\n",
            cell(Some(i.nis_mean)).trim(),
            cell(Some(i.nis_band[0])).trim(),
            cell(Some(i.nis_band[1])).trim(),
            if i.nis_consistent {
                "consistent"
            } else {
                "NOT consistent: the model's noise levels do not fit the data"
            }
        );
        for w in &i.whiteness {
            out += &format!(
                "  {}: {} (Ljung–Box Q = {} {} {} at 95 %, {} lags)\n",
                w.measurement,
                if w.white {
                    "white"
                } else {
                    "NOT white: the innovations are correlated, the model misses dynamics"
                },
                cell(Some(w.ljung_box)).trim(),
                if w.white { "≤" } else { ">" },
                cell(Some(w.critical)).trim(),
                w.lags
            );
        }
    }
    if r.optima.len() > 1 {
        out += &format!(
            "{} distinct optima from the starts (lowest J first):\n",
            r.optima.len()
        );
        for o in &r.optima {
            let params: Vec<String> = o
                .params
                .iter()
                .map(|(k, v)| format!("{k} {}", cell(Some(*v)).trim()))
                .collect();
            out += &format!(
                "  J {}  {}  (starts {:?})\n",
                short(o.neg_log_likelihood),
                params.join(", "),
                o.starts
            );
        }
    }
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

/// The innovations at θ̂ as CSV, one row per step: `t`, `nis` (νᵀS⁻¹ν, empty where
/// nothing was measured), then `innovation:NAME` (ν/√S per measurement, empty where
/// missing); numbers as the other kinds' CSVs write them.
pub fn innovations_csv(s: &super::result::InnovationSeries) -> String {
    use crate::text::{csv_text, num};
    let m = s.measurements.len();
    let cell = |x: f64| if x.is_nan() { String::new() } else { num(x) };
    let header = ["t".to_string(), "nis".to_string()]
        .into_iter()
        .chain(s.measurements.iter().map(|n| format!("innovation:{n}")));
    let rows = s.t.iter().enumerate().map(move |(k, t)| {
        [num(*t), cell(s.nis[k])]
            .into_iter()
            .chain((0..m).map(move |j| cell(s.innovations[k * m + j])))
    });
    csv_text(header, rows)
}
