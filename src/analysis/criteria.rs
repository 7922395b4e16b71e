//! The criteria: their running sums during a run (3.24), the averaged (3.24) and
//! weighted (3.25) criteria of a set made from them, and λ = Φ⁻¹((1+P)/2) (3.14) with
//! the bisection that gives it the same bits on every target.

use crate::analysis::result::{CriteriaSet, ExcludedSteps, StateCriteria, Weighted, WeightsOut};
use crate::model::compile::CompiledModel;
use std::collections::BTreeMap;

/// Running sums of one criterion of one state (3.24).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Avg {
    pub(crate) sum: f64,
    pub(crate) count: u64,
    pub(crate) excluded: u64,
}

impl Avg {
    #[inline(always)]
    pub(crate) fn add(&mut self, num: f64, den: f64) {
        let f = num / den;
        if den > 0.0 && f.is_finite() {
            self.sum += f;
            self.count += 1;
        } else {
            self.excluded += 1;
        }
    }
    pub(crate) fn mean(&self) -> Option<f64> {
        (self.count > 0).then(|| self.sum / self.count as f64)
    }
}

/// Accumulated criteria of one set (bound or covariance): ratios η/ζ, ζ/χ, η/χ per
/// state; the constant factors z_B/y_B are applied at the end (y_B is a sup over k).
#[derive(Clone, Debug)]
pub(crate) struct SetSums {
    pub(crate) yz: Vec<Avg>,
    pub(crate) zx: Vec<Avg>,
    pub(crate) yx: Vec<Avg>,
}

/// The running sums (3.24) of the six criteria of every state during a run, as
/// parallel arrays indexed [criterion · n + state] (criteria in the order of the
/// `C_*` constants) so that a step's update is one vectorisable loop.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub(super) struct Running {
    #[serde(with = "crate::resume::f64s")]
    pub(super) sum: Vec<f64>,
    pub(super) count: Vec<u64>,
    pub(super) excluded: Vec<u64>,
}

pub(super) const C_BOUND_YZ: usize = 0;
pub(super) const C_BOUND_ZX: usize = 1;
pub(super) const C_BOUND_YX: usize = 2;
pub(super) const C_COV_YZ: usize = 3;
pub(super) const C_COV_ZX: usize = 4;
pub(super) const C_COV_YX: usize = 5;

impl Running {
    pub(super) fn new(n: usize) -> Self {
        Running {
            sum: vec![0.0; 6 * n],
            count: vec![0; 6 * n],
            excluded: vec![0; 6 * n],
        }
    }

    /// One step: `ratio` holds the six criteria's ratios (laid out as the sums); for
    /// every entry where `part` is 1, a finite ratio counts and any other (NaN where
    /// its denominator is not positive) is an excluded step.
    #[inline(always)]
    pub(super) fn add(&mut self, ratio: &[f64], part: &[u64]) {
        let len = self.sum.len();
        let (sum, count, excluded) = (
            &mut self.sum[..],
            &mut self.count[..len],
            &mut self.excluded[..len],
        );
        let (ratio, part) = (&ratio[..len], &part[..len]);
        for x in 0..len {
            let f = ratio[x];
            let take = part[x] & u64::from(f.is_finite());
            // + 0.0 leaves a sum alone (a sum of +0.0 and ratios is never −0.0).
            sum[x] += if take != 0 { f } else { 0.0 };
            count[x] += take;
            excluded[x] += part[x] - take;
        }
    }

    /// The bound and the covariance set.
    pub(super) fn into_sets(self, n: usize) -> (SetSums, SetSums) {
        let avg = |c: usize| -> Vec<Avg> {
            (c * n..c * n + n)
                .map(|x| Avg {
                    sum: self.sum[x],
                    count: self.count[x],
                    excluded: self.excluded[x],
                })
                .collect()
        };
        (
            SetSums {
                yz: avg(C_BOUND_YZ),
                zx: avg(C_BOUND_ZX),
                yx: avg(C_BOUND_YX),
            },
            SetSums {
                yz: avg(C_COV_YZ),
                zx: avg(C_COV_ZX),
                yx: avg(C_COV_YX),
            },
        )
    }
}

/// λ = Φ⁻¹((1+P)/2), the two-sided normal quantile (3.14): the root of
/// erfc(λ/√2) = 1 − P (or, for P < 1/2, of erf(λ/√2) = P), bisected on `libm`'s erfc
/// (erf) down to adjacent floats. A quantile built on the standard library's exp and
/// ln (statrs') differs in its last bits between the native C library and wasm
/// (P = 0.99 did); this one is the same arithmetic on every target. `p` in (0, 1).
pub fn laplace_lambda(p: f64) -> f64 {
    if p < 0.5 {
        // erf keeps its relative accuracy near 0, where 1 − P would round to 1 and
        // λ to 0 (P = 1e-300 gave λ = 0, and ΔY = λη = 0).
        return bisect_root(0.0, 40.0, |x| {
            libm::erf(x * std::f64::consts::FRAC_1_SQRT_2) - p
        });
    }
    // 1 − P is exact for P ≥ 1/2 (Sterbenz), and erfc keeps its relative accuracy in
    // the tail, so λ stays accurate for P near 1.
    let tail = 1.0 - p;
    // erfc(x/√2) falls from 1 at 0 to below f64's smallest 1 − P (2⁻⁵³, P < 1)
    // before x = 40: the root is in the bracket.
    bisect_root(0.0, 40.0, |x| {
        tail - libm::erfc(x * std::f64::consts::FRAC_1_SQRT_2)
    })
}

/// The root of an increasing g in [lo, hi] (g(lo) ≤ 0 ≤ g(hi)), bisected down to
/// adjacent floats; of those two, the one where |g| is smaller. From a fixed bracket
/// this is the same sequence of operations on every target (the quantiles of λ and of
/// the Monte Carlo's χ² bands rely on it for the same bits natively and in wasm).
pub(crate) fn bisect_root(mut lo: f64, mut hi: f64, g: impl Fn(f64) -> f64) -> f64 {
    loop {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if g(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    if g(lo).abs() <= g(hi).abs() { lo } else { hi }
}

/// Averaged (3.24) and weighted (3.25) criteria of one set from its running sums;
/// `invalid[c]` nulls criterion c (yz, zx, yx) for every state with that reason.
pub(crate) fn criteria_set(
    m: &CompiledModel,
    s: &SetSums,
    y_max: &[f64],
    z_max: &[f64],
    set: &str,
    invalid: [Option<&str>; 3],
) -> CriteriaSet {
    let n = m.n_states();
    let mut per_state = Vec::with_capacity(n);
    for i in 0..n {
        let mut undefined = BTreeMap::new();
        let pair = m.pair_of_state[i];
        let yb = y_max[i];
        let zb = pair.map(|j| z_max[j]);
        let mut finish = |name: &str,
                          avg: &Avg,
                          factor: Option<f64>,
                          paired: bool|
         -> Option<f64> {
            if !paired {
                undefined.insert(
                    name.to_string(),
                    format!("state \"{}\" has no paired measurement", m.states[i]),
                );
                return None;
            }
            if yb == 0.0 {
                undefined.insert(
                    name.to_string(),
                    format!("y_B = 0: the mean of \"{}\" is identically zero, so relative errors (3.20) are undefined", m.states[i]),
                );
                return None;
            }
            let Some(factor) = factor else {
                undefined.insert(
                    name.to_string(),
                    "z_B = 0: the mean measurement is identically zero".to_string(),
                );
                return None;
            };
            if !factor.is_finite() {
                let why = if zb.is_some_and(f64::is_finite) {
                    format!(
                        "y_B/z_B or z_B/y_B overflowed f64 (y_B = {yb:e}, z_B = {:e}): the measurement's scale is out of all proportion to the state's",
                        zb.unwrap_or(0.0)
                    )
                } else {
                    "z_B = Σ|C_ji| y_B,i (1.5) overflowed f64, so relative errors (3.20) of the measurement are not numbers".to_string()
                };
                undefined.insert(name.to_string(), why);
                return None;
            }
            match avg.mean() {
                Some(v) if !(v * factor).is_finite() => {
                    undefined.insert(
                        name.to_string(),
                        format!("the {set} set's average (3.24) overflowed f64"),
                    );
                    None
                }
                Some(v) => Some(v * factor),
                None => {
                    undefined.insert(
                        name.to_string(),
                        format!(
                            "every step is excluded in the {set} set (a zero denominator, or no measurement available)"
                        ),
                    );
                    None
                }
            }
        };
        // f^YZ = (η/y_B)/(ζ/z_B) = (η/ζ)(z_B/y_B); f^ZX = (ζ/χ)(y_B/z_B); f^YX = η/χ.
        let f_yz = zb.filter(|z| *z > 0.0).map(|z| z / yb);
        let f_zx = zb.filter(|z| *z > 0.0).map(|z| yb / z);
        let mut yz = finish("yz", &s.yz[i], f_yz, pair.is_some());
        let mut zx = finish("zx", &s.zx[i], f_zx, pair.is_some());
        let mut yx = finish("yx", &s.yx[i], Some(1.0), true);
        for ((name, v), why) in [("yz", &mut yz), ("zx", &mut zx), ("yx", &mut yx)]
            .into_iter()
            .zip(invalid)
        {
            if let Some(why) = why {
                *v = None;
                undefined.insert(name.to_string(), why.to_string());
            }
        }
        per_state.push(StateCriteria {
            state: m.states[i].clone(),
            measurement: pair.map(|j| m.measurements[j].clone()),
            yz,
            zx,
            yx,
            undefined,
            excluded_steps: ExcludedSteps {
                yz: s.yz[i].excluded,
                zx: s.zx[i].excluded,
                yx: s.yx[i].excluded,
            },
        });
    }
    let mut undefined = BTreeMap::new();
    let mut weighted = |name: &str, given: Option<&Vec<f64>>, values: Vec<Option<f64>>| {
        let (w, v) = weighted_sum(given, &values);
        match v {
            Ok(v) => (w, Some(v)),
            Err(why) => {
                let why = why.replace("{state}", "");
                let named = why
                    .split_once('#')
                    .map(|(a, i)| format!("{a}\"{}\"", m.states[i.parse::<usize>().unwrap_or(0)]))
                    .unwrap_or(why);
                undefined.insert(name.to_string(), named);
                (w, None)
            }
        }
    };
    let (w_yz, yz) = weighted(
        "yz",
        m.weights_yz.as_ref(),
        per_state.iter().map(|p| p.yz).collect(),
    );
    let (w_zx, zx) = weighted(
        "zx",
        m.weights_zx.as_ref(),
        per_state.iter().map(|p| p.zx).collect(),
    );
    let (w_yx, yx) = weighted(
        "yx",
        m.weights_yx.as_ref(),
        per_state.iter().map(|p| p.yx).collect(),
    );
    CriteriaSet {
        per_state,
        weighted: Weighted {
            yz,
            zx,
            yx,
            weights: WeightsOut {
                yz: w_yz,
                zx: w_zx,
                yx: w_yx,
            },
            undefined,
        },
    }
}

/// (3.25): F = Σ k_i f_i. Default weights: equal over the states where f_i is defined.
/// Err names (as `#i`) a state with positive weight whose criterion is undefined.
fn weighted_sum(
    given: Option<&Vec<f64>>,
    values: &[Option<f64>],
) -> (Vec<f64>, Result<f64, String>) {
    let n = values.len();
    match given {
        Some(w) => {
            for i in 0..n {
                if w[i] > 0.0 && values[i].is_none() {
                    return (
                        w.clone(),
                        Err(format!(
                            "the criterion is undefined for weighted state #{i}"
                        )),
                    );
                }
            }
            let v = (0..n).map(|i| w[i] * values[i].unwrap_or(0.0)).sum();
            (w.clone(), Ok(v))
        }
        None => {
            let defined = values.iter().filter(|v| v.is_some()).count();
            if defined == 0 {
                return (
                    vec![0.0; n],
                    Err("the criterion is undefined for every state".to_string()),
                );
            }
            let k = 1.0 / defined as f64;
            let w: Vec<f64> = values
                .iter()
                .map(|v| if v.is_some() { k } else { 0.0 })
                .collect();
            let v = values.iter().flatten().map(|x| k * x).sum();
            (w, Ok(v))
        }
    }
}
