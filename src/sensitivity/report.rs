//! The sensitivity in words: the ranked table of S = d ln F / d ln p.

use super::result::SensitivityResult;
use crate::text::{CELL, cell, short};
use std::fmt::Write;

/// `kea sensitivity`'s report: the base criteria, then one row per param (ranked) with
/// its value and its six sensitivities, covariance set first.
pub fn render_text(r: &SensitivityResult) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "d ln F / d ln p by central differences at p e^±h, h = {} (D = {}, {} analyses){}",
        short(r.relative_step),
        r.steps,
        r.analyses,
        if r.timing.wall_ms > 0.0 {
            format!(", {:.1} ms", r.timing.wall_ms)
        } else {
            String::new()
        }
    );
    let _ = writeln!(s, "ranked by |S| of {}", r.rank_by);
    let w = r
        .params
        .iter()
        .map(|p| p.name.chars().count())
        .max()
        .unwrap_or(0)
        .max("param".len())
        .max("base F".len());
    let cw = CELL;
    let set_w = 3 * cw + 2;
    let _ = writeln!(
        s,
        "{:<w$} {:>cw$} | {:^set_w$} | {:^set_w$}",
        "", "", "covariance (exact)", "bound (modulus procedure)"
    );
    let _ = writeln!(
        s,
        "{:<w$} {:>cw$} | {:>cw$} {:>cw$} {:>cw$} | {:>cw$} {:>cw$} {:>cw$}",
        "param", "value", "S_YZ", "S_ZX", "S_YX", "S_YZ", "S_ZX", "S_YX"
    );
    let rule = "-".repeat(w + cw + 3 + set_w + 3 + set_w + 1);
    let _ = writeln!(s, "{rule}");
    let b = &r.base;
    let _ = writeln!(
        s,
        "{:<w$} {:>cw$} | {:>cw$} {:>cw$} {:>cw$} | {:>cw$} {:>cw$} {:>cw$}",
        "base F",
        "",
        cell(b.covariance.yz),
        cell(b.covariance.zx),
        cell(b.covariance.yx),
        cell(b.bound.yz),
        cell(b.bound.zx),
        cell(b.bound.yx)
    );
    let _ = writeln!(s, "{rule}");
    for p in &r.params {
        let (c, bd) = (&p.sensitivity.covariance, &p.sensitivity.bound);
        let _ = writeln!(
            s,
            "{:<w$} {:>cw$} | {:>cw$} {:>cw$} {:>cw$} | {:>cw$} {:>cw$} {:>cw$}",
            p.name,
            cell(Some(p.value)),
            cell(c.yz),
            cell(c.zx),
            cell(c.yx),
            cell(bd.yz),
            cell(bd.zx),
            cell(bd.yx)
        );
    }
    for p in &r.params {
        if let Some(why) = &p.undefined {
            let _ = writeln!(s, "{}: {why}", p.name);
        }
    }
    let _ = writeln!(
        s,
        "S: a 1 % larger param changes the criterion by about S %; — where the criterion is undefined."
    );
    for w in &r.warnings {
        let _ = writeln!(s, "warning: {w}");
    }
    s
}
