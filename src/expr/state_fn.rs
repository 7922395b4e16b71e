//! An expression in a nonlinear model's states, `t` and its params
//! (`crate::nonlinear`): its value and its exact partial derivatives in the states,
//! by the forward-mode dual numbers of [`super::dual`] — one evaluation per state the
//! text names (a state it does not name has derivative 0, exactly).
//!
//! Why not a symbolic derivative: exmex's `partial` knows only exmex's default
//! operators, not kea's table (`signum`, `round`, `atan2`, `min`, `max` with their
//! meanings here), and a derivative text would be a second expression to keep in step
//! with the first. The dual numbers carry the chain rule through the very operator
//! table the value uses, so the value is `ScalarOps`'s bit for bit and the derivative
//! is exact to rounding (a test compares both with central differences).

use super::dual::{DIRECTIONS, Dual, DualEx, Grad};
use super::dual_lanes::{DUAL_LANES, DualBlock, DualBlockEx};
use super::tape::DualTape;
use super::translate::{translate, unknown};
use super::{MAX_EXPRESSION_CHARS, Value, cannot_parse, names};
use crate::error::FieldError;
use exmex::prelude::*;
use std::collections::BTreeMap;
use std::sync::Arc;

/// What one of the expression's variables is.
#[derive(Clone, Copy, Debug)]
enum Slot {
    /// A number, constant or param: its value.
    Fixed(f64),
    /// The time.
    T,
    /// State `i`.
    State(usize),
}

/// A compiled expression in the states, `t` and the params (the params' values are
/// fixed at compile time).
#[derive(Clone, Debug)]
pub struct StateFn {
    expr: Arc<DualEx>,
    /// The same text over blocks of dual numbers, for many states at once
    /// ([`StateFn::eval_many_with_gradient`]), and its variables' values.
    block: Arc<DualBlockEx>,
    block_vars: Vec<DualBlock>,
    /// The same text as kea's own tape over blocks (in place, no copies per node;
    /// None for a text it does not take, which `block` then evaluates), and its
    /// registers.
    tape: Option<Arc<DualTape>>,
    registers: Vec<DualBlock>,
    slots: Vec<Slot>,
    /// The states the text names, each once, in state order.
    used: Vec<usize>,
    /// The variables' values for the next evaluation (kept: no allocation per call).
    vars: Vec<Dual>,
    text: String,
    /// A text that is one state's name (`x2`, `f` = ẋ1 = x2; `h` = x1): its value and
    /// its gradient without an evaluation — the most common entries of f and h.
    only: Option<usize>,
}

impl StateFn {
    /// Compile `value` (a number or a text) at `path`; `states` are the state names
    /// (distinct, none of them a param, `t` or a name of the language: the caller's
    /// checks).
    pub fn compile(
        value: &Value,
        states: &[String],
        params: &BTreeMap<String, f64>,
        path: &str,
    ) -> Result<StateFn, FieldError> {
        let text = match value {
            Value::Number(x) if x.is_finite() => format!("{x:?}"),
            Value::Number(_) => return Err(FieldError::new(path, "expected a finite number")),
            Value::Expr(s) => s.clone(),
        };
        if text.trim().is_empty() {
            return Err(FieldError::new(
                path,
                "empty expression: expected a number or an expression such as \"-b*abs(x2)*x2\"",
            ));
        }
        let chars = text.chars().count();
        if chars > MAX_EXPRESSION_CHARS {
            return Err(FieldError::new(
                path,
                format!("expression of {chars} characters; the limit is {MAX_EXPRESSION_CHARS}"),
            ));
        }
        // The translator knows a name by the map it is given: the params and the states.
        let mut known = params.clone();
        for s in states {
            known.insert(s.clone(), 0.0);
        }
        let (plain, literals) = translate(&text, &known, path, true)?;
        let expr = DualEx::parse(&plain).map_err(|e| cannot_parse(&text, path, &e))?;
        let block = DualBlockEx::parse(&plain).map_err(|e| cannot_parse(&text, path, &e))?;
        debug_assert_eq!(expr.var_names(), block.var_names());
        let mut slots = Vec::with_capacity(expr.var_names().len());
        for name in expr.var_names() {
            let literal = name
                .strip_prefix('#')
                .and_then(|k| literals.get(k.parse::<usize>().ok()?));
            let slot = if let Some(&v) = literal {
                Slot::Fixed(v)
            } else if name == "t" {
                Slot::T
            } else if let Some(i) = states.iter().position(|s| s == name) {
                Slot::State(i)
            } else if let Some(&v) = params.get(name.as_str()) {
                Slot::Fixed(v)
            } else {
                return Err(unknown(&text, name, &known, path, true));
            };
            slots.push(slot);
        }
        let mut used: Vec<usize> = names(&text)
            .iter()
            .filter_map(|n| states.iter().position(|s| s == n))
            .collect();
        used.sort_unstable();
        used.dedup();
        let vars = vec![Dual::default(); slots.len()];
        let block_vars = vec![DualBlock::default(); slots.len()];
        let tape = DualTape::compile(&text, expr.var_names());
        let registers = vec![DualBlock::default(); tape.as_ref().map_or(0, DualTape::registers)];
        let only = states.iter().position(|s| s == text.trim());
        Ok(StateFn {
            expr: Arc::new(expr),
            block: Arc::new(block),
            block_vars,
            tape: tape.map(Arc::new),
            registers,
            slots,
            used,
            vars,
            text,
            only,
        })
    }

    /// The text as written (a number as Rust prints it).
    pub fn text(&self) -> &str {
        &self.text
    }

    /// The states the text names, in state order.
    pub fn used(&self) -> &[usize] {
        &self.used
    }

    /// Set the variables at (`x`, `t`), the derivative directions on the states
    /// `directions` (at most [`DIRECTIONS`]), and evaluate.
    #[inline]
    fn eval(&mut self, x: &[f64], t: f64, directions: &[usize]) -> Dual {
        for (v, slot) in self.vars.iter_mut().zip(&self.slots) {
            *v = match *slot {
                Slot::Fixed(v) => Dual { v, d: Grad::ZERO },
                Slot::T => Dual {
                    v: t,
                    d: Grad::ZERO,
                },
                Slot::State(i) => {
                    let mut d = Grad::ZERO;
                    if let Some(k) = directions.iter().position(|&j| j == i) {
                        d.0[k] = 1.0;
                    }
                    Dual { v: x[i], d }
                }
            };
        }
        // Errors cannot happen after a successful parse with the right variable count;
        // NaN makes the caller's finiteness check fire with the expression's path.
        self.expr.eval(&self.vars).unwrap_or(Dual {
            v: f64::NAN,
            d: Grad([f64::NAN; DIRECTIONS]),
        })
    }

    /// The value at the state `x` and time `t`.
    #[inline]
    pub fn value(&mut self, x: &[f64], t: f64) -> f64 {
        match self.only {
            Some(i) => x[i],
            None => self.eval(x, t, &[]).v,
        }
    }

    /// The value at (`x`, `t`), and the gradient in the states into `grad` (length N;
    /// zero for the states the text does not name). One evaluation per [`DIRECTIONS`]
    /// states the text names (one when it names none); none for a text that is one
    /// state's name.
    #[inline]
    pub fn eval_with_gradient(&mut self, x: &[f64], t: f64, grad: &mut [f64]) -> f64 {
        grad.fill(0.0);
        if let Some(i) = self.only {
            grad[i] = 1.0;
            return x[i];
        }
        if self.used.is_empty() {
            return self.eval(x, t, &[]).v;
        }
        let mut value = f64::NAN;
        let used = std::mem::take(&mut self.used);
        for chunk in used.chunks(DIRECTIONS) {
            let d = self.eval(x, t, chunk);
            value = d.v;
            for (k, &j) in chunk.iter().enumerate() {
                grad[j] = d.d[k];
            }
        }
        self.used = used;
        value
    }
    /// The values and gradients at several states at once: `xs` holds `values.len()`
    /// states of `n` components each (row by row), `grads` receives their gradients
    /// (the same shape). Each row's value and gradient equal
    /// [`StateFn::eval_with_gradient`]'s at that state bit for bit; the expression is
    /// evaluated once per [`DUAL_LANES`] rows (and [`DIRECTIONS`] named states), not
    /// once per row — the bank's filters share exmex's bookkeeping.
    pub fn eval_many_with_gradient(
        &mut self,
        xs: &[f64],
        n: usize,
        t: f64,
        values: &mut [f64],
        grads: &mut [f64],
    ) {
        let rows = values.len();
        if rows == 1 || self.only.is_some() || self.used.is_empty() {
            for r in 0..rows {
                let x = &xs[r * n..r * n + n];
                values[r] = self.eval_with_gradient(x, t, &mut grads[r * n..r * n + n]);
            }
            return;
        }
        grads[..rows * n].fill(0.0);
        let used = std::mem::take(&mut self.used);
        for first in (0..rows).step_by(DUAL_LANES) {
            let count = DUAL_LANES.min(rows - first);
            for chunk in used.chunks(DIRECTIONS) {
                let out = self.eval_block(xs, n, t, first, count, chunk);
                for (l, d) in out.0[..count].iter().enumerate() {
                    let r = first + l;
                    values[r] = d.v;
                    for (k, &j) in chunk.iter().enumerate() {
                        grads[r * n + j] = d.d[k];
                    }
                }
            }
        }
        self.used = used;
    }

    /// One evaluation over the rows `first..first + count` of `xs` (the block's other
    /// lanes repeat the first row), directions on the states `directions`.
    #[inline]
    fn eval_block(
        &mut self,
        xs: &[f64],
        n: usize,
        t: f64,
        first: usize,
        count: usize,
        directions: &[usize],
    ) -> DualBlock {
        for (v, slot) in self.block_vars.iter_mut().zip(&self.slots) {
            *v = match *slot {
                Slot::Fixed(v) => DualBlock([Dual { v, d: Grad::ZERO }; DUAL_LANES]),
                Slot::T => DualBlock(
                    [Dual {
                        v: t,
                        d: Grad::ZERO,
                    }; DUAL_LANES],
                ),
                Slot::State(i) => {
                    let mut d = Grad::ZERO;
                    if let Some(k) = directions.iter().position(|&j| j == i) {
                        d.0[k] = 1.0;
                    }
                    DualBlock(std::array::from_fn(|l| {
                        let r = first + if l < count { l } else { 0 };
                        Dual {
                            v: xs[r * n + i],
                            d,
                        }
                    }))
                }
            };
        }
        if let Some(tape) = &self.tape {
            return tape.eval(&self.block_vars, &mut self.registers);
        }
        // As in `eval`: NaN for the caller's finiteness check.
        self.block.eval(&self.block_vars).unwrap_or(DualBlock(
            [Dual {
                v: f64::NAN,
                d: Grad([f64::NAN; DIRECTIONS]),
            }; DUAL_LANES],
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn states() -> Vec<String> {
        vec!["x1".into(), "x2".into()]
    }

    fn params() -> BTreeMap<String, f64> {
        BTreeMap::from([("b".to_string(), 1.5)])
    }

    /// The seed's drag law and its gradient in closed form.
    #[test]
    fn gradient_of_the_drag_law_is_the_closed_form() {
        let mut f = StateFn::compile(
            &Value::Expr("-b*abs(x2)*x2/abs(x1)".into()),
            &states(),
            &params(),
            "system.f[1]",
        )
        .unwrap();
        let (x1, x2, b) = (900.0, -40.0, 1.5);
        let mut g = [0.0; 2];
        let v = f.eval_with_gradient(&[x1, x2], 0.0, &mut g);
        assert_eq!(v, -b * f64::abs(x2) * x2 / f64::abs(x1));
        let d1 = b * x2.abs() * x2 / (x1 * x1.abs());
        let d2 = -2.0 * b * x2.abs() / x1.abs();
        assert!((g[0] - d1).abs() <= 1e-15 * d1.abs(), "{} {d1}", g[0]);
        assert!((g[1] - d2).abs() <= 1e-15 * d2.abs(), "{} {d2}", g[1]);
        assert_eq!(f.used(), &[0, 1]);
    }

    #[test]
    fn time_numbers_and_unnamed_states() {
        let mut f = StateFn::compile(
            &Value::Expr("x2 + sin(t)".into()),
            &states(),
            &params(),
            "f",
        )
        .unwrap();
        let mut g = [9.0; 2];
        let v = f.eval_with_gradient(&[1.0, 2.0], 0.5, &mut g);
        assert_eq!(v, 2.0 + libm::sin(0.5));
        assert_eq!(g, [0.0, 1.0]);
        let mut c = StateFn::compile(&Value::Number(3.0), &states(), &params(), "f").unwrap();
        assert_eq!(c.eval_with_gradient(&[1.0, 2.0], 0.0, &mut g), 3.0);
        assert_eq!(c.value(&[1.0, 2.0], 0.0), 3.0);
        assert_eq!(g, [0.0, 0.0]);
    }

    #[test]
    fn unknown_names_are_errors_at_the_path() {
        let e = StateFn::compile(
            &Value::Expr("x3 + b".into()),
            &states(),
            &params(),
            "system.f[0]",
        )
        .unwrap_err();
        assert_eq!(e.path, "system.f[0]");
        assert!(
            e.message.contains("unknown parameter \"x3\""),
            "{}",
            e.message
        );
    }
    /// Many states at once give each state's single evaluation, bit for bit, for
    /// every count around the block's width.
    #[test]
    fn many_states_at_once_equal_one_at_a_time() {
        let texts = [
            "-b*abs(x2)*x2/abs(x1)",
            "x2",
            "sin(t) + 2",
            "x1*x2 + exp(-x2)*b",
        ];
        for text in texts {
            let mut f =
                StateFn::compile(&Value::Expr(text.into()), &states(), &params(), "f").unwrap();
            for rows in [1, 2, 7, 8, 9, 17] {
                let xs: Vec<f64> = (0..2 * rows).map(|i| 900.0 - 37.5 * i as f64).collect();
                let (mut values, mut grads) = (vec![0.0; rows], vec![7.0; 2 * rows]);
                f.eval_many_with_gradient(&xs, 2, 0.25, &mut values, &mut grads);
                for r in 0..rows {
                    let mut g = [0.0; 2];
                    let v = f.eval_with_gradient(&xs[2 * r..2 * r + 2], 0.25, &mut g);
                    assert_eq!(
                        values[r].to_bits(),
                        v.to_bits(),
                        "{text}, {rows} rows, row {r}"
                    );
                    assert_eq!(grads[2 * r].to_bits(), g[0].to_bits(), "{text}, row {r}");
                    assert_eq!(
                        grads[2 * r + 1].to_bits(),
                        g[1].to_bits(),
                        "{text}, row {r}"
                    );
                }
            }
        }
    }
}
