//! Expressions evaluated at [`LANES`] time points at once.
//!
//! exmex interprets a parsed expression node by node; for the short expressions of
//! a model (`"-0.5 + 0.2*sin(t + 3)"`) that bookkeeping costs several times the
//! arithmetic. exmex is generic over its number type, so an expression parsed over
//! [`Block`] — LANES values — pays it once per LANES time points.
//!
//! [`BlockOps`] mirrors exmex's `FloatOpsFactory` operator for operator (the same
//! names, priorities, commutativity and constants) and applies the same `f64`
//! function to each lane, so every lane equals the scalar evaluation bit for bit
//! (tested below against `FlatEx<f64>`).

use exmex::{BinOp, MakeOperators, Operator};
use std::str::FromStr;

/// Time points per evaluation.
pub const LANES: usize = 16;

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

/// exmex's float operators, lane-wise.
#[derive(Clone, Debug)]
pub struct BlockOps;

macro_rules! unary {
    ($name:literal, $f:path) => {
        Operator::make_unary($name, |a: Block| a.map($f))
    };
}

macro_rules! binary {
    ($name:literal, $prio:literal, $comm:literal, $f:expr) => {
        Operator::make_bin(
            $name,
            BinOp {
                apply: |a: Block, b: Block| a.zip(b, $f),
                prio: $prio,
                is_commutative: $comm,
            },
        )
    };
}

impl MakeOperators<Block> for BlockOps {
    fn make<'a>() -> Vec<Operator<'a, Block>> {
        use std::f64::consts::{E, PI, TAU};
        vec![
            binary!("^", 4, false, f64::powf),
            binary!("*", 2, true, |a, b| a * b),
            binary!("/", 3, false, |a, b| a / b),
            Operator::make_bin_unary(
                "+",
                BinOp {
                    apply: |a: Block, b: Block| a.zip(b, |a, b| a + b),
                    prio: 0,
                    is_commutative: true,
                },
                |a| a,
            ),
            Operator::make_bin_unary(
                "-",
                BinOp {
                    apply: |a: Block, b: Block| a.zip(b, |a, b| a - b),
                    prio: 1,
                    is_commutative: false,
                },
                |a: Block| a.map(|x| -x),
            ),
            binary!("atan2", 0, false, f64::atan2),
            binary!("min", 0, false, f64::min),
            binary!("max", 0, false, f64::max),
            unary!("abs", f64::abs),
            unary!("signum", f64::signum),
            unary!("sin", f64::sin),
            unary!("cos", f64::cos),
            unary!("tan", f64::tan),
            unary!("asin", f64::asin),
            unary!("acos", f64::acos),
            unary!("atan", f64::atan),
            unary!("sinh", f64::sinh),
            unary!("cosh", f64::cosh),
            unary!("tanh", f64::tanh),
            unary!("asinh", f64::asinh),
            unary!("acosh", f64::acosh),
            unary!("atanh", f64::atanh),
            unary!("floor", f64::floor),
            unary!("round", f64::round),
            unary!("ceil", f64::ceil),
            unary!("trunc", f64::trunc),
            unary!("fract", f64::fract),
            unary!("exp", f64::exp),
            unary!("sqrt", f64::sqrt),
            unary!("cbrt", f64::cbrt),
            unary!("ln", f64::ln),
            unary!("log2", f64::log2),
            unary!("log10", f64::log10),
            unary!("log", f64::ln),
            Operator::make_constant("PI", Block([PI; LANES])),
            Operator::make_constant("π", Block([PI; LANES])),
            Operator::make_constant("E", Block([E; LANES])),
            Operator::make_constant("e", Block([E; LANES])),
            Operator::make_constant("TAU", Block([TAU; LANES])),
            Operator::make_constant("τ", Block([TAU; LANES])),
        ]
    }
}

/// An expression parsed over blocks.
pub type BlockEx = exmex::FlatEx<Block, BlockOps>;

#[cfg(test)]
mod tests {
    use super::*;
    use exmex::prelude::*;

    /// Every operator and constant, lane by lane, gives the scalar evaluation's bits
    /// (and the same operator names are known to both: a parse succeeds in both or
    /// fails in both).
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
            let scalar = FlatEx::<f64>::parse(text).unwrap();
            let block = BlockEx::parse(text).unwrap();
            assert_eq!(scalar.var_names(), block.var_names(), "{text}");
            let ts: [f64; LANES] = std::array::from_fn(|l| -1.3 + 0.61 * l as f64);
            let got = block.eval(&[Block(ts)]).unwrap();
            for (l, &t) in ts.iter().enumerate() {
                let want = scalar.eval(&[t]).unwrap();
                assert_eq!(got.0[l].to_bits(), want.to_bits(), "{text} at t = {t}");
            }
        }
        for bad in ["t**2", "sin(t", "foo(t)"] {
            assert_eq!(
                FlatEx::<f64>::parse(bad).is_ok(),
                BlockEx::parse(bad).is_ok(),
                "{bad}"
            );
        }
    }
}
