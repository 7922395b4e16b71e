//! Matrices whose entries may vary with time: [`TimeMatrix`], built entry by entry by
//! [`TimeMatrixBuilder`] (one parse per distinct text), and its evaluation over a time
//! grid, [`LANES`] grid points at a time.

use super::{Entry, ExprBudget, LANES, TimeFn, Value, compile_entry};
use crate::error::FieldError;
use std::collections::{BTreeMap, HashMap};

/// A matrix (row-major) whose entries may vary with time.
#[derive(Clone, Debug)]
pub struct TimeMatrix {
    pub rows: usize,
    pub cols: usize,
    /// Current values, row-major; constant entries are set once.
    pub values: Vec<f64>,
    /// (flat index, index into `fns`, path) of each time-varying entry, by index.
    varying: Vec<(usize, usize, String)>,
    /// The distinct time-dependent expressions (entries with one text share one).
    fns: Vec<TimeFn>,
    /// `update_grid`'s cache: the grid (t0, Δt bits), the first grid index held,
    /// and LANES values of each of `fns`.
    block_grid: Option<(u64, u64, u64)>,
    block_values: Vec<[f64; LANES]>,
}

impl TimeMatrix {
    pub fn constant(rows: usize, cols: usize, values: Vec<f64>) -> Self {
        debug_assert_eq!(values.len(), rows * cols);
        TimeMatrix {
            rows,
            cols,
            values,
            varying: Vec::new(),
            fns: Vec::new(),
            block_grid: None,
            block_values: Vec::new(),
        }
    }

    pub fn is_constant(&self) -> bool {
        self.varying.is_empty()
    }

    /// Whether entry `i` (flat, row-major) depends on t.
    pub fn varies(&self, i: usize) -> bool {
        self.varying.binary_search_by_key(&i, |v| v.0).is_ok()
    }

    /// Re-evaluate the time-varying entries at the grid point t = t0 + i·Δt — the
    /// same t, and the same values, as `TimeFn::eval(t0 + i as f64 * dt)` — evaluating
    /// LANES consecutive grid points at a time: for stepping through a grid in order.
    /// Err((path, t)) if one is not finite at this point.
    #[inline]
    pub fn update_grid(&mut self, t0: f64, dt: f64, i: u64) -> Result<(), (&str, f64)> {
        let grid = (t0.to_bits(), dt.to_bits());
        let lane = match self.block_grid {
            Some((g0, gd, first)) if (g0, gd) == grid && i >= first && i - first < LANES as u64 => {
                (i - first) as usize
            }
            _ => {
                self.eval_blocks(t0, dt, i);
                0
            }
        };
        for (idx, f, path) in &self.varying {
            let v = self.block_values[*f][lane];
            if !v.is_finite() {
                return Err((path.as_str(), t0 + i as f64 * dt));
            }
            self.values[*idx] = v;
        }
        Ok(())
    }

    /// Every expression at grid points i .. i + LANES, into `block_values`. Out of
    /// line, so that the steps served from the cache do not set up its frame (the
    /// exmex evaluation's, a few KB).
    #[inline(never)]
    fn eval_blocks(&mut self, t0: f64, dt: f64, i: u64) {
        let ts: [f64; LANES] = std::array::from_fn(|l| t0 + (i + l as u64) as f64 * dt);
        for (f, out) in self.fns.iter_mut().zip(&mut self.block_values) {
            *out = f.eval_block(ts);
        }
        self.block_grid = Some((t0.to_bits(), dt.to_bits(), i));
    }
}

/// Compiles a [`TimeMatrix`] entry by entry, in row-major order. Entries with the
/// same expression text are compiled once and share the result: a model that
/// repeats `"0.3*sin(2*t)"` over a 200 × 200 matrix parses it once and evaluates it
/// once per step.
#[derive(Debug)]
pub struct TimeMatrixBuilder {
    m: TimeMatrix,
    by_text: HashMap<String, Shared>,
}

#[derive(Clone, Copy, Debug)]
enum Shared {
    Const(f64),
    Fn(usize),
}

impl TimeMatrixBuilder {
    pub fn new(rows: usize, cols: usize) -> Self {
        TimeMatrixBuilder {
            m: TimeMatrix::constant(rows, cols, vec![0.0; rows * cols]),
            by_text: HashMap::new(),
        }
    }

    /// Compile entry `i` (flat, row-major; after every entry before it) at `path`.
    /// `budget`: what the model's distinct time-dependent expressions have used so
    /// far (see [`MAX_TIME_EXPRESSIONS`](super::MAX_TIME_EXPRESSIONS)). On error the
    /// entry stays 0.
    pub fn set(
        &mut self,
        i: usize,
        value: &Value,
        params: &BTreeMap<String, f64>,
        path: String,
        t0: f64,
        budget: &mut ExprBudget,
    ) -> Result<(), FieldError> {
        debug_assert!(self.m.varying.last().is_none_or(|v| v.0 < i));
        let text = match value {
            Value::Expr(s) => Some(s.as_str()),
            Value::Number(_) => None,
        };
        let shared = match text.and_then(|s| self.by_text.get(s)) {
            Some(&s) => s,
            // Past a limit (reported once, at the first entry beyond it): the model is
            // refused, so the rest of it is not parsed.
            None if budget.exceeded => return Ok(()),
            None => {
                let s = match compile_entry(value, params, &path, true, t0)? {
                    Entry::Const(x) => Shared::Const(x),
                    Entry::Time(f) => {
                        budget
                            .take(value)
                            .map_err(|why| FieldError::new(&path, why))?;
                        self.m.fns.push(*f);
                        Shared::Fn(self.m.fns.len() - 1)
                    }
                };
                if let Some(text) = text {
                    self.by_text.insert(text.to_string(), s);
                }
                s
            }
        };
        match shared {
            Shared::Const(x) => self.m.values[i] = x,
            Shared::Fn(f) => self.m.varying.push((i, f, path)),
        }
        Ok(())
    }

    pub fn finish(self) -> TimeMatrix {
        let mut m = self.m;
        m.block_values = vec![[0.0; LANES]; m.fns.len()];
        m
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::tests::params;

    /// A 2 × 2 matrix: two entries share `text`, one is constant, one is `other`.
    fn grid_matrix(text: &str, other: &str) -> TimeMatrix {
        let mut b = TimeMatrixBuilder::new(2, 2);
        let mut budget = ExprBudget::default();
        for (i, v) in [text, "s/m", other, text].iter().enumerate() {
            b.set(
                i,
                &(*v).into(),
                &params(),
                format!("x[{i}]"),
                0.0,
                &mut budget,
            )
            .unwrap();
        }
        b.finish()
    }

    #[test]
    fn update_grid_equals_one_point_evaluation_in_any_order() {
        let (text, other) = ("0.3*sin(2*t)+m*t^2", "exp(-t/s)");
        let mut m = grid_matrix(text, other);
        assert_eq!(m.fns.len(), 2, "entries 0 and 3 share one parse");
        let eval = |e: &str, t: f64| match compile_entry(&e.into(), &params(), "p", true, 0.0) {
            Ok(Entry::Time(mut f)) => f.eval(t),
            _ => panic!("time-varying"),
        };
        // In order, backwards, across block edges, and on a second grid.
        let visits = (0..40u64)
            .chain([39, 3, 16, 15, 0, 33])
            .map(|i| (0.5, 1e-3, i));
        for (t0, dt, i) in visits.chain((0..20).map(|i| (0.0, 0.37, i))) {
            m.update_grid(t0, dt, i).unwrap();
            let t = t0 + i as f64 * dt;
            assert_eq!(m.values[0].to_bits(), eval(text, t).to_bits(), "t = {t}");
            assert_eq!(m.values[3].to_bits(), m.values[0].to_bits());
            assert_eq!(m.values[2].to_bits(), eval(other, t).to_bits(), "t = {t}");
            assert_eq!(m.values[1], 37.17 / 100.0);
        }
    }

    #[test]
    fn update_grid_names_the_first_entry_that_is_not_finite() {
        // Both entries of `ln(2.5 - t)` fail from t = 2.5: the first (row-major) is named.
        let mut m = grid_matrix("ln(2.5-t)", "t");
        m.update_grid(0.0, 0.5, 4).unwrap();
        assert_eq!(m.update_grid(0.0, 0.5, 5), Err(("x[0]", 2.5)));
    }
}
