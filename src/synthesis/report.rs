//! The synthesis in words: its messages' pieces (the params, the numbers, the
//! criterion's name, the best value) and the plain-text rendering with the grid's tables.

use super::result::{Details, Point, SynthesisResult};
use std::collections::BTreeMap;

/// The end of a "no point meets the target" message: " (the best is 3.2100): widen the
/// range or lower the target." — or, where no point has a value, why (a criterion
/// undefined everywhere has no best: "-inf" was printed, with advice to widen).
pub(super) fn best_of<'a>(points: impl Iterator<Item = &'a Point> + Clone, range: &str) -> String {
    match points.clone().filter_map(|p| p.value).reduce(f64::max) {
        Some(best) => {
            format!(
                " (the best is {}): widen the {range} or lower the target.",
                crate::text::cell(Some(best))
            )
        }
        None => {
            let why = points
                .filter_map(|p| p.note.as_deref())
                .next()
                .unwrap_or("no value");
            format!(
                ": the criterion has no value at any point ({why}); an analysis of the model says why (y_B = 0, no paired measurement, …)."
            )
        }
    }
}

pub(super) fn describe(params: &[(String, f64)]) -> String {
    params
        .iter()
        .map(|(k, v)| format!("{k} = {}", crate::text::num(*v)))
        .collect::<Vec<_>>()
        .join(", ")
}

pub(super) fn fmt_params(p: &BTreeMap<String, f64>) -> String {
    p.iter()
        .map(|(k, v)| format!("{k} = {}", fmt_num(*v)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A number in what a synthesis reports (notes, summaries, the bisection's
/// findings): rounded to 6 decimals or 5 significant digits, for reading. Where a
/// point's parameters must be quoted exactly — the point an analysis failed at
/// ([`describe`]) — [`crate::text::num`] is used instead.
pub(super) fn fmt_num(x: f64) -> String {
    if x != 0.0 && (x.abs() < 1e-3 || x.abs() >= 1e6) {
        format!("{x:.4e}")
    } else {
        format!("{}", (x * 1e6).round() / 1e6)
    }
}

/// A criterion's value as the analysis table writes it ([`crate::text::cell`]).
pub(super) fn fmt_value(v: Option<f64>) -> String {
    v.map_or("undefined".into(), |v| crate::text::cell(Some(v)))
}

/// A plain-text rendering: the message, and for a grid its tables (rows = first param,
/// columns = second, one table per value of the third), cells `F_YZ / F_ZX / F_YX`
/// with `*` on those meeting the target and `[ ]` around the cheapest.
pub fn render_text(r: &SynthesisResult) -> String {
    let mut s = String::new();
    // Cells of three criteria, each as the analysis table writes it.
    let f = crate::text::cell;
    const W: usize = 3 * crate::text::CELL + 8;
    match &r.details {
        Details::Grid(g) => {
            let rows = &g.params[0];
            let cols = g.params.get(1);
            let pages = g.params.get(2);
            let n_cols = cols.map_or(1, |c| c.values.len());
            let n_pages = pages.map_or(1, |p| p.values.len());
            for k in 0..n_pages {
                if let Some(p) = pages {
                    s += &format!("{} = {}\n", p.name, fmt_num(p.values[k]));
                }
                let head = match cols {
                    Some(c) => format!("{} \\ {}", rows.name, c.name),
                    None => rows.name.clone(),
                };
                s += &format!("{head:>14}");
                for j in 0..n_cols {
                    let h = cols.map_or("F_YZ / F_ZX / F_YX".into(), |c| fmt_num(c.values[j]));
                    s += &format!(" | {h:^W$}");
                }
                s += "\n";
                for (i, rv) in rows.values.iter().enumerate() {
                    s += &format!("{:>14}", fmt_num(*rv));
                    for j in 0..n_cols {
                        let mut idx = vec![i];
                        if cols.is_some() {
                            idx.push(j);
                        }
                        if pages.is_some() {
                            idx.push(k);
                        }
                        let cell = g.cells.iter().find(|c| c.index == idx);
                        let txt = cell.map_or(String::new(), |c| {
                            let p = &c.point;
                            let body = format!("{} / {} / {}", f(p.yz), f(p.zx), f(p.yx));
                            let mark = if p.meets { "*" } else { " " };
                            if g.cheapest.as_ref() == Some(&idx) {
                                format!("[{body}]{mark}")
                            } else {
                                format!(" {body} {mark}")
                            }
                        });
                        s += &format!(" | {txt:^W$}");
                    }
                    s += "\n";
                }
                s += "\n";
            }
        }
        Details::SeedSearch(d) => {
            for (i, p) in d.visited.iter().enumerate() {
                s += &format!(
                    "{:>4}  {}  →  {}{}\n",
                    i + 1,
                    fmt_params(&p.params),
                    fmt_value(p.value),
                    if p.meets { "  *" } else { "" }
                );
            }
        }
        Details::Bisect(d) => {
            for p in &d.evaluations {
                s += &format!(
                    "  {}  →  {}{}\n",
                    fmt_params(&p.params),
                    fmt_value(p.value),
                    if p.meets { "  *" } else { "" }
                );
            }
        }
    }
    s += &r.message;
    // The answer's analysis's warnings, as `kea analyze` prints them.
    for w in r.verification.iter().flat_map(|v| &v.warnings) {
        s += &format!("\nwarning (the answer's analysis): {w}");
    }
    s += &format!(
        "\n{} analyses of D = {} steps, {:.1} ms\n",
        r.analyses, r.steps, r.timing.wall_ms
    );
    s
}
