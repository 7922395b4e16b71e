//! Exact derivatives of constant entries in their params (the maximum-likelihood
//! identification needs them; exmex's `partial` knows only its default operators), by
//! forward-mode automatic differentiation: a [`Dual`] carries a value and its derivative
//! in one direction through [`DualOps`], the language's operator table with the chain
//! rule. Each value is `ScalarOps`'s function, so it equals `compile_const`'s bit for bit.

use super::translate::{translate, unknown};
use crate::error::FieldError;
use exmex::prelude::*;
use exmex::{BinOp, MakeOperators, Operator};
use std::collections::BTreeMap;
use std::str::FromStr;

/// How many directions a [`Dual`] carries at once: a nonlinear model's Jacobian row of
/// two states is one evaluation (`expr::StateFn`); more states take one per pair.
pub const DIRECTIONS: usize = 2;

/// Derivatives in [`DIRECTIONS`] directions.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Grad(pub [f64; DIRECTIONS]);

impl Grad {
    pub const ZERO: Grad = Grad([0.0; DIRECTIONS]);

    /// 1 in direction `k`, 0 in the others.
    pub fn unit(k: usize) -> Grad {
        let mut g = Grad::ZERO;
        g.0[k] = 1.0;
        g
    }

    fn map2(self, other: Grad, f: impl Fn(f64, f64) -> f64) -> Grad {
        let mut out = Grad::ZERO;
        for k in 0..DIRECTIONS {
            out.0[k] = f(self.0[k], other.0[k]);
        }
        out
    }
}

impl std::ops::Index<usize> for Grad {
    type Output = f64;
    fn index(&self, k: usize) -> &f64 {
        &self.0[k]
    }
}

impl std::ops::Add for Grad {
    type Output = Grad;
    fn add(self, o: Grad) -> Grad {
        self.map2(o, |a, b| a + b)
    }
}

impl std::ops::Sub for Grad {
    type Output = Grad;
    fn sub(self, o: Grad) -> Grad {
        self.map2(o, |a, b| a - b)
    }
}

impl std::ops::Neg for Grad {
    type Output = Grad;
    fn neg(self) -> Grad {
        self.map2(Grad::ZERO, |a, _| -a)
    }
}

impl std::ops::Mul<Grad> for f64 {
    type Output = Grad;
    fn mul(self, g: Grad) -> Grad {
        g.map2(Grad::ZERO, |a, _| self * a)
    }
}

/// A value `v` and its derivatives `d` in [`DIRECTIONS`] directions.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Dual {
    pub v: f64,
    pub d: Grad,
}

impl FromStr for Dual {
    type Err = std::num::ParseFloatError;
    /// A literal: exmex's `f64` parse, derivative 0.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        f64::from_str(s).map(|v| Dual { v, d: Grad::ZERO })
    }
}

/// `slope · dx`, and 0 when `dx` is 0 even where `slope` is infinite or NaN: a function
/// of a constant sub-expression is constant (`sqrt(r - r)`, `0^0.5`), so only moving
/// an argument where no derivative exists is an error.
/// a + b, a − b, a·b, a/b and −a on dual numbers: the table's arithmetic, named so
/// that [`super::tape`]'s kernels are the table's functions.
#[inline(always)]
pub(super) fn add(a: Dual, b: Dual) -> Dual {
    Dual {
        v: a.v + b.v,
        d: a.d + b.d,
    }
}

#[inline(always)]
pub(super) fn sub(a: Dual, b: Dual) -> Dual {
    Dual {
        v: a.v - b.v,
        d: a.d - b.d,
    }
}

#[inline(always)]
pub(super) fn mul(a: Dual, b: Dual) -> Dual {
    Dual {
        v: a.v * b.v,
        d: term(b.v, a.d) + term(a.v, b.d),
    }
}

#[inline(always)]
pub(super) fn div(a: Dual, b: Dual) -> Dual {
    let v = a.v / b.v;
    Dual {
        v,
        d: term(1.0 / b.v, a.d) - term(v / b.v, b.d),
    }
}

#[inline(always)]
pub(super) fn neg(a: Dual) -> Dual {
    Dual { v: -a.v, d: -a.d }
}

pub(super) fn term(slope: f64, dx: Grad) -> Grad {
    dx.map2(Grad::ZERO, |dx, _| if dx == 0.0 { 0.0 } else { slope * dx })
}

/// `f(a)` of value `v` and derivative `slope` at `a.v`, by the chain rule.
pub(super) fn chain(a: Dual, v: f64, slope: f64) -> Dual {
    Dual {
        v,
        d: term(slope, a.d),
    }
}

/// A function whose derivative is 0 wherever it exists (signum, floor, round…; their
/// jumps are ignored).
pub(super) fn flat(v: f64) -> Dual {
    Dual { v, d: Grad::ZERO }
}

/// `a^b`: b·a^(b−1)·a′ + a^b·ln a·b′, with a^0's a-part 0 (a^0 is 1 for every a) and
/// 0^b's b-part 0 for b > 0 (0^b is 0 near every b > 0).
pub(super) fn pow(a: Dual, b: Dual) -> Dual {
    let v = libm::pow(a.v, b.v);
    let a_part = if b.v == 0.0 {
        0.0
    } else {
        b.v * libm::pow(a.v, b.v - 1.0)
    };
    let b_part = if a.v == 0.0 && b.v > 0.0 {
        0.0
    } else {
        v * libm::log(a.v)
    };
    Dual {
        v,
        d: term(a_part, a.d) + term(b_part, b.d),
    }
}

/// `atan2(y, x)`: (x·y′ − y·x′) / (x² + y²).
pub(super) fn atan2(y: Dual, x: Dual) -> Dual {
    let r2 = x.v * x.v + y.v * y.v;
    Dual {
        v: libm::atan2(y.v, x.v),
        d: term(x.v / r2, y.d) - term(y.v / r2, x.d),
    }
}

/// The derivative of whichever of `a` and `b` gave `v` (min or max); at a tie the mean
/// of the two one-sided derivatives, as `abs` at 0 (so max(x, −x) is abs(x) there too).
pub(super) fn chosen(a: Dual, b: Dual, v: f64) -> Dual {
    let d = if a.v == b.v {
        0.5 * (a.d + b.d)
    } else if v == a.v {
        a.d
    } else {
        b.d
    };
    Dual { v, d }
}

/// 1/√(1 − x²), asin's slope, without the cancellation of 1 − x² near ±1.
pub(super) fn inv_sqrt(x: f64) -> f64 {
    1.0 / (libm::sqrt(1.0 - x) * libm::sqrt(1.0 + x))
}

/// The language's sign function: −1, 0 or 1.
pub(super) fn sign(x: f64) -> f64 {
    if x == 0.0 { x } else { x.signum() }
}

/// The language's operators on dual numbers — `block::operators!`'s names,
/// priorities, commutativity and constants (`the_table_is_scalar_ops_table`), each
/// value by `ScalarOps`'s function — for a value type that `$un!` and `$bin!` lift a
/// [`Dual`] function to, and `$k!` a constant: one table for [`DualOps`] and
/// `lanes::DualLaneOps`.
macro_rules! dual_operators {
    ($un:ident, $bin:ident, $k:ident) => {{
        use std::f64::consts::{E, LN_2, LN_10, PI, TAU};
        vec![
            Operator::make_bin(
                "^",
                BinOp {
                    apply: $bin!(pow),
                    prio: 4,
                    is_commutative: false,
                },
            ),
            Operator::make_bin(
                "*",
                BinOp {
                    apply: $bin!(mul),
                    prio: 2,
                    is_commutative: true,
                },
            ),
            Operator::make_bin(
                "/",
                BinOp {
                    apply: $bin!(div),
                    prio: 3,
                    is_commutative: false,
                },
            ),
            Operator::make_bin_unary(
                "+",
                BinOp {
                    apply: $bin!(add),
                    prio: 0,
                    is_commutative: true,
                },
                $un!(|a: Dual| a),
            ),
            Operator::make_bin_unary(
                "-",
                BinOp {
                    apply: $bin!(sub),
                    prio: 1,
                    is_commutative: false,
                },
                $un!(neg),
            ),
            Operator::make_bin(
                "atan2",
                BinOp {
                    apply: $bin!(atan2),
                    prio: 0,
                    is_commutative: false,
                },
            ),
            Operator::make_bin(
                "min",
                BinOp {
                    apply: $bin!(|a: Dual, b: Dual| chosen(a, b, libm::fmin(a.v, b.v))),
                    prio: 0,
                    is_commutative: false,
                },
            ),
            Operator::make_bin(
                "max",
                BinOp {
                    apply: $bin!(|a: Dual, b: Dual| chosen(a, b, libm::fmax(a.v, b.v))),
                    prio: 0,
                    is_commutative: false,
                },
            ),
            Operator::make_unary("abs", $un!(|a: Dual| chain(a, a.v.abs(), sign(a.v)))),
            Operator::make_unary("signum", $un!(|a: Dual| flat(sign(a.v)))),
            Operator::make_unary(
                "sin",
                $un!(|a: Dual| chain(a, libm::sin(a.v), libm::cos(a.v))),
            ),
            Operator::make_unary(
                "cos",
                $un!(|a: Dual| chain(a, libm::cos(a.v), -libm::sin(a.v))),
            ),
            Operator::make_unary(
                "tan",
                $un!(|a: Dual| {
                    let v = libm::tan(a.v);
                    chain(a, v, 1.0 + v * v)
                }),
            ),
            Operator::make_unary(
                "asin",
                $un!(|a: Dual| chain(a, libm::asin(a.v), inv_sqrt(a.v))),
            ),
            Operator::make_unary(
                "acos",
                $un!(|a: Dual| chain(a, libm::acos(a.v), -inv_sqrt(a.v))),
            ),
            Operator::make_unary(
                "atan",
                $un!(|a: Dual| { chain(a, libm::atan(a.v), 1.0 / (1.0 + a.v * a.v)) }),
            ),
            Operator::make_unary(
                "sinh",
                $un!(|a: Dual| chain(a, libm::sinh(a.v), libm::cosh(a.v))),
            ),
            Operator::make_unary(
                "cosh",
                $un!(|a: Dual| chain(a, libm::cosh(a.v), libm::sinh(a.v))),
            ),
            Operator::make_unary(
                "tanh",
                $un!(|a: Dual| {
                    let c = libm::cosh(a.v);
                    chain(a, libm::tanh(a.v), 1.0 / (c * c))
                }),
            ),
            Operator::make_unary(
                "asinh",
                $un!(|a: Dual| { chain(a, libm::asinh(a.v), 1.0 / libm::hypot(a.v, 1.0)) }),
            ),
            Operator::make_unary(
                "acosh",
                $un!(|a: Dual| {
                    let slope = 1.0 / (libm::sqrt(a.v - 1.0) * libm::sqrt(a.v + 1.0));
                    chain(a, libm::acosh(a.v), slope)
                }),
            ),
            Operator::make_unary(
                "atanh",
                $un!(|a: Dual| { chain(a, libm::atanh(a.v), 1.0 / ((1.0 - a.v) * (1.0 + a.v))) }),
            ),
            Operator::make_unary("floor", $un!(|a: Dual| flat(a.v.floor()))),
            Operator::make_unary("round", $un!(|a: Dual| flat(a.v.round()))),
            Operator::make_unary("ceil", $un!(|a: Dual| flat(a.v.ceil()))),
            Operator::make_unary("trunc", $un!(|a: Dual| flat(a.v.trunc()))),
            Operator::make_unary(
                "fract",
                $un!(|a: Dual| Dual {
                    v: a.v.fract(),
                    d: a.d,
                }),
            ),
            Operator::make_unary(
                "exp",
                $un!(|a: Dual| {
                    let v = libm::exp(a.v);
                    chain(a, v, v)
                }),
            ),
            Operator::make_unary(
                "sqrt",
                $un!(|a: Dual| {
                    let v = a.v.sqrt();
                    chain(a, v, 0.5 / v)
                }),
            ),
            Operator::make_unary(
                "cbrt",
                $un!(|a: Dual| {
                    let v = libm::cbrt(a.v);
                    chain(a, v, 1.0 / (3.0 * v * v))
                }),
            ),
            Operator::make_unary("ln", $un!(|a: Dual| chain(a, libm::log(a.v), 1.0 / a.v))),
            Operator::make_unary(
                "log2",
                $un!(|a: Dual| chain(a, libm::log2(a.v), 1.0 / (a.v * LN_2))),
            ),
            Operator::make_unary(
                "log10",
                $un!(|a: Dual| chain(a, libm::log10(a.v), 1.0 / (a.v * LN_10))),
            ),
            Operator::make_unary("log", $un!(|a: Dual| chain(a, libm::log(a.v), 1.0 / a.v))),
            Operator::make_constant("PI", $k!(PI)),
            Operator::make_constant("π", $k!(PI)),
            Operator::make_constant("E", $k!(E)),
            Operator::make_constant("e", $k!(E)),
            Operator::make_constant("TAU", $k!(TAU)),
            Operator::make_constant("τ", $k!(TAU)),
        ]
    }};
}
pub(super) use dual_operators;

macro_rules! same {
    ($f:expr) => {
        $f
    };
}

macro_rules! dual_k {
    ($x:expr) => {
        Dual {
            v: $x,
            d: Grad::ZERO,
        }
    };
}

/// The operators on dual numbers.
#[derive(Clone, Debug)]
pub struct DualOps;

impl MakeOperators<Dual> for DualOps {
    fn make<'a>() -> Vec<Operator<'a, Dual>> {
        dual_operators!(same, same, dual_k)
    }
}

/// An expression parsed over dual numbers.
pub type DualEx = exmex::FlatEx<Dual, DualOps>;

/// A constant text's value and derivative with respect to each param of `directions`
/// (one evaluation each), for a text `compile_const` accepts.
pub(super) fn along(
    text: &str,
    params: &BTreeMap<String, f64>,
    directions: &[&str],
    path: &str,
) -> Result<Vec<Dual>, FieldError> {
    let (plain, literals) = translate(text, params, path, false)?;
    let expr = DualEx::parse(&plain).map_err(|e| super::cannot_parse(text, path, &e))?;
    let mut vars = Vec::with_capacity(expr.var_names().len());
    for name in expr.var_names() {
        let literal = name
            .strip_prefix('#')
            .and_then(|k| literals.get(k.parse::<usize>().ok()?));
        match literal.or_else(|| params.get(name.as_str())) {
            Some(&v) => vars.push((name.as_str(), v)),
            None => return Err(unknown(text, name, params, path, false)),
        }
    }
    let mut out = Vec::with_capacity(directions.len());
    for &direction in directions {
        let duals: Vec<Dual> = vars
            .iter()
            .map(|&(name, v)| Dual {
                v,
                d: if name == direction {
                    Grad::unit(0)
                } else {
                    Grad::ZERO
                },
            })
            .collect();
        let x = expr
            .eval(&duals)
            .map_err(|e| FieldError::new(path, format!("cannot evaluate \"{text}\": {e}")))?;
        out.push(x);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::block::ScalarOps;
    use crate::expr::{MAX_EXPRESSION_CHARS, Value, compile_const, compile_const_with_derivatives};

    /// The dual table is `ScalarOps`'s: the same names in the same order, the same
    /// unary and binary forms, priorities and commutativity, the same constants.
    #[test]
    fn the_table_is_scalar_ops_table() {
        let dual = <DualOps as MakeOperators<Dual>>::make();
        let scalar = <ScalarOps as MakeOperators<f64>>::make();
        assert_eq!(dual.len(), scalar.len());
        for (d, s) in dual.iter().zip(&scalar) {
            let name = s.repr();
            assert_eq!(d.repr(), name);
            assert_eq!(d.has_bin(), s.has_bin(), "{name}");
            assert_eq!(d.has_unary(), s.has_unary(), "{name}");
            if let (Ok(db), Ok(sb)) = (d.bin(), s.bin()) {
                assert_eq!(db.prio, sb.prio, "{name}");
                assert_eq!(db.is_commutative, sb.is_commutative, "{name}");
            }
            match (d.constant(), s.constant()) {
                (Some(dc), Some(sc)) => {
                    assert_eq!(dc.v.to_bits(), sc.to_bits(), "{name}");
                    assert_eq!(dc.d, Grad::ZERO, "{name}");
                }
                (None, None) => {}
                _ => panic!("{name}: a constant in one table only"),
            }
        }
    }

    fn params(pairs: &[(&str, f64)]) -> BTreeMap<String, f64> {
        pairs.iter().map(|&(k, v)| (k.to_string(), v)).collect()
    }

    /// The value of `text` by `compile_const`, `name` set to `x`.
    fn scalar(text: &str, p: &BTreeMap<String, f64>, name: &str, x: f64) -> f64 {
        let mut p = p.clone();
        p.insert(name.to_string(), x);
        compile_const(&text.into(), &p, "p").unwrap()
    }

    /// ∂text/∂name by central differences of `compile_const`, extrapolated twice
    /// (Richardson: error O(h⁶)).
    fn reference(text: &str, p: &BTreeMap<String, f64>, name: &str) -> f64 {
        let x = p[name];
        let central = |h: f64| {
            let (up, down) = (x + h, x - h);
            (scalar(text, p, name, up) - scalar(text, p, name, down)) / (up - down)
        };
        let h = 1e-3 * x.abs().max(1.0);
        let (d1, d2, d4) = (central(h), central(h / 2.0), central(h / 4.0));
        let (r1, r2) = ((4.0 * d2 - d1) / 3.0, (4.0 * d4 - d2) / 3.0);
        (16.0 * r2 - r1) / 15.0
    }

    /// `text`'s derivatives in each of its params `p` against the reference, within
    /// `tol` relative, and its value's bits against `compile_const`'s.
    fn check(text: &str, p: &BTreeMap<String, f64>, tol: f64) {
        let names: Vec<&str> = p.keys().map(String::as_str).collect();
        let want = compile_const(&text.into(), p, "p").unwrap();
        let duals = along(text, p, &names, "p").unwrap();
        let (value, derivatives) = compile_const_with_derivatives(&text.into(), p, &names, "p")
            .unwrap_or_else(|e| panic!("{text} at {p:?}: {}", e.message));
        assert_eq!(value.to_bits(), want.to_bits(), "{text} at {p:?}");
        for ((name, dual), &d) in names.iter().zip(&duals).zip(&derivatives) {
            assert_eq!(dual.v.to_bits(), want.to_bits(), "{text} at {p:?}");
            assert_eq!(dual.d[0].to_bits(), d.to_bits(), "{text} at {p:?}");
            let r = reference(text, p, name);
            assert!(
                (d - r).abs() <= tol * r.abs(),
                "∂{text}/∂{name} at {p:?}: {d} against {r} (relative {:e})",
                (d - r).abs() / r.abs()
            );
        }
    }

    /// Every function at points inside its domain, away from its kinks and jumps.
    #[test]
    fn functions_match_richardson_differences() {
        let cases: &[(&str, &[f64])] = &[
            ("abs", &[-1.3, 0.7, 2.5]),
            ("signum", &[-1.3, 0.7]),
            ("sin", &[-1.1, 0.3, 1.2, 2.0]),
            ("cos", &[-1.1, 0.3, 1.2, 2.0]),
            ("tan", &[-1.1, 0.3, 1.2, 2.0]),
            ("asin", &[-0.7, 0.2, 0.9]),
            ("acos", &[-0.7, 0.2, 0.9]),
            ("atan", &[-3.0, 0.5, 10.0]),
            ("sinh", &[-2.0, 0.4, 3.0]),
            ("cosh", &[-2.0, 0.4, 3.0]),
            ("tanh", &[-2.0, 0.4, 3.0]),
            ("asinh", &[-5.0, 0.3, 40.0]),
            ("acosh", &[1.2, 3.0, 50.0]),
            ("atanh", &[-0.8, 0.1, 0.6]),
            ("floor", &[-1.3, 0.7, 2.2]),
            ("round", &[-1.3, 0.7, 2.2]),
            ("ceil", &[-1.3, 0.7, 2.2]),
            ("trunc", &[-1.3, 0.7, 2.2]),
            ("fract", &[-1.3, 0.7, 2.2]),
            ("exp", &[-3.0, 0.5, 4.0]),
            ("sqrt", &[0.2, 2.0, 150.0]),
            ("cbrt", &[-8.0, 0.3, 27.0]),
            ("ln", &[0.2, 1.5, 300.0]),
            ("log2", &[0.2, 1.5, 300.0]),
            ("log10", &[0.2, 1.5, 300.0]),
            ("log", &[0.2, 1.5, 300.0]),
        ];
        let mut tested: Vec<&str> = Vec::new();
        for &(f, points) in cases {
            tested.push(f);
            for &x in points {
                check(&format!("{f}(x)"), &params(&[("x", x)]), 1e-10);
                // Inside an expression: the chain rule through a product and a sum.
                check(
                    &format!("y*{f}(x + 0.1*(y - 0.5))"),
                    &params(&[("x", x), ("y", 0.5)]),
                    1e-10,
                );
            }
        }
        // Every one-argument function of the language is here.
        let lang = crate::expr::language();
        assert_eq!(lang.unary, tested);
    }

    /// The operators and the two-argument functions, in each argument.
    #[test]
    fn operators_match_richardson_differences() {
        let points = [(0.7, -1.3), (2.5, 0.4), (-0.6, 3.1), (4.0, 7.0)];
        for text in [
            "x + y",
            "x - y",
            "x*y",
            "x/y",
            "atan2(x, y)",
            "min(x, y)",
            "max(x, y)",
            "-x*y",
            "+x*y",
            "-x^2*y",
        ] {
            for (x, y) in points {
                check(text, &params(&[("x", x), ("y", y)]), 1e-10);
            }
        }
        for (x, y) in [(0.7, 1.3), (2.5, -0.4), (1.9, 3.1), (0.3, 0.5)] {
            check("x^y", &params(&[("x", x), ("y", y)]), 1e-10);
        }
        // A negative base to a constant integer power.
        check("x^3", &params(&[("x", -1.5)]), 1e-10);
        check("x^-2", &params(&[("x", -1.5)]), 1e-10);
        let lang = crate::expr::language();
        assert_eq!(lang.binary, ["atan2", "min", "max"]);
    }

    /// `text`'s derivatives in `wrt` at `p` against closed forms, to a few ulps.
    fn closed(text: &str, p: &[(&str, f64)], wrt: &[&str], want: &[f64]) {
        let (_, got) = compile_const_with_derivatives(&text.into(), &params(p), wrt, "p")
            .unwrap_or_else(|e| panic!("{text}: {}", e.message));
        for ((name, g), w) in wrt.iter().zip(&got).zip(want) {
            assert!(
                (g - w).abs() <= 1e-14 * w.abs(),
                "∂{text}/∂{name}: {g} against {w}"
            );
        }
    }

    #[test]
    fn composites_match_closed_forms() {
        let (r, w) = (1.7f64, 0.6f64);
        let p = [("r", r), ("w", w)];
        closed("r*cos(w)", &p, &["r", "w"], &[w.cos(), -r * w.sin()]);
        closed("-r*sin(w)", &p, &["r", "w"], &[-w.sin(), -r * w.cos()]);
        closed("sw^2", &[("sw", 0.3)], &["sw"], &[0.6]);
        closed("c*g", &[("c", 2.2), ("g", -0.8)], &["c", "g"], &[-0.8, 2.2]);
        let (dt, tau) = (0.1f64, 3.5f64);
        let decay = (-dt / tau).exp();
        closed(
            "exp(-dt/tau)",
            &[("dt", dt), ("tau", tau)],
            &["dt", "tau"],
            &[-decay / tau, decay * dt / (tau * tau)],
        );
        closed("q^0.5", &[("q", 0.49)], &["q"], &[0.5 / 0.7]);
        let x = 1.3f64;
        closed(
            "2^-x",
            &[("x", x)],
            &["x"],
            &[-std::f64::consts::LN_2 * 2f64.powf(-x)],
        );
        let y = 2.4f64;
        closed(
            "x^y",
            &[("x", x), ("y", y)],
            &["x", "y"],
            &[y * x.powf(y - 1.0), x.powf(y) * x.ln()],
        );
        closed(
            "atan2(r, w)",
            &p,
            &["r", "w"],
            &[w / (r * r + w * w), -r / (r * r + w * w)],
        );
        closed("PI*r^2", &p, &["r"], &[2.0 * std::f64::consts::PI * r]);
    }

    /// Exact zeros: a param the text does not name, a number, a constant
    /// sub-expression (even where its function has no derivative), the flat functions.
    #[test]
    fn unnamed_params_and_numbers_have_zero_derivatives() {
        let p = params(&[("q", 0.0), ("r", 1.7), ("w", 0.6)]);
        let d = |text: &str, wrt: &[&str]| {
            compile_const_with_derivatives(&text.into(), &p, wrt, "p")
                .unwrap()
                .1
        };
        assert_eq!(d("r*cos(w)", &["q", "r"]), [0.0, 0.6f64.cos()]);
        assert_eq!(d("r*cos(w)", &[]), Vec::<f64>::new());
        // q = 0, where sqrt has no derivative: not an error when q is not moved.
        assert_eq!(d("sqrt(q) + r", &["r", "w"]), [1.0, 0.0]);
        assert_eq!(d("sqrt(r - r) + w", &["r", "w"]), [0.0, 1.0]);
        assert_eq!(d("floor(r)*w + round(w) + signum(r)", &["r"]), [0.0]);
        assert_eq!(d("r - r", &["r"]), [0.0]);
        assert_eq!(d("0^0.5*r + q^0*w", &["r", "q"]), [0.0, 0.0]);
        let (value, zeros) =
            compile_const_with_derivatives(&Value::Number(2.5), &p, &["r", "w"], "p").unwrap();
        assert_eq!((value, zeros), (2.5, vec![0.0, 0.0]));
    }

    /// At a tie min and max take the mean of the arguments' derivatives, abs at 0
    /// takes 0: max(x, −x) and abs(x) agree.
    #[test]
    fn ties_and_kinks_take_the_mean() {
        let d = |text: &str, x: f64| {
            compile_const_with_derivatives(&text.into(), &params(&[("x", x)]), &["x"], "p")
                .unwrap()
                .1[0]
        };
        assert_eq!(d("min(x, 2)", 2.0), 0.5);
        assert_eq!(d("max(2*x, 4)", 2.0), 1.0);
        assert_eq!(d("min(x, x)", 2.0), 1.0);
        assert_eq!(d("abs(x)", 0.0), 0.0);
        assert_eq!(d("max(x, -x)", 0.0), 0.0);
        assert_eq!(d("abs(x)", -3.0), -1.0);
        assert_eq!(d("max(x, -x)", -3.0), -1.0);
        assert_eq!(d("fract(x)", 2.0), 1.0);
    }

    #[test]
    fn non_finite_derivatives_are_errors() {
        let error = |text: &str, p: &[(&str, f64)], wrt: &[&str]| {
            compile_const_with_derivatives(&text.into(), &params(p), wrt, "system.q[0][0]")
                .unwrap_err()
        };
        let e = error("sqrt(q)", &[("q", 0.0)], &["q"]);
        assert_eq!(e.path, "system.q[0][0]");
        assert_eq!(
            e.message,
            "the derivative of \"sqrt(q)\" with respect to q is not finite at q = 0"
        );
        assert_eq!(
            error("2*asin(x)", &[("x", 1.0)], &["x"]).message,
            "the derivative of \"2*asin(x)\" with respect to x is not finite at x = 1"
        );
        assert!(
            error("cbrt(x)", &[("x", 0.0)], &["x"])
                .message
                .contains("not finite")
        );
        assert!(
            error("x^0.5", &[("x", 0.0)], &["x"])
                .message
                .contains("not finite")
        );
        // The second direction fails: it is named.
        let e = error(
            "r*(-x)^y",
            &[("r", 2.0), ("x", 1.5), ("y", 2.0)],
            &["r", "y"],
        );
        assert_eq!(
            e.message,
            "the derivative of \"r*(-x)^y\" with respect to y is not finite at y = 2"
        );
    }

    /// Bad entries give `compile_const`'s errors.
    #[test]
    fn bad_entries_give_compile_const_errors() {
        let p = params(&[("q", 0.3), ("r", 1.7)]);
        let long = format!("q{}", "+q".repeat(MAX_EXPRESSION_CHARS));
        let values: Vec<Value> = [
            "mass*q", "q*t", "", "   ", "q**2", "1/0", "sqrt(-q)", "min(q)", "2^3^q", "ln(q-q)",
            &long,
        ]
        .iter()
        .map(|&s| s.into())
        .chain([Value::Number(f64::NAN), Value::Number(f64::INFINITY)])
        .collect();
        for value in &values {
            let want = compile_const(value, &p, "a[1]").unwrap_err();
            let got = compile_const_with_derivatives(value, &p, &["q", "r"], "a[1]").unwrap_err();
            assert_eq!(got, want, "{value:?}");
        }
        let unknown = compile_const_with_derivatives(&"mass*q".into(), &p, &["q"], "a[1]");
        assert!(
            unknown
                .unwrap_err()
                .message
                .contains("unknown parameter \"mass\""),
            "the message is compile_const's own"
        );
    }
}
