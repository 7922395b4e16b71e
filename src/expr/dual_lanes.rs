//! [`DUAL_LANES`] dual numbers through one evaluation: the nonlinear bank's filters
//! each need f and ∂f/∂x at their own state, and exmex's node-by-node bookkeeping
//! costs several times the arithmetic of a short expression (`-b*abs(x2)*x2/abs(x1)`),
//! so an expression parsed over [`DualBlock`] pays it once per DUAL_LANES filters —
//! as `block::Block` does for time points.
//!
//! [`DualBlockOps`] is `dual::dual_operators!`'s table lifted lane-wise, so every lane
//! equals the [`Dual`] evaluation bit for bit (tested below).

use super::dual::{
    Dual, Grad, add, atan2, chain, chosen, div, dual_operators, flat, inv_sqrt, mul, neg, pow,
    sign, sub,
};
use exmex::{BinOp, MakeOperators, Operator};
use std::str::FromStr;

/// How many dual numbers a [`DualBlock`] carries: the procedure's default bank of six
/// filters is one evaluation.
pub const DUAL_LANES: usize = 8;

/// DUAL_LANES dual numbers of one expression node.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DualBlock(pub [Dual; DUAL_LANES]);

impl FromStr for DualBlock {
    type Err = std::num::ParseFloatError;
    /// A literal: [`Dual`]'s parse, in every lane.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Dual::from_str(s).map(|x| DualBlock([x; DUAL_LANES]))
    }
}

impl DualBlock {
    #[inline(always)]
    fn map(self, f: impl Fn(Dual) -> Dual) -> DualBlock {
        DualBlock(self.0.map(f))
    }
    #[inline(always)]
    fn zip(self, o: DualBlock, f: impl Fn(Dual, Dual) -> Dual) -> DualBlock {
        DualBlock(std::array::from_fn(|l| f(self.0[l], o.0[l])))
    }
}

macro_rules! lane_un {
    ($f:expr) => {
        |a: DualBlock| a.map($f)
    };
}

macro_rules! lane_bin {
    ($f:expr) => {
        |a: DualBlock, b: DualBlock| a.zip(b, $f)
    };
}

macro_rules! lane_k {
    ($x:expr) => {
        DualBlock(
            [Dual {
                v: $x,
                d: Grad::ZERO,
            }; DUAL_LANES],
        )
    };
}

/// The operators on dual numbers, lane-wise.
#[derive(Clone, Debug)]
pub struct DualBlockOps;

impl MakeOperators<DualBlock> for DualBlockOps {
    fn make<'a>() -> Vec<Operator<'a, DualBlock>> {
        dual_operators!(lane_un, lane_bin, lane_k)
    }
}

/// An expression parsed over blocks of dual numbers.
pub type DualBlockEx = exmex::FlatEx<DualBlock, DualBlockOps>;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::expr::dual::{DIRECTIONS, DualEx, DualOps};
    use exmex::prelude::*;

    #[test]
    fn the_table_is_the_dual_table() {
        let lanes = <DualBlockOps as MakeOperators<DualBlock>>::make();
        let dual = <DualOps as MakeOperators<Dual>>::make();
        assert_eq!(lanes.len(), dual.len());
        for (l, d) in lanes.iter().zip(&dual) {
            let name = d.repr();
            assert_eq!(l.repr(), name);
            assert_eq!(l.has_bin(), d.has_bin(), "{name}");
            assert_eq!(l.has_unary(), d.has_unary(), "{name}");
            if let (Ok(lb), Ok(db)) = (l.bin(), d.bin()) {
                assert_eq!(lb.prio, db.prio, "{name}");
                assert_eq!(lb.is_commutative, db.is_commutative, "{name}");
            }
            match (l.constant(), d.constant()) {
                (Some(lc), Some(dc)) => assert!(lc.0.iter().all(|x| *x == dc), "{name}"),
                (None, None) => {}
                _ => panic!("{name}: a constant in one table only"),
            }
        }
    }

    /// Every operator of the language, each lane at its own point and directions,
    /// equals the one-point dual evaluation bit for bit.
    #[test]
    fn every_lane_is_the_dual_evaluation() {
        let texts = [
            "a^b + a*b - a/b",
            "atan2(a, b) + min(a, b) * max(a, b)",
            "abs(a) + signum(b) + sin(a) * cos(b) + tan(a)",
            "asin(a/4) + acos(b/4) + atan(a) + sinh(a) + cosh(b) + tanh(a)",
            "asinh(a) + acosh(b + 3) + atanh(a/4)",
            "floor(a) + round(b) + ceil(a) + trunc(b) + fract(a)",
            "exp(a) + sqrt(b + 2) + cbrt(a) + ln(b + 2) + log2(b + 2) + log10(b + 2) + log(b + 2)",
            "-a + +b + PI*E - TAU",
        ];
        for text in texts {
            let dual = DualEx::parse(text).unwrap();
            let lanes = DualBlockEx::parse(text).unwrap();
            assert_eq!(dual.var_names(), lanes.var_names(), "{text}");
            let point = |l: usize, var: usize| {
                let v = 0.37 * l as f64 - 1.2 + 0.5 * var as f64;
                let mut d = Grad::ZERO;
                d.0[(l + var) % DIRECTIONS] = 1.0 + var as f64;
                Dual { v, d }
            };
            let vars: Vec<DualBlock> = (0..dual.var_names().len())
                .map(|var| DualBlock(std::array::from_fn(|l| point(l, var))))
                .collect();
            let out = lanes.eval(&vars).unwrap();
            for l in 0..DUAL_LANES {
                let one: Vec<Dual> = (0..vars.len()).map(|var| point(l, var)).collect();
                let want = dual.eval(&one).unwrap();
                assert_eq!(out.0[l].v.to_bits(), want.v.to_bits(), "{text}, lane {l}");
                for k in 0..DIRECTIONS {
                    assert_eq!(
                        out.0[l].d[k].to_bits(),
                        want.d[k].to_bits(),
                        "{text}, lane {l}, direction {k}"
                    );
                }
            }
        }
    }
}
