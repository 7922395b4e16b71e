//! The measurements of one step prepared for the sequential update: Rv = L D Lᵀ
//! (`ldl`, with diagonal pivoting) whitens them into independent scalar measurements;
//! and the checks that choose how the step takes the gain (2.5) and the update (2.7).

/// The measurement covariance Rv has a negative pivot beyond rounding: it is not
/// positive semi-definite.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NotSemidefinite;

/// The measurements used at one step, prepared for sequential (scalar) processing:
/// P Rv Pᵀ = L D Lᵀ (P a permutation, L unit lower triangular, D ≥ 0 diagonal), so
/// the whitened measurements L⁻¹ P Z have rows L⁻¹ P C and independent noises of
/// variance D. A diagonal Rv (the usual case: Γ = I or one noise per measurement)
/// needs no whitening.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// Measurements in use at this step (indices into 0..nm), in P's order when
    /// whitened.
    pub idx: Vec<usize>,
    /// Their (whitened) rows, nk × n.
    pub(super) rows: Vec<f64>,
    /// Some((col, coef)) where a row is coef·e_col: its products cost O(1) or O(n).
    pub(super) unit: Vec<Option<(usize, f64)>>,
    /// D: the noise variance of each whitened row.
    pub(super) d: Vec<f64>,
    /// L⁻¹ (nk × nk, unit lower), used when `whitened` (Rv is not diagonal).
    pub(super) linv: Vec<f64>,
    pub(super) whitened: bool,
    /// The spread of the whitening's non-zero pivots, max D / min D (1 when Rv is
    /// diagonal): about the condition of Rv, whose log10 is the digits whitening loses.
    pub spread: f64,
    work: Vec<f64>,
    /// P: the row of the factored matrix that became row j, and `idx` in that order.
    perm: Vec<usize>,
    permuted: Vec<usize>,
}

impl Prepared {
    pub fn new(n: usize, nm: usize) -> Self {
        Prepared {
            idx: Vec::with_capacity(nm),
            rows: vec![0.0; nm * n],
            unit: vec![None; nm],
            d: vec![0.0; nm],
            linv: vec![0.0; nm * nm],
            whitened: false,
            spread: 1.0,
            work: vec![0.0; nm * nm],
            perm: vec![0; nm],
            permuted: Vec::with_capacity(nm),
        }
    }

    /// Prepare the rows of C (nm × n) and Rv (nm × nm) of the measurements with
    /// `avail[j]` (all when None). Err if Rv is not positive semi-definite.
    pub fn prepare(
        &mut self,
        c: &[f64],
        rv: &[f64],
        avail: Option<&[bool]>,
        n: usize,
        nm: usize,
    ) -> Result<(), NotSemidefinite> {
        self.idx.clear();
        self.idx
            .extend((0..nm).filter(|&j| avail.is_none_or(|a| a[j])));
        let nk = self.idx.len();
        let diagonal = self
            .idx
            .iter()
            .all(|&a| self.idx.iter().all(|&b| a == b || rv[a * nm + b] == 0.0));
        for (r, &j) in self.idx.iter().enumerate() {
            self.rows[r * n..r * n + n].copy_from_slice(&c[j * n..j * n + n]);
        }
        if diagonal {
            for (r, &j) in self.idx.iter().enumerate() {
                self.d[r] = rv[j * nm + j];
            }
            self.whitened = false;
            self.spread = 1.0;
        } else {
            // P Rv_k Pᵀ = L D Lᵀ, the measurements (and their rows of C) taken in P's
            // order, then L⁻¹ by forward substitution, rows := L⁻¹ P C.
            let a = &mut self.work[..nk * nk];
            for (r, &i) in self.idx.iter().enumerate() {
                for (s, &j) in self.idx.iter().enumerate() {
                    a[r * nk + s] = rv[i * nm + j];
                }
            }
            ldl(a, &mut self.d[..nk], &mut self.perm[..nk], nk)?;
            self.permuted.clear();
            self.permuted
                .extend(self.perm[..nk].iter().map(|&p| self.idx[p]));
            std::mem::swap(&mut self.idx, &mut self.permuted);
            for (r, &j) in self.idx.iter().enumerate() {
                self.rows[r * n..r * n + n].copy_from_slice(&c[j * n..j * n + n]);
            }
            let linv = &mut self.linv[..nk * nk];
            linv.fill(0.0);
            for j in 0..nk {
                linv[j * nk + j] = 1.0;
                for i in j + 1..nk {
                    let mut s = 0.0;
                    for k in j..i {
                        s -= a[i * nk + k] * linv[k * nk + j];
                    }
                    linv[i * nk + j] = s;
                }
            }
            // How far a noise-free whitened row may be rounding residue (below): L⁻¹'s
            // entries carry errors of about ε times Rv's condition, which the pivots'
            // spread estimates.
            let (d_max, d_min) = self.d[..nk]
                .iter()
                .filter(|&&d| d > 0.0)
                .fold((0.0, f64::INFINITY), |(hi, lo): (f64, f64), &d| {
                    (hi.max(d), lo.min(d))
                });
            self.spread = if d_max > 0.0 { d_max / d_min } else { 1.0 };
            let residue = if d_max > 0.0 {
                DEPENDENT_ROW.max(16.0 * f64::EPSILON * d_max / d_min)
            } else {
                DEPENDENT_ROW
            };
            // In place, last row first: row i needs the original rows k < i.
            for i in (0..nk).rev() {
                let (before, from_i) = self.rows.split_at_mut(i * n);
                let row = &mut from_i[..n];
                // Each entry summed in k's order, with the size of the terms it sums
                // (for the test below).
                let mut scale = 0.0f64;
                for (x, entry) in row.iter_mut().enumerate() {
                    let mut terms = entry.abs();
                    for k in 0..i {
                        let t = linv[i * nk + k] * before[k * n + x];
                        *entry += t;
                        terms += t.abs();
                    }
                    scale = scale.max(terms);
                }
                // A noise-free whitened measurement (zero pivot) whose row cancelled to
                // rounding level is a measurement that repeats the others, noise and
                // all: its row is 0, as it is where the cancellation comes out exact,
                // and the step reports q singular. Kept, the residue (≈ 1e-17 of the
                // terms, up to ≈ 1e-10 with an ill-conditioned Rv) made a noise-free
                // "measurement" with a gain of 1/residue (≈ 7e16).
                let left = row.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
                if self.d[i] == 0.0 && left <= residue * scale {
                    row.fill(0.0);
                }
            }
            self.whitened = true;
        }
        for r in 0..nk {
            let row = &self.rows[r * n..r * n + n];
            let mut nz = row.iter().enumerate().filter(|(_, v)| **v != 0.0);
            self.unit[r] = match (nz.next(), nz.next()) {
                (Some((col, &coef)), None) => Some((col, coef)),
                _ => None,
            };
        }
        Ok(())
    }

    /// Whether the block gain may be read off the updated covariance, p = R Cᵀ D⁻¹
    /// (see [`SequentialJoseph::step`]): every row is a unit row coef·e_col with a
    /// noise variance d > 0 and an innovation variance q ≤ coef² r_col,col + d at
    /// most [`DIRECT_GAIN_MAX_Q_OVER_D`] times d. R's rounding error, about ε·q
    /// absolute, is divided by d in p, so q/d bounds how much p's error grows against
    /// the composed gain's.
    pub(super) fn gain_from_covariance(&self, r_pred: &[f64], n: usize) -> bool {
        !self.idx.is_empty()
            && self.unit[..self.idx.len()]
                .iter()
                .zip(&self.d)
                .all(|(u, &d)| match *u {
                    Some((col, coef)) => {
                        d > 0.0
                            && coef * coef * r_pred[col * n + col]
                                <= (DIRECT_GAIN_MAX_Q_OVER_D - 1.0) * d
                    }
                    None => false,
                })
    }

    /// Whether a unit row's update would lose digits in the expanded form of (2.7)
    /// (see [`SequentialJoseph::step`]): its innovation variance
    /// q = coef² r_col,col + d above [`EXACT_Q_OVER_D`] times its noise variance d,
    /// or d = 0 (or NaN, which the exact path reports: hence `!(x <= …)`). The
    /// expanded form subtracts terms of size q to leave R_col,col ≈ r_col,col·d/q, so
    /// its relative error is ≈ ε·q/d. Updates only shrink r, so the rows' q at the
    /// predicted r bound every q of the step. Never where
    /// [`Self::gain_from_covariance`] holds (q ≤ 16 d for every row), which the step
    /// asks first.
    pub(super) fn needs_exact(&self, r_pred: &[f64], n: usize) -> bool {
        self.unit[..self.idx.len()]
            .iter()
            .zip(&self.d)
            .any(|(u, &d)| match *u {
                Some((col, coef)) => {
                    !(coef * coef * r_pred[col * n + col] <= (EXACT_Q_OVER_D - 1.0) * d)
                }
                None => false,
            })
    }

    /// A measurement in use is a unit row on state `i`.
    pub fn measures(&self, i: usize) -> bool {
        self.unit[..self.idx.len()]
            .iter()
            .any(|u| u.is_some_and(|(col, _)| col == i))
    }

    /// The number of measurements in use.
    pub fn len(&self) -> usize {
        self.idx.len()
    }

    pub fn is_empty(&self) -> bool {
        self.idx.is_empty()
    }
}

/// A noise-free whitened row at most this fraction of the terms it was summed from is
/// rounding residue (the same relative level as `ldl`'s zero pivots; more where Rv is
/// ill-conditioned, see `prepare`): the measurement is a combination of the others.
const DEPENDENT_ROW: f64 = 1e-14;

/// The largest innovation-to-noise variance ratio q/d for which the block gain is
/// read off the updated covariance instead of composed from the scalar gains.
const DIRECT_GAIN_MAX_Q_OVER_D: f64 = 16.0;

/// The largest q/d for which a unit row's update takes the expanded form of (2.7),
/// whose relative error in R_col,col is then ≲ 1e3 ε ≈ 2e-13; above it (a diffuse
/// initial SKO, a sensor far more accurate than the prediction, no noise at all) the
/// step takes [`update_exact`].
const EXACT_Q_OVER_D: f64 = 1e3;

/// P a Pᵀ = L D Lᵀ in place (a full symmetric m × m; its strict lower triangle := L),
/// for a positive semi-definite a, with diagonal pivoting: each step takes the largest
/// pivot left (LAPACK's `pstrf` order), and `perm[j]` is the row of a that became row
/// j. A zero pivot zeroes its column of L. Err on a negative pivot beyond rounding.
///
/// A singular a (fewer noise sources than measurements: Γ Ψ² Γᵀ of rank M < n) has
/// pivots that are 0 exactly and only near 0 in floating point. Without pivoting the
/// last one is the small difference of terms divided by the earlier, possibly small,
/// pivots (seen at −4e-12 of the scale); taken largest first, the zero pivots come
/// last and stay within a few ε of the scale (Higham, *Accuracy and Stability of
/// Numerical Algorithms*, §10.3). Pivots up to `tiny` are zeros. The negative bound
/// is what the validator lets through: a covariance whose smallest eigenvalue is down
/// to −1e-12 of its largest (`validate.rs`); no pivot is below the smallest
/// eigenvalue, and the largest is at most m·scale.
fn ldl(a: &mut [f64], d: &mut [f64], perm: &mut [usize], m: usize) -> Result<(), NotSemidefinite> {
    let scale = (0..m).map(|i| a[i * m + i].abs()).fold(0.0, f64::max);
    let tiny = 1e-14 * scale;
    let negative_zero = tiny + 1e-12 * m as f64 * scale;
    for (j, p) in perm.iter_mut().enumerate() {
        *p = j;
    }
    for j in 0..m {
        let pivot = |a: &[f64], i: usize| {
            let mut di = a[i * m + i];
            for k in 0..j {
                di -= a[i * m + k] * a[i * m + k] * d[k];
            }
            di
        };
        let (mut p, mut dj) = (j, pivot(a, j));
        for i in j + 1..m {
            let di = pivot(a, i);
            if di > dj {
                (p, dj) = (i, di);
            }
        }
        if p != j {
            // Rows j and p of L so far, and of a's remaining entries; columns j and p.
            for c in 0..m {
                a.swap(j * m + c, p * m + c);
            }
            for r in 0..m {
                a.swap(r * m + j, r * m + p);
            }
            perm.swap(j, p);
        }
        if !dj.is_finite() || dj < -negative_zero {
            return Err(NotSemidefinite);
        }
        if dj <= tiny {
            dj = 0.0;
        }
        d[j] = dj;
        for i in j + 1..m {
            let mut s = a[i * m + j];
            for k in 0..j {
                s -= a[i * m + k] * a[j * m + k] * d[k];
            }
            a[i * m + j] = if dj > 0.0 { s / dj } else { 0.0 };
        }
    }
    Ok(())
}
