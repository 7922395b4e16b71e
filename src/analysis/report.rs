//! Plain-text and CSV renderings of a result, shared by the CLI, the server and wasm.

use crate::analysis::budget::{Budget, BudgetSource, Shares, SourceKind, StateBudget};

use crate::analysis::result::{AnalysisResult, CriteriaSet, Mismatch};
use crate::text::{CELL, cell, csv_text, num, short};
use std::fmt::Write;

/// The seed's layout: per state and weighted, bound and covariance side by side.
pub fn criteria_table(r: &AnalysisResult) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "steps D = {}, dt = {:e}, t = [{}, {}]{}",
        r.steps,
        r.dt,
        short(r.t0),
        short(r.t_end),
        if r.timing.wall_ms > 0.0 {
            format!(", {:.1} ms", r.timing.wall_ms)
        } else {
            String::new()
        }
    );
    let w = r
        .states
        .iter()
        .map(|x| x.chars().count())
        .max()
        .unwrap_or(5)
        .max("weighted".len());
    // Three columns and their separating spaces per set, and the rules under them.
    let (cw, set_w) = (CELL, 3 * CELL + 2);
    let rule = "-".repeat(w + 3 + set_w + 3 + set_w);
    let _ = writeln!(
        s,
        "{:<w$} | {:^set_w$} | {:^set_w$}",
        "", "bound (modulus procedure)", "covariance (exact)"
    );
    let _ = writeln!(
        s,
        "{:<w$} | {:>cw$} {:>cw$} {:>cw$} | {:>cw$} {:>cw$} {:>cw$}",
        "state", "F_YZ", "F_ZX", "F_YX", "F_YZ", "F_ZX", "F_YX"
    );
    let _ = writeln!(s, "{rule}");
    two_sets(
        &mut s,
        w,
        &r.criteria.bound,
        &r.criteria.covariance,
        Some(&rule),
    );
    notes(&mut s, "bound", &r.criteria.bound);
    notes(&mut s, "covariance", &r.criteria.covariance);
    if let Some(ss) = &r.steady_state {
        let _ = writeln!(
            s,
            "steady state reached at step {} (t = {}){}",
            ss.reached_at_step,
            short(ss.t),
            if ss.shortcut_used {
                ", shortcut used"
            } else {
                ""
            }
        );
    }
    if let Some(b) = &r.budget {
        budget_tables(&mut s, b);
    }
    if let (Some(m), Some(actual)) = (&r.mismatch, &r.criteria.actual) {
        mismatch_table(&mut s, m, actual);
    }
    for w in &r.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s
}

/// The mismatched filter: per state its actual, believed and optimal SKO at t_D, the
/// loss, the bias; then the actual criteria beside the optimal filter's.
fn mismatch_table(s: &mut String, m: &Mismatch, actual: &CriteriaSet) {
    let _ = writeln!(
        s,
        "\nmismatched filter (the truth differs in {}): SKOs at t_D",
        m.differs_in
    );
    let w = m
        .states
        .iter()
        .map(|x| x.state.chars().count())
        .max()
        .unwrap_or(0)
        .max("weighted".len());
    let cw = CELL;
    let head = format!(
        "{:<w$} | {:>cw$} {:>cw$} {:>cw$} {:>cw$} {:>cw$}",
        "state", "actual", "believed", "optimal", "loss", "bias"
    );
    let _ = writeln!(s, "{head}");
    let _ = writeln!(s, "{}", "-".repeat(head.chars().count()));
    for x in &m.states {
        let _ = writeln!(
            s,
            "{:<w$} | {:>cw$} {:>cw$} {:>cw$} {:>cw$} {:>cw$}",
            x.state,
            cell(Some(x.actual_sko)),
            cell(Some(x.believed_sko)),
            cell(Some(x.optimal_sko)),
            cell(x.loss),
            cell(Some(x.bias))
        );
    }
    let set_w = 3 * cw + 2;
    let _ = writeln!(
        s,
        "\n{:<w$} | {:^set_w$} | {:^set_w$}",
        "", "actual (mismatched filter)", "optimal (designed on the truth)"
    );
    let _ = writeln!(
        s,
        "{:<w$} | {:>cw$} {:>cw$} {:>cw$} | {:>cw$} {:>cw$} {:>cw$}",
        "state", "F_YZ", "F_ZX", "F_YX", "F_YZ", "F_ZX", "F_YX"
    );
    two_sets(s, w, actual, &m.optimal, None);
}

/// Two criteria sets side by side: a row per state, then (after `rule`, if any) the
/// weighted row, each F_YZ, F_ZX, F_YX of `left` then of `right`.
fn two_sets(s: &mut String, w: usize, left: &CriteriaSet, right: &CriteriaSet, rule: Option<&str>) {
    for (a, b) in left.per_state.iter().zip(&right.per_state) {
        six(s, w, &a.state, [a.yz, a.zx, a.yx], [b.yz, b.zx, b.yx]);
    }
    if let Some(rule) = rule {
        let _ = writeln!(s, "{rule}");
    }
    let (a, b) = (&left.weighted, &right.weighted);
    six(s, w, "weighted", [a.yz, a.zx, a.yx], [b.yz, b.zx, b.yx]);
}

/// One row of [`two_sets`].
fn six(s: &mut String, w: usize, name: &str, a: [Option<f64>; 3], b: [Option<f64>; 3]) {
    let cw = CELL;
    let _ = writeln!(
        s,
        "{name:<w$} | {:>cw$} {:>cw$} {:>cw$} | {:>cw$} {:>cw$} {:>cw$}",
        cell(a[0]),
        cell(a[1]),
        cell(a[2]),
        cell(b[0]),
        cell(b[1]),
        cell(b[2])
    );
}

/// The error budget: each source's share (%) of every state's filtered variance at t_D
/// and averaged over the steps, and of the open-loop variance at t_D; the SKOs they
/// split under each.
fn budget_tables(s: &mut String, b: &Budget) {
    type Pick = fn(&StateBudget) -> &Shares;
    let tables: [(&str, Pick, bool); 3] = [
        ("filtered variance at t_D", |x| &x.potential, true),
        (
            "filtered variance averaged over the steps",
            |x| &x.potential,
            false,
        ),
        ("open-loop variance at t_D", |x| &x.open_loop, true),
    ];
    let label = |x: &BudgetSource| match (&x.enters, x.kind) {
        (Some(e), k) if k != SourceKind::Initial => format!("{} → {e}", x.name),
        _ => x.name.clone(),
    };
    let w = b
        .sources
        .iter()
        .map(|x| label(x).chars().count())
        .max()
        .unwrap_or(0)
        .max("SKO".len());
    let cw = b
        .states
        .iter()
        .map(|x| x.state.chars().count())
        .max()
        .unwrap_or(0)
        .max(CELL);
    for (title, pick, at_end) in tables {
        let _ = writeln!(s, "\nerror budget: each source's share (%) of the {title}");
        let mut head = format!("{:<w$} |", "source");
        for st in &b.states {
            let _ = write!(head, " {:>cw$}", st.state);
        }
        let _ = writeln!(s, "{head}");
        let _ = writeln!(s, "{}", "-".repeat(head.chars().count()));
        for (k, src) in b.sources.iter().enumerate() {
            let mut line = format!("{:<w$} |", label(src));
            for st in &b.states {
                let sh = pick(st);
                let share = if at_end {
                    &sh.final_share
                } else {
                    &sh.mean_share
                };
                let _ = write!(line, " {:>cw$}", cell(share[k].map(|x| 100.0 * x)));
            }
            let _ = writeln!(s, "{line}");
        }
        let mut line = format!("{:<w$} |", "SKO");
        for st in &b.states {
            let sh = pick(st);
            let v = if at_end {
                sh.final_variance
            } else {
                sh.mean_variance
            };
            let _ = write!(line, " {:>cw$}", cell(Some(v.max(0.0).sqrt())));
        }
        let _ = writeln!(s, "{line}");
    }
}

fn notes(s: &mut String, set: &str, c: &CriteriaSet) {
    // Undefined criteria, one line per reason (an overflowed bound makes every one
    // undefined for the same reason): "D_f yz, zx, yx; V_f yz, zx, yx undefined: …".
    let mut reasons: Vec<(&str, Vec<String>)> = Vec::new();
    let undefined = c
        .per_state
        .iter()
        .map(|p| (p.state.as_str(), &p.undefined))
        .chain(std::iter::once(("weighted", &c.weighted.undefined)));
    for (state, list) in undefined {
        let mut by_reason: Vec<(&str, Vec<&str>)> = Vec::new();
        for (k, why) in list {
            match by_reason.iter_mut().find(|(w, _)| *w == why) {
                Some((_, ks)) => ks.push(k),
                None => by_reason.push((why, vec![k])),
            }
        }
        for (why, ks) in by_reason {
            let entry = format!("{state} {}", ks.join(", "));
            match reasons.iter_mut().find(|(w, _)| *w == why) {
                Some((_, entries)) => entries.push(entry),
                None => reasons.push((why, vec![entry])),
            }
        }
    }
    for (why, entries) in reasons {
        let _ = writeln!(s, "{set}: {} undefined: {why}", entries.join("; "));
    }
    for p in &c.per_state {
        let e = &p.excluded_steps;
        if e.yz + e.zx + e.yx > 0 {
            let _ = writeln!(
                s,
                "{set}: {} excluded steps (a zero denominator, or no measurement then): yz {}, zx {}, yx {}",
                p.state, e.yz, e.zx, e.yx
            );
        }
    }
}

/// The decimated traces as CSV: one row per trace point, columns `t` then
/// `<series>:<state>` for every series of every state (empty cell = undefined).
pub fn traces_csv(r: &AnalysisResult) -> String {
    let tr = &r.traces;
    let mut cols: Vec<(String, Vec<Option<f64>>)> = Vec::new();
    let some = |v: &Vec<f64>| v.iter().map(|x| Some(*x)).collect::<Vec<_>>();
    let opt = |v: &Vec<Option<f64>>| v.clone();
    for st in &tr.states {
        let n = &st.state;
        cols.push((format!("y:{n}"), some(&st.y)));
        cols.push((format!("eta:{n}"), opt(&st.eta)));
        if let Some(z) = &st.zeta {
            cols.push((format!("zeta:{n}"), opt(z)));
        }
        cols.push((format!("chi:{n}"), opt(&st.chi)));
        cols.push((format!("potential_sko:{n}"), opt(&st.potential_sko)));
        cols.push((format!("open_loop_sko:{n}"), opt(&st.open_loop_sko)));
        if let Some(z) = &st.measured_sko {
            cols.push((format!("measured_sko:{n}"), opt(z)));
        }
        cols.push((format!("rel_y:{n}"), opt(&st.rel_y)));
        if let Some(z) = &st.rel_z {
            cols.push((format!("rel_z:{n}"), opt(z)));
        }
        cols.push((format!("rel_x:{n}"), opt(&st.rel_x)));
        if let Some(z) = &st.local_yz {
            cols.push((format!("local_yz:{n}"), z.clone()));
        }
        if let Some(z) = &st.local_zx {
            cols.push((format!("local_zx:{n}"), z.clone()));
        }
        cols.push((format!("local_yx:{n}"), st.local_yx.clone()));
    }
    let header = std::iter::once("t".to_string()).chain(cols.iter().map(|(n, _)| n.clone()));
    let rows = tr.t.iter().enumerate().map(|(k, t)| {
        // (Plain, or in exponent form outside [1e-4, 1e15): never 300 digits for 1e300.
        // Either form reads back to the same f64.)
        std::iter::once(num(*t)).chain(cols.iter().map(move |(_, v)| match v.get(k) {
            Some(Some(x)) => num(*x),
            _ => String::new(),
        }))
    });
    csv_text(header, rows)
}

#[cfg(test)]
mod tests {
    use super::{CELL, cell, short, traces_csv};

    /// Criteria undefined for one reason are one line, not one per state and criterion
    /// (the tracker's bound overflows over 1000 s: six criteria, one reason).
    #[test]
    fn undefined_criteria_are_listed_once_per_reason() {
        let mut model = crate::presets::get("cv-tracker").unwrap();
        model.time.t_end = 1000.0;
        model.time.steps = crate::model::Steps::Fixed(10_000);
        let r = crate::analysis::analyze(
            &model,
            &Default::default(),
            &mut crate::progress::NoProgress,
        )
        .unwrap();
        let table = super::criteria_table(&r);
        let overflow: Vec<&str> = table
            .lines()
            .filter(|l| l.contains("overflowed at step"))
            .collect();
        assert_eq!(overflow.len(), 2, "{table}"); // the note and the warning
        assert!(
            overflow[0].starts_with("bound: position yx, yz, zx; velocity yx, yz, zx undefined: the bound (modulus procedure) overflowed"),
            "{table}"
        );
    }

    /// State names may hold a comma or a quote (not a line break: validation refuses
    /// control characters): the CSV quotes them (RFC 4180), so every record keeps its
    /// columns.
    #[test]
    fn csv_quotes_names_that_need_it() {
        let model = crate::model::model_from_value(serde_json::json!({
            "time": {"t0": 0, "t_end": 1, "steps": 100},
            "system": {"states": ["p,1", "v \"x\", w"], "a": [[0, 1], [0, 0]],
                       "b": [[0], [1]], "phi": [1], "eta0": [1, 1]},
            "measurement": {"names": ["z"], "c": [[1, 0]], "gamma": [[1]], "psi": [0.5]},
            "options": {"trace_points": 10}
        }))
        .unwrap();
        let r = crate::analysis::analyze(
            &model,
            &Default::default(),
            &mut crate::progress::NoProgress,
        )
        .unwrap();
        let text = traces_csv(&r);
        assert!(
            text.starts_with("t,\"y:p,1\",\"eta:p,1\","),
            "{}",
            &text[..80]
        );
        assert!(text.contains(",\"y:v \"\"x\"\", w\","), "{text}");
        let mut reader = csv::Reader::from_reader(text.as_bytes());
        let header = reader.headers().unwrap().clone();
        assert_eq!(&header[1], "y:p,1");
        assert_eq!(&header[header.len() - 1], "local_yx:v \"x\", w");
        let rows: Vec<csv::StringRecord> = reader.records().map(|r| r.unwrap()).collect();
        assert_eq!(rows.len(), r.traces.t.len());
        assert!(rows.iter().all(|row| row.len() == header.len()));
    }

    #[test]
    fn times_read_short() {
        assert_eq!(short(0.0 + 156.0 * 0.1), "15.6");
        assert_eq!(short(-1.0 / 3.0), "-0.333333333333");
        assert_eq!(short(1e-30), "1e-30");
        assert_eq!(short(2.5e20), "2.5e20");
        assert_eq!(short(0.0), "0");
    }

    #[test]
    fn cells_fit_their_column() {
        assert_eq!(cell(Some(48554.1906)), "48554.1906");
        assert_eq!(cell(Some(99999.99994)), "99999.9999");
        // Four decimals would take 11 characters here: the exponent form instead.
        assert_eq!(cell(Some(99999.99996)), "1.0000e5");
        assert_eq!(cell(Some(294309.2552)), "2.9431e5");
        assert_eq!(cell(Some(5.5301e25)), "5.5301e25");
        assert_eq!(cell(Some(0.0069)), "0.0069");
        assert_eq!(cell(Some(4.2e-4)), "4.2000e-4");
        assert_eq!(cell(Some(0.0)), "0.0000");
        assert_eq!(cell(None), "—");
        assert_eq!(cell(Some(f64::NAN)), "—");
        assert_eq!(cell(Some(f64::INFINITY)), "—");
        assert_eq!(cell(Some(1e-300)), "1.000e-300");
        for v in [1e-300, 3.3e-3, 1.0, 12345.678, 1e5, 7.7e7, 1e300] {
            assert!(cell(Some(v)).len() <= CELL, "{v}: {}", cell(Some(v)));
        }
    }
}
