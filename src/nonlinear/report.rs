//! The nonlinear run in words (`kea nonlinear`'s table) and its traces as CSV.

use super::result::{NonlinearResult, Summary};
use crate::text::{CELL, cell, csv_text, num, short};

/// One table row: δ, δ on the posteriors and, with a truth, the RMS per state.
fn row(label: &str, s: &Summary, truth: bool, mark: &str) -> String {
    let mut out = format!(
        "{label:<18}  {:>CELL$}  {:>CELL$}",
        cell(Some(s.delta)),
        cell(Some(s.delta_posterior))
    );
    if truth {
        for r in s.rms.iter().flatten() {
            out += &format!("  {:>CELL$}", cell(*r));
        }
    }
    out + mark + "\n"
}

/// The plain-text report.
pub fn text(r: &NonlinearResult) -> String {
    let truth = r.ekf.rms.is_some();
    let mut out = format!(
        "{:<18}  {:>CELL$}  {:>CELL$}",
        "filter", "delta", "delta post"
    );
    if truth {
        for s in &r.states {
            out += &format!("  {:>CELL$}", format!("rms {s}"));
        }
    }
    out += "\n";
    for s in &r.iterates {
        let i = s.i.unwrap_or(0);
        let mark = if i == r.i_star { "  <- i*" } else { "" };
        out += &row(&format!("iterate {i}"), s, truth, mark);
    }
    out += &row("EKF", &r.ekf, truth, "");
    if let Some(c) = r.q_scale.chosen {
        let p = &r.q_scale.grid[c];
        let scale = format!("{:.3}", p.scale);
        let scale = scale.trim_end_matches('0').trim_end_matches('.');
        out += &row(
            &format!("EKF, W × {scale}"),
            &p.summary,
            truth,
            "  (Q scale by delta)",
        );
    }
    out += &format!(
        "\ni* = {} (least delta on the one-step predictions); stop at the first increase: {}\n",
        r.i_star, r.i_stop_first_increase
    );
    out += "gamma (row k: gamma_1^k … gamma_k^k):\n";
    for (k, g) in r.gamma.iter().enumerate() {
        let cells: Vec<String> = g.iter().map(|x| short(*x)).collect();
        out += &format!("  k = {}: {}\n", k + 1, cells.join("  "));
    }
    out += &format!(
        "{} steps of {} s; delta = mean of (y − h(x))² over {} measured values. P of iterates k ≥ 2 is not their error covariance: only the EKF's and iterate 1's SKO are bands.\n",
        r.steps,
        short(r.dt),
        r.measured.iter().sum::<u64>()
    );
    out
}

/// The traces as CSV: `t`, `n` (the step), then `series:name` columns —
/// `measurement:NAME`, `truth:STATE` (with a truth), `ekf:STATE`, `ekf_sko:STATE`,
/// `iterate1:STATE` … `iterateK:STATE`, `iterate1_sko:STATE`, `q_scaled:STATE` (with
/// a Q-scale grid); an empty cell for a value that is not there.
pub fn traces_csv(r: &NonlinearResult) -> String {
    let tr = &r.traces;
    let mut header: Vec<String> = vec!["t".into(), "n".into()];
    let mut columns: Vec<Vec<Option<f64>>> = Vec::new();
    for (j, name) in r.measurements.iter().enumerate() {
        header.push(format!("measurement:{name}"));
        columns.push(tr.measurements[j].clone());
    }
    let some = |v: &Vec<f64>| v.iter().map(|x| Some(*x)).collect::<Vec<_>>();
    if let Some(truth) = &tr.truth {
        for (i, s) in r.states.iter().enumerate() {
            header.push(format!("truth:{s}"));
            columns.push(truth[i].clone());
        }
    }
    for (i, s) in r.states.iter().enumerate() {
        header.push(format!("ekf:{s}"));
        columns.push(some(&tr.ekf[i]));
        header.push(format!("ekf_sko:{s}"));
        columns.push(some(&tr.ekf_sko[i]));
    }
    for (k, it) in tr.iterates.iter().enumerate() {
        for (i, s) in r.states.iter().enumerate() {
            header.push(format!("iterate{}:{s}", k + 1));
            columns.push(some(&it[i]));
        }
    }
    for (i, s) in r.states.iter().enumerate() {
        header.push(format!("iterate1_sko:{s}"));
        columns.push(some(&tr.iterate_1_sko[i]));
    }
    if let Some(q) = &tr.q_scaled {
        for (i, s) in r.states.iter().enumerate() {
            header.push(format!("q_scaled:{s}"));
            columns.push(some(&q[i]));
        }
    }
    let rows = (0..tr.n.len()).map(|p| {
        let mut row = vec![num(tr.t[p]), tr.n[p].to_string()];
        row.extend(columns.iter().map(|c| c[p].map(num).unwrap_or_default()));
        row
    });
    csv_text(header, rows)
}
