//! Expressions evaluated at [`LANES`] time points at once.
//!
//! exmex interprets a parsed expression node by node; for the short expressions of
//! a model (`"-0.5 + 0.2*sin(t + 3)"`) that bookkeeping costs several times the
//! arithmetic. exmex is generic over its number type, so an expression parsed over
//! [`Block`] — LANES values — pays it once per LANES time points.
//!
//! [`BlockOps`] and [`ScalarOps`] are one operator table (exmex's `FloatOpsFactory`'s
//! names, priorities, commutativity and constants, with the `libm` crate's functions:
//! see `operators!`), lane-wise and on one value, so every lane equals the scalar
//! evaluation bit for bit (tested below), natively and in wasm alike.

use exmex::{BinOp, MakeOperators, Operator};
use std::str::FromStr;

pub use super::LANES;

/// LANES values of one expression node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Block(pub [f64; LANES]);

impl Default for Block {
    fn default() -> Self {
        Block([0.0; LANES])
    }
}

impl FromStr for Block {
    type Err = std::num::ParseFloatError;
    /// A literal: the same parse as exmex's `f64`, in every lane.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        f64::from_str(s).map(|x| Block([x; LANES]))
    }
}

impl Block {
    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> Block {
        Block(self.0.map(f))
    }
    #[inline(always)]
    fn zip(self, o: Block, f: impl Fn(f64, f64) -> f64) -> Block {
        Block(std::array::from_fn(|l| f(self.0[l], o.0[l])))
    }
}

/// The expression language's operators for a value type, as exmex's `FloatOpsFactory`
/// has them (the same names, priorities, commutativity and constants), with every
/// function that is not exact IEEE arithmetic taken from the `libm` crate. `$un!(f)`
/// and `$bin!(f)` lift an `f64` function to the type, `$k!(x)` a constant; `$sin` and
/// `$cos` are the type's sin and cos.
///
/// Why `libm`: the standard library's `sin`, `ln`, `powf`… call the platform's C
/// library natively and a port of musl's in wasm, and the two differ in the last bit
/// for some arguments (sin, cos and ln were seen to), so a model with them gave the
/// browser other bits than the server. One implementation on every target gives one
/// answer. (abs, signum, floor, round, ceil, trunc, fract and sqrt are exact everywhere.)
macro_rules! operators {
    ($T:ty, $un:ident, $bin:ident, $k:ident, $sin:expr, $cos:expr) => {{
        use std::f64::consts::{E, PI, TAU};
        vec![
            Operator::make_bin(
                "^",
                BinOp {
                    apply: $bin!(libm::pow),
                    prio: 4,
                    is_commutative: false,
                },
            ),
            Operator::make_bin(
                "*",
                BinOp {
                    apply: $bin!(|a: f64, b: f64| a * b),
                    prio: 2,
                    is_commutative: true,
                },
            ),
            Operator::make_bin(
                "/",
                BinOp {
                    apply: $bin!(|a: f64, b: f64| a / b),
                    prio: 3,
                    is_commutative: false,
                },
            ),
            Operator::make_bin_unary(
                "+",
                BinOp {
                    apply: $bin!(|a: f64, b: f64| a + b),
                    prio: 0,
                    is_commutative: true,
                },
                $un!(|a: f64| a),
            ),
            Operator::make_bin_unary(
                "-",
                BinOp {
                    apply: $bin!(|a: f64, b: f64| a - b),
                    prio: 1,
                    is_commutative: false,
                },
                $un!(|a: f64| -a),
            ),
            Operator::make_bin(
                "atan2",
                BinOp {
                    apply: $bin!(libm::atan2),
                    prio: 0,
                    is_commutative: false,
                },
            ),
            Operator::make_bin(
                "min",
                BinOp {
                    apply: $bin!(libm::fmin),
                    prio: 0,
                    is_commutative: false,
                },
            ),
            Operator::make_bin(
                "max",
                BinOp {
                    apply: $bin!(libm::fmax),
                    prio: 0,
                    is_commutative: false,
                },
            ),
            Operator::make_unary("abs", $un!(f64::abs)),
            // The sign function of mathematics (numpy, MATLAB, Julia): 0 at ±0, where
            // Rust's f64::signum gives ±1; NaN stays NaN.
            Operator::make_unary(
                "signum",
                $un!(|a: f64| if a == 0.0 { a } else { a.signum() }),
            ),
            Operator::make_unary("sin", $sin),
            Operator::make_unary("cos", $cos),
            Operator::make_unary("tan", $un!(libm::tan)),
            Operator::make_unary("asin", $un!(libm::asin)),
            Operator::make_unary("acos", $un!(libm::acos)),
            Operator::make_unary("atan", $un!(libm::atan)),
            Operator::make_unary("sinh", $un!(libm::sinh)),
            Operator::make_unary("cosh", $un!(libm::cosh)),
            Operator::make_unary("tanh", $un!(libm::tanh)),
            Operator::make_unary("asinh", $un!(libm::asinh)),
            Operator::make_unary("acosh", $un!(libm::acosh)),
            Operator::make_unary("atanh", $un!(libm::atanh)),
            Operator::make_unary("floor", $un!(f64::floor)),
            Operator::make_unary("round", $un!(f64::round)),
            Operator::make_unary("ceil", $un!(f64::ceil)),
            Operator::make_unary("trunc", $un!(f64::trunc)),
            Operator::make_unary("fract", $un!(f64::fract)),
            Operator::make_unary("exp", $un!(libm::exp)),
            Operator::make_unary("sqrt", $un!(f64::sqrt)),
            Operator::make_unary("cbrt", $un!(libm::cbrt)),
            Operator::make_unary("ln", $un!(libm::log)),
            Operator::make_unary("log2", $un!(libm::log2)),
            Operator::make_unary("log10", $un!(libm::log10)),
            Operator::make_unary("log", $un!(libm::log)),
            Operator::make_constant("PI", $k!(PI)),
            Operator::make_constant("π", $k!(PI)),
            Operator::make_constant("E", $k!(E)),
            Operator::make_constant("e", $k!(E)),
            Operator::make_constant("TAU", $k!(TAU)),
            Operator::make_constant("τ", $k!(TAU)),
        ] as Vec<Operator<'_, $T>>
    }};
}

macro_rules! block_un {
    ($f:expr) => {
        |a: Block| a.map($f)
    };
}
macro_rules! block_bin {
    ($f:expr) => {
        |a: Block, b: Block| a.zip(b, $f)
    };
}
macro_rules! block_k {
    ($x:expr) => {
        Block([$x; LANES])
    };
}
macro_rules! scalar_fn {
    ($f:expr) => {
        $f
    };
}

/// The operators lane-wise: every lane equals the scalar [`ScalarOps`] evaluation.
#[derive(Clone, Debug)]
pub struct BlockOps;

impl MakeOperators<Block> for BlockOps {
    fn make<'a>() -> Vec<Operator<'a, Block>> {
        // sin and cos: all lanes at once, as libm's bits (`trig`)
        let sin = |a: Block| Block(crate::expr::trig::sin_lanes(a.0));
        let cos = |a: Block| Block(crate::expr::trig::cos_lanes(a.0));
        operators!(Block, block_un, block_bin, block_k, sin, cos)
    }
}

/// The operators on one `f64` (constant entries, and the scalar evaluation).
#[derive(Clone, Debug)]
pub struct ScalarOps;

impl MakeOperators<f64> for ScalarOps {
    fn make<'a>() -> Vec<Operator<'a, f64>> {
        operators!(f64, scalar_fn, scalar_fn, scalar_fn, libm::sin, libm::cos)
    }
}

/// An expression parsed over single values.
pub type ScalarEx = exmex::FlatEx<f64, ScalarOps>;

/// An expression parsed over blocks.
pub type BlockEx = exmex::FlatEx<Block, BlockOps>;

#[cfg(test)]
mod tests {
    use super::*;
    use exmex::prelude::*;

    /// Every operator and constant, lane by lane, gives the scalar evaluation's bits
    /// (and the same operator names are known to both, and to exmex's own float
    /// operators: a parse succeeds in all or fails in all).
    #[test]
    fn lanes_equal_the_scalar_evaluation_bitwise() {
        let names = [
            "abs", "signum", "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh",
            "asinh", "acosh", "atanh", "floor", "round", "ceil", "trunc", "fract", "exp", "sqrt",
            "cbrt", "ln", "log2", "log10", "log",
        ];
        let mut texts: Vec<String> = names.iter().map(|f| format!("{f}(0.37*t - 0.2)")).collect();
        texts.extend(
            [
                "-0.5 - 0.1*3 + 0.2*sin(t + 3)",
                "t^2.5 / (1 + t) - -t",
                "2^-t*PI + π*E - e/TAU + τ",
                "atan2(t, 0.3) + min(t, 0.5)*max(t, 2) + (1 + t)^(1/3)",
                "-t^2 + 3*-2^t",
                "0.3*sin(2*t)*exp(-t/7)/cosh(t)",
            ]
            .map(String::from),
        );
        for text in &texts {
            let scalar = ScalarEx::parse(text).unwrap();
            let block = BlockEx::parse(text).unwrap();
            // exmex's own float operators: the same language (names, priorities), and
            // values within rounding of the C library's functions.
            let std_ops = FlatEx::<f64>::parse(text).unwrap();
            assert_eq!(scalar.var_names(), block.var_names(), "{text}");
            assert_eq!(scalar.var_names(), std_ops.var_names(), "{text}");
            let ts: [f64; LANES] = std::array::from_fn(|l| -1.3 + 0.61 * l as f64);
            let got = block.eval(&[Block(ts)]).unwrap();
            for (l, &t) in ts.iter().enumerate() {
                let want = scalar.eval(&[t]).unwrap();
                assert_eq!(got.0[l].to_bits(), want.to_bits(), "{text} at t = {t}");
                let other = std_ops.eval(&[t]).unwrap();
                assert!(
                    want.to_bits() == other.to_bits()
                        || (want.is_nan() && other.is_nan())
                        || (want - other).abs() <= 1e-14 * want.abs().max(other.abs()),
                    "{text} at t = {t}: {want} against {other}"
                );
            }
        }
        for bad in ["t**2", "sin(t", "foo(t)"] {
            assert_eq!(
                ScalarEx::parse(bad).is_ok(),
                BlockEx::parse(bad).is_ok(),
                "{bad}"
            );
            assert_eq!(
                FlatEx::<f64>::parse(bad).is_ok(),
                ScalarEx::parse(bad).is_ok(),
                "{bad}"
            );
        }
    }
}
