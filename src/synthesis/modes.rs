//! The three modes of a synthesis (METHOD §1.7): the seed's search, bisection on a log
//! scale with its monotonicity check, and the grid (the seed's Table 2); each answer
//! verified by a fresh analysis.

use super::Ctx;
use super::report::{best_of, fmt_num, fmt_params, fmt_value};
use super::request::crit_name;
use super::request::{
    Bisect, Cheaper, Grid, GridParam, SeedSearch, bisect_iterations_max, cartesian, levels,
    seed_order,
};
use super::result::{
    BisectOut, Details, GridCell, GridOut, Point, SeedSearchOut, Side, Status, Verification,
};
use crate::error::Error;
use crate::exec::Executor;
use crate::progress::Progress;
use std::collections::BTreeMap;

/// How much looser than the bisection answer the verification's "looser" point is.
pub const LOOSER_FACTOR: f64 = 1.01;
/// Relative tolerance of the monotonicity check (rounding of equal criteria).
const MONOTONE_TOL: f64 = 1e-9;

/// Index of the first value meeting the threshold: the seed's stopping rule.
pub fn first_meeting(values: &[Option<f64>], threshold: f64) -> Option<usize> {
    values
        .iter()
        .position(|v| v.is_some_and(|v| v >= threshold))
}

pub(super) type ModeOut = (Status, String, Option<Point>, Option<Verification>, Details);

fn named(names: &[String], values: &[f64]) -> Vec<(String, f64)> {
    names.iter().cloned().zip(values.iter().copied()).collect()
}

/// Re-analyse `point` (and `looser`, which must miss) for the verification.
fn verify<E: Executor>(
    ctx: &mut Ctx,
    exec: &E,
    point: &Point,
    looser: Option<&BTreeMap<String, f64>>,
    progress: &mut dyn Progress,
) -> Result<Verification, Error> {
    let as_list =
        |m: &BTreeMap<String, f64>| m.iter().map(|(k, v)| (k.clone(), *v)).collect::<Vec<_>>();
    let mut batch = vec![as_list(&point.params)];
    if let Some(l) = looser {
        batch.push(as_list(l));
    }
    let mut out = ctx.batch_warned(exec, batch, progress)?;
    let looser = if looser.is_some() {
        out.pop().map(|(p, _)| p)
    } else {
        None
    };
    let (again, warnings) = out.pop().expect("one result per point");
    let passed = again.meets && looser.as_ref().is_none_or(|l| !l.meets);
    Ok(Verification {
        point: again,
        looser,
        passed,
        warnings,
    })
}

/// The seed's procedure (METHOD §1.7): nested loops from the upper bounds, shrink
/// factors < 1, stop at the first point meeting the target.
pub(super) fn seed_search<E: Executor>(
    ctx: &mut Ctx,
    exec: &E,
    s: &SeedSearch,
    progress: &mut dyn Progress,
) -> Result<ModeOut, Error> {
    let names: Vec<String> = s.params.iter().map(|p| p.name.clone()).collect();
    let order = seed_order(&s.params);
    let levels: Vec<GridParam> = s
        .params
        .iter()
        .map(|p| GridParam {
            name: p.name.clone(),
            values: levels(p),
        })
        .collect();
    let points_total = order.len();
    let mut visited: Vec<Point> = Vec::new();
    let mut found: Option<Point> = None;
    for chunk in order.chunks(s.batch) {
        let batch = chunk.iter().map(|v| named(&names, v)).collect();
        for p in ctx.batch(exec, batch, progress)? {
            let meets = p.meets;
            visited.push(p.clone());
            if meets {
                found = Some(p);
                break;
            }
        }
        if found.is_some() {
            break;
        }
    }
    let details = |visited| {
        Details::SeedSearch(SeedSearchOut {
            levels: levels.clone(),
            points_total,
            visited,
        })
    };
    let crit = crit_name(ctx.target);
    match found {
        Some(p) => {
            let v = verify(ctx, exec, &p, None, progress)?;
            let message = format!(
                "{crit} = {} ≥ {} at {} (point {} of {} in the seed's order; verified by a fresh analysis: {}).",
                fmt_value(p.value),
                ctx.target.threshold,
                fmt_params(&p.params),
                visited.len(),
                points_total,
                if v.passed { "meets" } else { "FAILED" }
            );
            Ok((Status::Found, message, Some(p), Some(v), details(visited)))
        }
        None => {
            let best = visited
                .iter()
                .filter(|p| p.value.is_some())
                .max_by(|a, b| a.value.partial_cmp(&b.value).expect("finite criteria"));
            let message = format!(
                "No point of the {points_total} in the ranges reaches {crit} ≥ {}{}. Widen the ranges (lower the low bounds of {}) or lower the target.",
                ctx.target.threshold,
                best.map_or(String::new(), |b| format!(
                    " (the best is {} at {})",
                    fmt_value(b.value),
                    fmt_params(&b.params)
                )),
                names.join(", ")
            );
            Ok((Status::NotFound, message, None, None, details(visited)))
        }
    }
}

/// Whether values along increasing x are monotonic (within rounding), and if not the
/// index i where values[i−1], values[i], values[i+1] turn.
fn monotonic_violation(values: &[f64]) -> Option<usize> {
    let scale = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let tol = MONOTONE_TOL * scale;
    let mut dir = 0i8; // +1 rising, −1 falling
    for i in 1..values.len() {
        let d = values[i] - values[i - 1];
        let s = if d > tol {
            1
        } else if d < -tol {
            -1
        } else {
            0
        };
        if s != 0 {
            if dir != 0 && s != dir {
                return Some(i - 1);
            }
            dir = s;
        }
    }
    None
}

/// The boundary of one param by bisection on a log scale (METHOD §1.7).
pub(super) fn bisect<E: Executor>(
    ctx: &mut Ctx,
    exec: &E,
    b: &Bisect,
    progress: &mut dyn Progress,
) -> Result<ModeOut, Error> {
    let name = b.param.clone();
    let at = |x: f64| vec![(name.clone(), x)];
    let (l0, l1) = (b.low.ln(), b.high.ln());
    let n = b.probes;
    let xs: Vec<f64> = (0..n)
        .map(|i| match i {
            0 => b.low,
            i if i == n - 1 => b.high,
            i => (l0 + (l1 - l0) * i as f64 / (n - 1) as f64).exp(),
        })
        .collect();
    let probes = ctx.batch(exec, xs.iter().map(|&x| at(x)).collect(), progress)?;
    let mut evals: Vec<(f64, Point)> = xs.iter().copied().zip(probes).collect();
    let crit = crit_name(ctx.target);
    let thr = crate::text::num(ctx.target.threshold); // (for messages: 1e308 not in 309 digits)
    let out = |evals: &[(f64, Point)], side, bracket, iterations| {
        Details::Bisect(BisectOut {
            param: name.clone(),
            meets_side: side,
            bracket,
            iterations,
            evaluations: evals.iter().map(|(_, p)| p.clone()).collect(),
        })
    };
    let fmt_evals = |evals: &[(f64, Point)], idx: &[usize]| {
        idx.iter()
            .map(|&i| {
                format!(
                    "{} at {name} = {}",
                    fmt_value(evals[i].1.value),
                    fmt_num(evals[i].0)
                )
            })
            .collect::<Vec<_>>()
            .join(", ")
    };

    // Undefined criteria: no answer can be trusted.
    if let Some((x, p)) = evals.iter().find(|(_, p)| p.value.is_none()) {
        let message = format!(
            "{crit} is undefined at {name} = {} ({}); no boundary can be bisected.",
            fmt_num(*x),
            p.note.clone().unwrap_or_default()
        );
        return Ok((
            Status::NonMonotonic,
            message,
            None,
            None,
            out(&evals, None, None, 0),
        ));
    }
    let meets: Vec<bool> = evals.iter().map(|(_, p)| p.meets).collect();
    let transitions: Vec<usize> = (1..n).filter(|&i| meets[i] != meets[i - 1]).collect();
    let values: Vec<f64> = evals.iter().map(|(_, p)| p.value.unwrap()).collect();
    if transitions.len() > 1 || monotonic_violation(&values).is_some() {
        let i = monotonic_violation(&values).unwrap_or_else(|| transitions[0]);
        let idx: Vec<usize> = (i.saturating_sub(1)..(i + 2).min(n)).collect();
        let message = format!(
            "{crit} is not monotonic in {name} on [{}, {}] ({}){}: bisection could return a wrong answer, so none is given. Narrow the range to a monotonic part, or use a grid to see the shape.",
            fmt_num(b.low),
            fmt_num(b.high),
            fmt_evals(&evals, &idx),
            if transitions.len() > 1 {
                format!(
                    ", and the target is met on {} separate parts",
                    transitions.len() / 2 + 1
                )
            } else {
                String::new()
            }
        );
        return Ok((
            Status::NonMonotonic,
            message,
            None,
            None,
            out(&evals, None, None, 0),
        ));
    }
    if transitions.is_empty() {
        let best = best_of(evals.iter().map(|(_, p)| p), "range");
        return Ok(if meets[0] {
            (
                Status::WholeRangeMeets,
                format!(
                    "Every {name} in [{}, {}] meets {crit} ≥ {thr} ({}): the boundary lies outside the range; widen it.",
                    fmt_num(b.low),
                    fmt_num(b.high),
                    fmt_evals(&evals, &[0, n - 1])
                ),
                None,
                None,
                out(&evals, None, None, 0),
            )
        } else {
            (
                Status::NotFound,
                format!(
                    "No {name} in [{}, {}] reaches {crit} ≥ {thr}{best}",
                    fmt_num(b.low),
                    fmt_num(b.high)
                ),
                None,
                None,
                out(&evals, None, None, 0),
            )
        });
    }
    let t = transitions[0];
    let side = if meets[0] { Side::Low } else { Side::High };
    // The bracket: `good` meets, `bad` misses.
    let (mut good, mut bad) = if meets[0] {
        (xs[t - 1], xs[t])
    } else {
        (xs[t], xs[t - 1])
    };
    let mut iterations = 0u32;
    while good.max(bad) / good.min(bad) - 1.0 > b.rel_tol {
        // The geometric mean; √good·√bad where good·bad leaves f64's range.
        let mid = match (good * bad).sqrt() {
            m if m.is_finite() && m > 0.0 => m,
            _ => good.sqrt() * bad.sqrt(),
        };
        // Never reached with normal bounds and rel_tol ≥ 1e-12 (validation), but a
        // bracket with no double inside must end the loop, not repeat it forever.
        if !(mid > good.min(bad) && mid < good.max(bad)) || iterations >= bisect_iterations_max(b) {
            break;
        }
        let p = ctx.batch(exec, vec![at(mid)], progress)?.remove(0);
        iterations += 1;
        let pos = evals.partition_point(|(x, _)| *x < mid);
        let m = p.meets;
        evals.insert(pos, (mid, p));
        let values: Vec<f64> = evals
            .iter()
            .map(|(_, p)| p.value.unwrap_or(f64::NAN))
            .collect();
        if let Some(i) = monotonic_violation(&values) {
            let idx: Vec<usize> = (i.saturating_sub(1)..(i + 2).min(evals.len())).collect();
            let message = format!(
                "{crit} turns out not monotonic in {name} near {} ({}): no answer is given. Narrow the range or use a grid.",
                fmt_num(mid),
                fmt_evals(&evals, &idx)
            );
            return Ok((
                Status::NonMonotonic,
                message,
                None,
                None,
                out(&evals, Some(side), None, iterations),
            ));
        }
        if m {
            good = mid;
        } else {
            bad = mid;
        }
    }
    let answer = evals
        .iter()
        .find(|(x, _)| *x == good)
        .map(|(_, p)| p.clone())
        .expect("the bracket's ends were analysed");
    let looser_x = match side {
        Side::Low => good * LOOSER_FACTOR,
        Side::High => good / LOOSER_FACTOR,
    };
    let looser: BTreeMap<String, f64> = [(name.clone(), looser_x)].into_iter().collect();
    let v = verify(ctx, exec, &answer, Some(&looser), progress)?;
    let bracket = Some([good, bad]);
    if !v.passed {
        let message = format!(
            "Bisection ended at {name} = {} but the verification failed ({} there, {} at {name} = {}): {crit} is not monotonic near the boundary; no answer is given.",
            fmt_num(good),
            fmt_value(v.point.value),
            fmt_value(v.looser.as_ref().and_then(|l| l.value)),
            fmt_num(looser_x)
        );
        return Ok((
            Status::NonMonotonic,
            message,
            None,
            Some(v),
            out(&evals, Some(side), bracket, iterations),
        ));
    }
    let message = format!(
        "The loosest {name} meeting {crit} ≥ {thr} is {name} = {} ({}; the target is met for {name} {} it). Verified: {} there, {} at {name} = {} (1 % looser) misses.",
        fmt_num(good),
        fmt_value(answer.value),
        match side {
            Side::Low => "at or below",
            Side::High => "at or above",
        },
        fmt_value(v.point.value),
        fmt_value(v.looser.as_ref().and_then(|l| l.value)),
        fmt_num(looser_x)
    );
    Ok((
        Status::Found,
        message,
        Some(answer),
        Some(v),
        out(&evals, Some(side), bracket, iterations),
    ))
}

/// Criteria tables over up to three params (the seed's Table 2).
pub(super) fn grid<E: Executor>(
    ctx: &mut Ctx,
    exec: &E,
    g: &Grid,
    progress: &mut dyn Progress,
) -> Result<ModeOut, Error> {
    let names: Vec<String> = g.params.iter().map(|p| p.name.clone()).collect();
    let lists: Vec<Vec<f64>> = g.params.iter().map(|p| p.values.clone()).collect();
    let index_lists: Vec<Vec<f64>> = lists
        .iter()
        .map(|l| (0..l.len()).map(|i| i as f64).collect())
        .collect();
    let indices: Vec<Vec<usize>> = cartesian(&index_lists)
        .into_iter()
        .map(|v| v.into_iter().map(|i| i as usize).collect())
        .collect();
    let points: Vec<Vec<(String, f64)>> =
        cartesian(&lists).iter().map(|v| named(&names, v)).collect();
    let mut cells = Vec::with_capacity(points.len());
    let per_batch = exec.threads().max(1);
    let mut idx_iter = indices.into_iter();
    let mut rest = points;
    while !rest.is_empty() {
        let tail = rest.split_off(per_batch.min(rest.len()));
        for p in ctx.batch(exec, rest, progress)? {
            cells.push(GridCell {
                index: idx_iter.next().expect("one index per cell"),
                point: p,
            });
        }
        rest = tail;
    }
    let qualifying = cells.iter().filter(|c| c.point.meets).count();
    let crit = crit_name(ctx.target);
    let thr = crate::text::num(ctx.target.threshold); // (for messages)
    let cheapest = g.cost_order.as_ref().and_then(|order| {
        cells
            .iter()
            .filter(|c| c.point.meets)
            .min_by(|a, b| {
                for k in order {
                    let (x, y) = (a.point.params[&k.name], b.point.params[&k.name]);
                    let ord = match k.cheaper {
                        Cheaper::Higher => y.partial_cmp(&x),
                        Cheaper::Lower => x.partial_cmp(&y),
                    }
                    .expect("finite values");
                    if ord.is_ne() {
                        return ord;
                    }
                }
                std::cmp::Ordering::Equal
            })
            .cloned()
    });
    let out = |cheapest: Option<Vec<usize>>, cells| {
        Details::Grid(GridOut {
            params: g.params.clone(),
            cells,
            cheapest,
        })
    };
    match (&g.cost_order, cheapest) {
        (Some(_), Some(c)) => {
            let v = verify(ctx, exec, &c.point, None, progress)?;
            let message = format!(
                "{qualifying} of {} cells meet {crit} ≥ {thr}; the cheapest is {} with {} (verified by a fresh analysis: {}).",
                cells.len(),
                fmt_params(&c.point.params),
                fmt_value(c.point.value),
                if v.passed { "meets" } else { "FAILED" }
            );
            Ok((
                Status::Found,
                message,
                Some(c.point.clone()),
                Some(v),
                out(Some(c.index), cells),
            ))
        }
        _ if qualifying == 0 => {
            let best = best_of(cells.iter().map(|c| &c.point), "ranges");
            Ok((
                Status::NotFound,
                format!("No cell of {} meets {crit} ≥ {thr}{best}", cells.len()),
                None,
                None,
                out(None, cells),
            ))
        }
        _ => Ok((
            Status::Table,
            format!(
                "{qualifying} of {} cells meet {crit} ≥ {thr} (marked); give `cost_order` to pick the cheapest.",
                cells.len()
            ),
            None,
            None,
            out(None, cells),
        )),
    }
}
