//! The Monte Carlo's renderings: the plain-text report (`kea monte-carlo`'s) and the
//! traces as CSV, shared by the command line, the server and wasm.

use super::{MonteCarloResult, Verdict};
use crate::text::{cell, short};
use std::fmt::Write;

fn verdict(v: Verdict) -> &'static str {
    match v {
        Verdict::Consistent => "consistent",
        Verdict::Optimistic => "optimistic (real worse than potential)",
        Verdict::Pessimistic => "pessimistic (real better than potential)",
        Verdict::Undefined => "undefined",
    }
}

/// The plain-text report: final SKOs, verdicts, and the three criteria sets; numbers as
/// in the analysis table ([`number`]), `—` where undefined.
pub fn text(r: &MonteCarloResult, threads: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Monte Carlo: {} runs × {} steps, seed {}, truth = {}, model error = {} ({:.0} ms, {threads} threads)",
        r.request.runs,
        r.steps,
        r.request.seed,
        // (the names of the JSON and of the flags: process, white…)
        serde_json::to_value(r.request.truth)
            .unwrap_or_default()
            .as_str()
            .unwrap_or("?"),
        serde_json::to_value(r.request.model_error)
            .unwrap_or_default()
            .as_str()
            .unwrap_or("?"),
        r.timing.wall_ms
    );
    let _ = writeln!(
        s,
        "\nAt t = {}: SKO of the errors (sample) against the potential sqrt(R_ii) and the bound χ",
        short(r.t_end)
    );
    let _ = writeln!(
        s,
        "{:<12} {:>12} {:>12} {:>12} {:>12} {:>12}   verdict (mean s²/R_ii, band)",
        "state", "a-priori", "measured", "filtered", "potential", "bound χ"
    );
    for (i, st) in r.states.iter().enumerate() {
        let f = &r.final_;
        let v = &r.consistency.per_state[i];
        let _ = writeln!(
            s,
            "{:<12} {:>12} {:>12} {:>12} {:>12} {:>12}   {} ({} in [{}, {}])",
            st,
            cell(Some(f.a_priori_sko[i])),
            cell(f.measured_sko[i]),
            cell(Some(f.filtered_sko[i])),
            cell(Some(f.potential_sko[i])),
            cell(Some(f.chi[i])),
            verdict(v.verdict),
            cell(v.variance_ratio),
            cell(Some(v.band[0])),
            cell(Some(v.band[1]))
        );
    }
    if let (Some(actual), Some(bias), Some(verdicts)) = (
        &r.final_.actual_sko,
        &r.final_.actual_bias,
        &r.consistency.per_state_actual,
    ) {
        let _ = writeln!(
            s,
            "\nThe runs imitate the truth; the filter is the model's. Its actual error (the mismatch's recursion) against the sample:"
        );
        let _ = writeln!(
            s,
            "{:<12} {:>12} {:>12} {:>12}   verdict (mean s²/σ², band; mean sample − actual bias, in σ)",
            "state", "sample SKO", "actual SKO", "actual bias"
        );
        for (i, st) in r.states.iter().enumerate() {
            let v = &verdicts[i];
            let _ = writeln!(
                s,
                "{:<12} {:>12} {:>12} {:>12}   {} ({} in [{}, {}]; {})",
                st,
                cell(Some(r.final_.filtered_sko[i])),
                cell(Some(actual[i])),
                cell(Some(bias[i])),
                verdict(v.verdict),
                cell(v.variance_ratio),
                cell(Some(v.band[0])),
                cell(Some(v.band[1])),
                cell(v.normalised_bias)
            );
        }
    }
    let c = &r.consistency;
    for (name, st) in [("NEES", &c.nees), ("NIS", &c.nis)] {
        let _ = writeln!(
            s,
            "{name}: average {} (dof {:.2}), {:.0} % band [{}, {}], {} of steps in band: {}",
            cell(st.time_average),
            st.dof,
            c.band_probability * 100.0,
            cell(Some(st.band[0])),
            cell(Some(st.band[1])),
            st.fraction_in_band
                .map_or("—".into(), |f| format!("{:.1} %", f * 100.0)),
            verdict(st.verdict)
        );
    }
    let _ = writeln!(
        s,
        "\nCriteria (weighted F): bound / covariance / monte_carlo"
    );
    let sets = [
        Some(&r.criteria.bound),
        Some(&r.criteria.covariance),
        r.criteria.monte_carlo.as_ref(),
    ];
    for (name, get) in [("F_YZ", 0usize), ("F_ZX", 1), ("F_YX", 2)] {
        let vals: Vec<String> = sets
            .iter()
            .map(|set| {
                cell(set.and_then(|c| match get {
                    0 => c.weighted.yz,
                    1 => c.weighted.zx,
                    _ => c.weighted.yx,
                }))
            })
            .collect();
        let _ = writeln!(
            s,
            "{name:<6} {:>12} {:>12} {:>12}",
            vals[0], vals[1], vals[2]
        );
    }
    for w in &r.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s
}

/// Traces of a Monte Carlo as CSV: t, then per state the sample and potential SKOs,
/// NEES and NIS, and with a truth each state's actual SKO and bias; a
/// value that is not a number (overflowed, or no measurement) is an empty cell, as in
/// the analysis's CSV (`null` in the JSON).
pub fn traces_csv(r: &MonteCarloResult) -> String {
    const SERIES: [&str; 7] = [
        "a_priori_sko",
        "open_loop_sko",
        "measured_sko",
        "filtered_sko",
        "filtered_mean",
        "potential_sko",
        "chi",
    ];
    let tr = &r.traces;
    let header = std::iter::once("t".to_string())
        .chain(
            tr.states
                .iter()
                .flat_map(|st| SERIES.iter().map(move |s| format!("{s}:{}", st.state))),
        )
        .chain(["nees".to_string(), "nis".to_string()])
        .chain(
            tr.states
                .iter()
                .filter(|st| st.actual_sko.is_some())
                .flat_map(|st| ["actual_sko", "actual_bias"].map(|s| format!("{s}:{}", st.state))),
        );
    // (As the analysis's CSV: plain, or in exponent form outside [1e-4, 1e15).)
    let num = crate::text::num;
    let opt = |v: Option<f64>| v.filter(|x| x.is_finite()).map(num).unwrap_or_default();
    let rows = tr.t.iter().enumerate().map(|(row, t)| {
        let mut fields = vec![num(*t)];
        for st in &tr.states {
            let meas = st.measured_sko.as_ref().and_then(|m| m[row]);
            fields.extend(
                [
                    Some(st.a_priori_sko[row]),
                    Some(st.open_loop_sko[row]),
                    meas,
                    Some(st.filtered_sko[row]),
                    Some(st.filtered_mean[row]),
                    Some(st.potential_sko[row]),
                    Some(st.chi[row]),
                ]
                .map(opt),
            );
        }
        fields.extend([opt(tr.nees[row]), opt(tr.nis[row])]);
        // With a truth: the actual SKO and bias of every state, after NEES and NIS.
        for st in &tr.states {
            if let (Some(a), Some(b)) = (&st.actual_sko, &st.actual_bias) {
                fields.extend([Some(a[row]), Some(b[row])].map(opt));
            }
        }
        fields
    });
    crate::text::csv_text(header, rows)
}
