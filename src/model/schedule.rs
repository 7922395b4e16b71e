//! Measurement schedules: when each measurement is available (METHOD §2, "measurements
//! arrive rarely, the prediction runs every step"). At a step where a measurement is
//! missing, the filter update uses only the available rows of C; with none available
//! the filtered covariance is the predicted one (R_k = r_k, p_k = 0).

use crate::error::FieldError;
use crate::expr::{Entry, ExprBudget, TimeFn, compile_entry};
use crate::model::Schedule;
use std::collections::BTreeMap;

#[derive(Clone, Debug)]
pub enum Availability {
    Always,
    Never,
    /// Available at steps k with k ≡ offset (mod every), 0 ≤ offset < every.
    Every {
        every: u64,
        offset: u64,
    },
    /// Available where the expression in t is > 0.
    When(TimeFn, String),
    /// Unavailable inside any of these closed intervals of t: the model's, sorted and
    /// merged where they overlap or touch (the same union), so that a step looks one
    /// up by bisection instead of testing each (a schedule of 10⁵ intervals made every
    /// step cost 10⁵ tests).
    Unavailable(Vec<(f64, f64)>),
}

#[derive(Clone, Debug)]
pub struct Schedules {
    pub items: Vec<Availability>,
}

impl Schedules {
    /// Fill `out[j]` with whether measurement j is available at step k (time t).
    /// Returns whether all are available; Err(path) if a `when` expression is not finite.
    #[inline]
    pub fn mask(&mut self, k: u64, t: f64, out: &mut [bool]) -> Result<bool, String> {
        let mut all = true;
        for (o, a) in out.iter_mut().zip(self.items.iter_mut()) {
            *o = match a {
                Availability::Always => true,
                Availability::Never => false,
                Availability::Every { every, offset } => k % *every == *offset,
                Availability::When(f, path) => {
                    let v = f.eval(t);
                    if !v.is_finite() {
                        return Err(path.clone());
                    }
                    v > 0.0
                }
                Availability::Unavailable(iv) => {
                    // Sorted, disjoint: the last interval starting at or before t.
                    let i = iv.partition_point(|(a, _)| *a <= t);
                    !(i > 0 && t <= iv[i - 1].1)
                }
            };
            all &= *o;
        }
        Ok(all)
    }
}

/// Closed intervals as their union: sorted by start, those that overlap or touch merged.
fn union(mut iv: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    iv.retain(|(a, b)| a <= b); // (an invalid one is refused; the model is not run)
    iv.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(iv.len());
    for (a, b) in iv {
        match out.last_mut() {
            Some(last) if a <= last.1 => last.1 = last.1.max(b),
            _ => out.push((a, b)),
        }
    }
    out
}

/// Compile `measurement.schedule` (n entries, null = always available).
pub fn compile(
    sched: &[Option<Schedule>],
    nm: usize,
    params: &BTreeMap<String, f64>,
    t0: f64,
    budget: &mut ExprBudget,
    errs: &mut Vec<FieldError>,
) -> Option<Schedules> {
    let base = "measurement.schedule";
    if sched.len() != nm {
        errs.push(FieldError::new(
            base,
            format!(
                "has {}, expected one per measurement ({nm}); use null for always",
                crate::text::entries(sched.len())
            ),
        ));
        return None;
    }
    let mut items = Vec::with_capacity(nm);
    for (j, s) in sched.iter().enumerate() {
        let path = format!("{base}[{j}]");
        let Some(s) = s else {
            items.push(Availability::Always);
            continue;
        };
        let given =
            s.every.is_some() as u8 + s.when.is_some() as u8 + s.unavailable.is_some() as u8;
        if given != 1 {
            errs.push(FieldError::new(
                &path,
                "give exactly one of every (a step count), when (an expression in t, available where > 0) or unavailable (a list of [t_from, t_to] intervals)",
            ));
            items.push(Availability::Always);
            continue;
        }
        if s.offset.is_some() && s.every.is_none() {
            errs.push(FieldError::new(
                format!("{path}.offset"),
                "offset goes with every",
            ));
        }
        if let Some(every) = s.every {
            if every == 0 {
                errs.push(FieldError::new(
                    format!("{path}.every"),
                    "expected a whole number of steps from 1, got 0",
                ));
                items.push(Availability::Always);
            } else {
                let offset = s.offset.unwrap_or(0);
                if offset >= every {
                    // A phase: offset 6 with every 4 would measure at steps 2, 6, 10, …
                    // where the reader expects the first measurement at step 6.
                    errs.push(FieldError::new(
                        format!("{path}.offset"),
                        format!(
                            "must be below every ({every}): the measurement is taken at the steps k with k mod {every} = offset, got {offset}"
                        ),
                    ));
                }
                items.push(Availability::Every { every, offset });
            }
        } else if let Some(when) = &s.when {
            let p = format!("{path}.when");
            if budget.is_exceeded() {
                // Refused already (reported once): not parsed.
                items.push(Availability::Always);
                continue;
            }
            match compile_entry(when, params, &p, true, t0) {
                Ok(Entry::Const(v)) => items.push(if v > 0.0 {
                    Availability::Always
                } else {
                    Availability::Never
                }),
                Ok(Entry::Time(f)) => {
                    // Counted with the model's other time-dependent expressions.
                    if let Err(why) = budget.take(when) {
                        errs.push(FieldError::new(&p, why));
                    }
                    items.push(Availability::When(*f, p));
                }
                Err(e) => {
                    errs.push(e);
                    items.push(Availability::Always);
                }
            }
        } else if let Some(iv) = &s.unavailable {
            let mut out = Vec::with_capacity(iv.len());
            for (i, [a, b]) in iv.iter().enumerate() {
                if !(a.is_finite() && b.is_finite() && a <= b) {
                    errs.push(FieldError::new(
                        format!("{path}.unavailable[{i}]"),
                        format!(
                            "expected [t_from, t_to] with finite t_from ≤ t_to, got [{a}, {b}]"
                        ),
                    ));
                }
                out.push((*a, *b));
            }
            items.push(Availability::Unavailable(union(out)));
        }
    }
    Some(Schedules { items })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// The union looked up by bisection says what testing every interval says, for
    /// overlapping, nested, touching and single-point intervals and times at their ends.
    #[test]
    fn unavailable_intervals_by_bisection_equal_testing_each() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for _ in 0..200 {
            let count = rng.random_range(1..12);
            let given: Vec<(f64, f64)> = (0..count)
                .map(|_| {
                    let a = rng.random_range(0..20) as f64 * 0.5;
                    (a, a + rng.random_range(0..6) as f64 * 0.5)
                })
                .collect();
            let mut s = Schedules {
                items: vec![Availability::Unavailable(union(given.clone()))],
            };
            if let Availability::Unavailable(u) = &s.items[0] {
                assert!(u.windows(2).all(|w| w[0].1 < w[1].0), "{u:?}");
            }
            for k in 0..=50 {
                let t = k as f64 * 0.25 - 0.5;
                let mut out = [true];
                s.mask(k, t, &mut out).unwrap();
                let naive = !given.iter().any(|(a, b)| t >= *a && t <= *b);
                assert_eq!(out[0], naive, "t = {t}, intervals {given:?}");
            }
        }
    }
}
