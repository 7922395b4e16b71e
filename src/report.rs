//! Plain-text and CSV renderings of a result, shared by the CLI, the server and wasm.

use crate::result::{AnalysisResult, CriteriaSet};
use std::fmt::Write;

fn cell(x: Option<f64>) -> String {
    match x {
        Some(v) if v != 0.0 && !(1e-3..1e6).contains(&v.abs()) => format!("{v:.4e}"),
        Some(v) => format!("{v:.4}"),
        None => "—".to_string(),
    }
}

/// The seed's layout: per state and weighted, bound and covariance side by side.
pub fn criteria_table(r: &AnalysisResult) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "steps D = {}, dt = {:e}, t = [{}, {}]{}",
        r.steps,
        r.dt,
        r.t0,
        r.t_end,
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
    let _ = writeln!(
        s,
        "{:<w$} | {:^32} | {:^32}",
        "", "bound (modulus procedure)", "covariance (exact)"
    );
    let _ = writeln!(
        s,
        "{:<w$} | {:>10} {:>10} {:>10} | {:>10} {:>10} {:>10}",
        "state", "F_YZ", "F_ZX", "F_YX", "F_YZ", "F_ZX", "F_YX"
    );
    let _ = writeln!(s, "{}", "-".repeat(w + 70));
    let (b, c) = (&r.criteria.bound, &r.criteria.covariance);
    for (i, name) in r.states.iter().enumerate() {
        let (pb, pc) = (&b.per_state[i], &c.per_state[i]);
        let _ = writeln!(
            s,
            "{:<w$} | {:>10} {:>10} {:>10} | {:>10} {:>10} {:>10}",
            name,
            cell(pb.yz),
            cell(pb.zx),
            cell(pb.yx),
            cell(pc.yz),
            cell(pc.zx),
            cell(pc.yx)
        );
    }
    let _ = writeln!(s, "{}", "-".repeat(w + 70));
    let _ = writeln!(
        s,
        "{:<w$} | {:>10} {:>10} {:>10} | {:>10} {:>10} {:>10}",
        "weighted",
        cell(b.weighted.yz),
        cell(b.weighted.zx),
        cell(b.weighted.yx),
        cell(c.weighted.yz),
        cell(c.weighted.zx),
        cell(c.weighted.yx)
    );
    notes(&mut s, "bound", b);
    notes(&mut s, "covariance", c);
    if let Some(ss) = &r.steady_state {
        let _ = writeln!(
            s,
            "steady state reached at step {} (t = {}){}",
            ss.reached_at_step,
            ss.t,
            if ss.shortcut_used {
                ", shortcut used"
            } else {
                ""
            }
        );
    }
    for w in &r.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s
}

fn notes(s: &mut String, set: &str, c: &CriteriaSet) {
    for p in &c.per_state {
        for (k, why) in &p.undefined {
            let _ = writeln!(s, "{set}: {} {k} undefined: {why}", p.state);
        }
        let e = &p.excluded_steps;
        if e.yz + e.zx + e.yx > 0 {
            let _ = writeln!(
                s,
                "{set}: {} excluded steps (zero denominator): yz {}, zx {}, yx {}",
                p.state, e.yz, e.zx, e.yx
            );
        }
    }
    for (k, why) in &c.weighted.undefined {
        let _ = writeln!(s, "{set}: weighted {k} undefined: {why}");
    }
}

/// The decimated traces as CSV: one row per trace point, columns `t` then
/// `<series>:<state>` for every series of every state (empty cell = undefined).
pub fn traces_csv(r: &AnalysisResult) -> String {
    let tr = &r.traces;
    let mut cols: Vec<(String, Vec<Option<f64>>)> = Vec::new();
    let some = |v: &Vec<f64>| v.iter().map(|x| Some(*x)).collect::<Vec<_>>();
    for st in &tr.states {
        let n = &st.state;
        cols.push((format!("y:{n}"), some(&st.y)));
        cols.push((format!("eta:{n}"), some(&st.eta)));
        if let Some(z) = &st.zeta {
            cols.push((format!("zeta:{n}"), some(z)));
        }
        cols.push((format!("chi:{n}"), some(&st.chi)));
        cols.push((format!("potential_sko:{n}"), some(&st.potential_sko)));
        cols.push((format!("open_loop_sko:{n}"), some(&st.open_loop_sko)));
        if let Some(z) = &st.measured_sko {
            cols.push((format!("measured_sko:{n}"), some(z)));
        }
        cols.push((format!("rel_y:{n}"), some(&st.rel_y)));
        if let Some(z) = &st.rel_z {
            cols.push((format!("rel_z:{n}"), some(z)));
        }
        cols.push((format!("rel_x:{n}"), some(&st.rel_x)));
        if let Some(z) = &st.local_yz {
            cols.push((format!("local_yz:{n}"), z.clone()));
        }
        if let Some(z) = &st.local_zx {
            cols.push((format!("local_zx:{n}"), z.clone()));
        }
        cols.push((format!("local_yx:{n}"), st.local_yx.clone()));
    }
    let mut s = String::from("t");
    for (name, _) in &cols {
        s.push(',');
        s.push_str(name);
    }
    s.push('\n');
    for (k, t) in tr.t.iter().enumerate() {
        let _ = write!(s, "{t}");
        for (_, v) in &cols {
            s.push(',');
            if let Some(Some(x)) = v.get(k) {
                let _ = write!(s, "{x}");
            }
        }
        s.push('\n');
    }
    s
}
