//! kea's own evaluator of an expression over [`DUAL_LANES`] dual numbers: the text is
//! parsed once into a register tape (the language's grammar, as `translate` gives it
//! to exmex: expr = term {(+|−) term}, term = unary {(*|/) unary}, unary = (+|−) unary
//! | power, power = atom [^ unary], atom = number | name | f(expr) | g(expr, expr) |
//! (expr)), and each instruction runs lane by lane, in place, on preallocated
//! registers. exmex evaluates by value: a block of 8 × 3 numbers is copied in and out
//! of its value stack at every node, a quarter of the nonlinear bank's time.
//!
//! The arithmetic is the operator table's own functions (`dual::{add, sub, mul, div,
//! neg}`), the other functions its entries (`DualOps`), applied in the grammar's order:
//! every lane equals exmex's evaluation bit for bit (tested below on random texts).

use super::dual::{Dual, DualOps, add, div, mul, neg, sub};
use super::dual_lanes::{DUAL_LANES, DualBlock};
use super::language;
use super::lex::{Tok, Token, lex};
use exmex::MakeOperators;

/// Where an instruction reads a value: a variable (the caller's slice, in the order
/// of the names given to [`DualTape::compile`]), a constant, or a register.
#[derive(Clone, Copy, Debug)]
enum Operand {
    Var(usize),
    Const(usize),
    Reg(usize),
}

/// The table's functions of one and two dual numbers.
type Fn1 = fn(Dual) -> Dual;
type Fn2 = fn(Dual, Dual) -> Dual;

#[derive(Clone, Copy, Debug)]
enum Op2 {
    Add,
    Sub,
    Mul,
    Div,
    /// `^`, atan2, min, max: the table's function.
    Table(Fn2),
}

#[derive(Clone, Copy, Debug)]
enum Op1 {
    Neg,
    Table(Fn1),
}

#[derive(Clone, Copy, Debug)]
enum Instr {
    Binary(Op2, Operand, Operand, usize),
    Unary(Op1, Operand, usize),
}

/// A compiled expression over blocks of dual numbers.
#[derive(Clone, Debug)]
pub struct DualTape {
    code: Vec<Instr>,
    consts: Vec<DualBlock>,
    registers: usize,
    result: Operand,
}

impl DualTape {
    /// The tape of `text` (a text `translate` accepted), its names read as the
    /// variables `vars` (by position); None for a text outside the grammar or a name
    /// that is neither a variable nor the language's, which the caller then
    /// evaluates with exmex.
    pub fn compile(text: &str, vars: &[String]) -> Option<DualTape> {
        let tokens = lex(text).ok()?;
        let table = <DualOps as MakeOperators<Dual>>::make();
        let mut p = Parser {
            text,
            tokens: &tokens,
            i: 0,
            vars,
            tape: DualTape {
                code: Vec::new(),
                consts: Vec::new(),
                registers: 0,
                result: Operand::Const(0),
            },
            unary: table
                .iter()
                .filter_map(|op| Some((op.repr(), op.unary().ok()?)))
                .collect(),
            binary: table
                .iter()
                .filter_map(|op| Some((op.repr(), op.bin().ok()?.apply)))
                .collect(),
        };
        let result = p.expr()?;
        if p.i != tokens.len() {
            return None;
        }
        p.tape.result = result;
        Some(p.tape)
    }

    /// The registers [`DualTape::eval`] needs.
    pub fn registers(&self) -> usize {
        self.registers
    }

    /// The value at `vars` (`registers`: at least [`DualTape::registers`], reused).
    #[inline]
    pub fn eval(&self, vars: &[DualBlock], registers: &mut [DualBlock]) -> DualBlock {
        for ins in &self.code {
            match *ins {
                Instr::Binary(op, a, b, out) => {
                    let (x, y) = (self.read(a, vars, registers), self.read(b, vars, registers));
                    let z = match op {
                        Op2::Add => lanes2(x, y, add),
                        Op2::Sub => lanes2(x, y, sub),
                        Op2::Mul => lanes2(x, y, mul),
                        Op2::Div => lanes2(x, y, div),
                        Op2::Table(f) => lanes2(x, y, f),
                    };
                    registers[out] = z;
                }
                Instr::Unary(op, a, out) => {
                    let x = self.read(a, vars, registers);
                    let z = match op {
                        Op1::Neg => DualBlock(x.0.map(neg)),
                        Op1::Table(f) => DualBlock(x.0.map(f)),
                    };
                    registers[out] = z;
                }
            }
        }
        *self.read(self.result, vars, registers)
    }

    #[inline(always)]
    fn read<'a>(
        &'a self,
        at: Operand,
        vars: &'a [DualBlock],
        registers: &'a [DualBlock],
    ) -> &'a DualBlock {
        match at {
            Operand::Var(k) => &vars[k],
            Operand::Const(k) => &self.consts[k],
            Operand::Reg(k) => &registers[k],
        }
    }
}

#[inline(always)]
fn lanes2(x: &DualBlock, y: &DualBlock, f: impl Fn(Dual, Dual) -> Dual) -> DualBlock {
    DualBlock(std::array::from_fn(|l| f(x.0[l], y.0[l])))
}

/// Recursive descent over the tokens, emitting instructions in evaluation order.
struct Parser<'a> {
    text: &'a str,
    tokens: &'a [Token],
    i: usize,
    vars: &'a [String],
    tape: DualTape,
    unary: Vec<(&'static str, Fn1)>,
    binary: Vec<(&'static str, Fn2)>,
}

impl Parser<'_> {
    fn peek(&self) -> Option<Tok> {
        self.tokens.get(self.i).map(|t| t.tok)
    }

    fn take(&mut self, tok: Tok) -> bool {
        let found = self.peek() == Some(tok);
        self.i += usize::from(found);
        found
    }

    fn register(&mut self) -> usize {
        self.tape.registers += 1;
        self.tape.registers - 1
    }

    fn constant(&mut self, v: f64) -> Operand {
        let block = DualBlock(
            [Dual {
                v,
                ..Dual::default()
            }; DUAL_LANES],
        );
        self.tape.consts.push(block);
        Operand::Const(self.tape.consts.len() - 1)
    }

    fn binary(&mut self, op: Op2, a: Operand, b: Operand) -> Operand {
        let out = self.register();
        self.tape.code.push(Instr::Binary(op, a, b, out));
        Operand::Reg(out)
    }

    fn unary_op(&mut self, op: Op1, a: Operand) -> Operand {
        let out = self.register();
        self.tape.code.push(Instr::Unary(op, a, out));
        Operand::Reg(out)
    }

    fn expr(&mut self) -> Option<Operand> {
        let mut x = self.term()?;
        loop {
            if self.take(Tok::Op('+')) {
                let y = self.term()?;
                x = self.binary(Op2::Add, x, y);
            } else if self.take(Tok::Op('-')) {
                let y = self.term()?;
                x = self.binary(Op2::Sub, x, y);
            } else {
                return Some(x);
            }
        }
    }

    fn term(&mut self) -> Option<Operand> {
        let mut x = self.unary()?;
        loop {
            if self.take(Tok::Op('*')) {
                let y = self.unary()?;
                x = self.binary(Op2::Mul, x, y);
            } else if self.take(Tok::Op('/')) {
                let y = self.unary()?;
                x = self.binary(Op2::Div, x, y);
            } else {
                return Some(x);
            }
        }
    }

    fn unary(&mut self) -> Option<Operand> {
        if self.take(Tok::Op('-')) {
            let x = self.unary()?;
            Some(self.unary_op(Op1::Neg, x))
        } else if self.take(Tok::Op('+')) {
            self.unary()
        } else {
            let x = self.atom()?;
            if self.take(Tok::Op('^')) {
                let y = self.unary()?;
                let pow = self.table2("^")?;
                Some(self.binary(Op2::Table(pow), x, y))
            } else {
                Some(x)
            }
        }
    }

    fn table2(&self, name: &str) -> Option<Fn2> {
        self.binary.iter().find(|(n, _)| *n == name).map(|e| e.1)
    }

    fn atom(&mut self) -> Option<Operand> {
        let token = *self.tokens.get(self.i)?;
        self.i += 1;
        match token.tok {
            Tok::Num(v) => Some(self.constant(v)),
            Tok::Open => {
                let x = self.expr()?;
                self.take(Tok::Close).then_some(x)
            }
            Tok::Name => {
                let name = &self.text[token.start..token.end];
                if self.take(Tok::Open) {
                    let a = self.expr()?;
                    let out = if self.take(Tok::Comma) {
                        let b = self.expr()?;
                        let f = self.table2(name)?;
                        self.binary(Op2::Table(f), a, b)
                    } else {
                        let f = self.unary.iter().find(|(n, _)| *n == name)?.1;
                        self.unary_op(Op1::Table(f), a)
                    };
                    return self.take(Tok::Close).then_some(out);
                }
                if let Some(k) = self.vars.iter().position(|v| v == name) {
                    return Some(Operand::Var(k));
                }
                let v = language().constant(name)?;
                Some(self.constant(v))
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::dual_lanes::DualBlockEx;
    use super::super::translate::translate;
    use super::*;
    use exmex::Express;
    use std::collections::BTreeMap;

    /// A small deterministic generator (xorshift).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
        fn below(&mut self, k: usize) -> usize {
            (self.next() % k as u64) as usize
        }
        fn unit(&mut self) -> f64 {
            (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn random_text(rng: &mut Rng, depth: usize) -> String {
        let sub = |rng: &mut Rng| random_text(rng, depth.saturating_sub(1));
        let operand = |x: String| {
            if x.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'.') {
                x
            } else {
                format!("({x})")
            }
        };
        match if depth == 0 {
            rng.below(5)
        } else {
            rng.below(15)
        } {
            0 => ["1", "2.5", "3", "0.5", "1e2"][rng.below(5)].to_string(),
            1 => "x1".into(),
            2 => "x2".into(),
            3 => ["b", "t"][rng.below(2)].into(),
            4 => ["PI", "e"][rng.below(2)].into(),
            5 => format!("({})", sub(rng)),
            6..=9 => {
                let (a, b) = (sub(rng), sub(rng));
                format!("{a}{}{b}", ["+", "-", "*", "/"][rng.below(4)])
            }
            10 => format!("{}{}", ["-", "+", "--", "-+-"][rng.below(4)], sub(rng)),
            11 => {
                let (a, b) = (sub(rng), sub(rng));
                format!("{}^{}{}", operand(a), ["", "-"][rng.below(2)], operand(b))
            }
            12 | 13 => {
                let f = ["sin", "sqrt", "abs", "exp", "ln", "signum", "tanh"][rng.below(7)];
                format!("{f}({})", sub(rng))
            }
            _ => {
                let (a, b) = (sub(rng), sub(rng));
                format!("{}({a},{b})", ["min", "max", "atan2"][rng.below(3)])
            }
        }
    }

    /// The same bits, or both NaN.
    fn same(a: f64, b: f64) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    /// Random texts in the states, a param, t and the constants: the tape's value and
    /// gradient in every lane equal exmex's evaluation of `translate`'s text, bit for
    /// bit, at random states with both directions set.
    #[test]
    fn random_texts_equal_exmex_bit_for_bit() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let params = BTreeMap::from([
            ("b".to_string(), 1.7),
            ("x1".to_string(), 0.0),
            ("x2".to_string(), 0.0),
        ]);
        let mut compared = 0;
        for _ in 0..3000 {
            let text = random_text(&mut rng, 4);
            let Ok((plain, literals)) = translate(&text, &params, "f", true) else {
                continue;
            };
            let ex = DualBlockEx::parse(&plain).expect("exmex reads translate's text");
            let names: Vec<String> = ex.var_names().to_vec();
            let tape_vars: Vec<String> = ["x1", "x2", "b", "t"].map(String::from).to_vec();
            let tape = DualTape::compile(&text, &tape_vars).expect(&text);
            let mut registers = vec![DualBlock::default(); tape.registers()];
            for _ in 0..3 {
                let lane = |rng: &mut Rng, scale: f64| -> [f64; DUAL_LANES] {
                    std::array::from_fn(|_| scale * (2.0 * rng.unit() - 1.0))
                };
                let (x1, x2, t) = (lane(&mut rng, 3.0), lane(&mut rng, 3.0), rng.unit());
                let dual = |v: &[f64; DUAL_LANES], k: Option<usize>| {
                    DualBlock(std::array::from_fn(|l| Dual {
                        v: v[l],
                        d: k.map_or(Default::default(), super::super::dual::Grad::unit),
                    }))
                };
                let flat = |v: f64| dual(&[v; DUAL_LANES], None);
                let value = |name: &str| -> DualBlock {
                    match name {
                        "x1" => dual(&x1, Some(0)),
                        "x2" => dual(&x2, Some(1)),
                        "b" => flat(1.7),
                        "t" => flat(t),
                        _ => {
                            let k: usize = name.strip_prefix('#').unwrap().parse().unwrap();
                            flat(literals[k])
                        }
                    }
                };
                let ex_vars: Vec<DualBlock> = names.iter().map(|n| value(n)).collect();
                let tape_values: Vec<DualBlock> = tape_vars.iter().map(|n| value(n)).collect();
                let want = ex.eval(&ex_vars).unwrap();
                let got = tape.eval(&tape_values, &mut registers);
                for l in 0..DUAL_LANES {
                    let (g, w) = (got.0[l], want.0[l]);
                    assert!(
                        same(g.v, w.v) && same(g.d.0[0], w.d.0[0]) && same(g.d.0[1], w.d.0[1]),
                        "{text} lane {l}: {g:?} against {w:?}"
                    );
                }
                compared += 1;
            }
        }
        assert!(compared > 5000, "{compared}");
    }
}
