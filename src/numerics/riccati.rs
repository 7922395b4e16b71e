//! The filter's Riccati recursion (2.1)–(2.7), step by step and at its stationary point.
//!
//! - [`SequentialJoseph`]: one step, for the analysis engine. The measurements,
//!   whitened by [`Prepared`] (Rv = L D Lᵀ), are processed one scalar at a time in
//!   Joseph form; the block gain p_k (2.5) is read off the updated covariance or
//!   composed from the scalar gains. The tests check it against the plain block form.
//! - [`dare_doubling`]: the stationary solution for a time-invariant model, by the
//!   structure-preserving doubling algorithm (SDA), for the analysis's steady-state
//!   shortcut; checked against scipy's DARE in the tests.

mod doubling;
mod whiten;

pub use doubling::{MAX_DOUBLINGS, NoStationary, dare_doubling, doublings_for};
pub use whiten::{NotSemidefinite, Prepared};

use crate::numerics::lanes::Lanes;
use crate::numerics::linalg::{SparseRows, mat_mut, mirror, predict_cov, predict_work};

/// Work buffers and outputs of one step of the filter's covariance recursion
/// (2.1)–(2.7). Allocated once; `step` allocates nothing.
///
/// The measurements are processed one (whitened) scalar at a time, each in Joseph
/// form; for independent measurement noises this is the same update as the block
/// form (2.3)–(2.7), at O(n·N²) instead of O(n·N² + n²·N + n³) and without a matrix
/// solve. The block gain p_k of (2.5) is read off R_k or composed from the scalar
/// gains (see [`SequentialJoseph::step`]).
///
/// It is also its part of an analysis's state ([`crate::resume`]: its f64s kept as
/// their bits; the work buffers with them, which a step overwrites before it reads).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SequentialJoseph {
    #[serde(with = "crate::resume::f64s")]
    u: Vec<f64>,
    #[serde(with = "crate::resume::f64s")]
    s: Vec<f64>,
    /// The scalar gains, composed into the columns of the whitened block gain (nk × N).
    #[serde(with = "crate::resume::f64s")]
    kt: Vec<f64>,
    /// r_k, the predicted (a-priori) covariance (2.1).
    #[serde(with = "crate::resume::f64s")]
    pub r_pred: Vec<f64>,
    /// p_kᵀ (nm × N): row j is the gain column of measurement j (zero when it is not
    /// available at this step).
    #[serde(with = "crate::resume::f64s")]
    pub gain_t: Vec<f64>,
    /// h_kᵀ, the transpose of h_k = I − p_k C (N × N): row c is column c of h_k,
    /// so that building it and the bound's product |h| x (3.19) are row operations.
    #[serde(with = "crate::resume::f64s")]
    pub ht: Vec<f64>,
    /// The last step's update was [`update_exact`]: the filtered variance of a state
    /// a unit row measures is then the filter's, however far below the predicted.
    pub exact: bool,
    /// update_exact's two rows (2N).
    #[serde(with = "crate::resume::f64s")]
    row: Vec<f64>,
}

impl SequentialJoseph {
    pub fn new(n: usize, nm: usize) -> Self {
        SequentialJoseph {
            u: predict_work(n),
            s: vec![0.0; n],
            kt: vec![0.0; nm * n],
            r_pred: vec![0.0; n * n],
            gain_t: vec![0.0; nm * n],
            ht: vec![0.0; n * n],
            exact: false,
            row: vec![0.0; 2 * n],
        }
    }

    /// One step: from R_{k−1} (`big_r`, overwritten with R_k), A_{k−1} = I + E with E
    /// given by its non-zeros, B_{k−1}, and the prepared measurements. Returns false
    /// if an innovation variance is not positive (q_k singular).
    ///
    /// ```text
    /// r = A R Aᵀ + B                                   (2.1)
    /// for each whitened measurement row c with noise variance d:
    ///   s = r cᵀ,  q = c s + d                          (2.3)
    ///   k = s / q                                       (2.5)
    ///   r := (I − k c) r (I − k c)ᵀ + k d kᵀ            (2.7), Joseph form,
    ///      = r − (k sᵀ + s kᵀ) + q k kᵀ                 upper triangle only;
    ///        row a: r_a· − k_a s + (q k_a − s_a) k      (the same sum, regrouped)
    /// R = r, its lower triangle mirrored from the upper: exactly symmetric
    /// p = R Cᵀ D⁻¹ (whitened C and D)                   (2.5), when every row is a unit
    ///                                                   row and q/d ≤ 16 (N·n work);
    /// else p_j = (I − k_n c_n)⋯(I − k_{j+1} c_{j+1}) k_j  (N·n²/2)
    /// ```
    /// The expansion holds for any k, so like the Joseph form it does not rely on k
    /// being the optimal gain. Its rounding error in R_col,col is ≈ ε·q/d of it, so
    /// where a unit row's q at the predicted r exceeds 10³ d (or d = 0) the step's
    /// updates take [`update_exact`] instead: (2.7) as a product, with the factor's
    /// entry 1 − coef·k_col taken as d/q. `n` is the state dimension (a compile-time
    /// constant at the call site lets the compiler unroll every loop here).
    #[inline(always)]
    pub(crate) fn step<const N: usize, L: Lanes>(
        &mut self,
        n: usize,
        big_r: &mut [f64],
        e: &SparseRows,
        big_b: &[f64],
        prep: &Prepared,
    ) -> bool {
        // A constant when N > 0, so that the loops below have fixed trip counts.
        let n = if N > 0 { N } else { n };
        let big_r = &mut big_r[..n * n];
        predict_cov::<N, L>(&mut self.r_pred, big_r, e, big_b, &mut self.u, n);
        big_r.copy_from_slice(&self.r_pred[..n * n]);
        let nk = prep.len();
        let direct = prep.gain_from_covariance(&self.r_pred, n);
        let exact = !direct && prep.needs_exact(&self.r_pred, n);
        self.exact = exact;
        let ok = if exact {
            let w = (&mut self.s[..], &mut self.row[..]);
            update_exact::<N>(n, big_r, &mut self.kt, &mut self.ht, w, prep)
        } else if N > 0 {
            update_fixed::<N>(
                mat_mut(big_r),
                self.kt.as_chunks_mut::<N>().0,
                prep,
                !direct,
            )
        } else {
            update_slices::<L>(n, big_r, &mut self.kt, &mut self.s, prep, !direct)
        };
        if !ok {
            return false;
        }
        if direct {
            // K' column j = R (coef e_col)ᵀ / d = (coef / d) · row col of R (symmetric).
            for (j, k) in self.kt.chunks_exact_mut(n).take(nk).enumerate() {
                if let Some((col, coef)) = prep.unit[j] {
                    let f = coef / prep.d[j];
                    let r = &big_r[col * n..col * n + n];
                    if N > 0 {
                        // Through a local array: LLVM cannot tell kt and R apart, and
                        // would otherwise leave this copy scalar.
                        let r: &[f64; N] = r.try_into().expect("N");
                        let k: &mut [f64; N] = k.try_into().expect("N");
                        *k = r.map(|r| f * r);
                    } else {
                        for (k, r) in k.iter_mut().zip(r) {
                            *k = f * r;
                        }
                    }
                }
            }
        }
        // hᵀ = I − (L⁻¹ C)ᵀ K'ᵀ: row c of hᵀ loses (L⁻¹ C)_jc times gain j, for each
        // measurement j in turn (each entry sees the same subtractions, in the same
        // order, as h = I − K' (L⁻¹ C) built entry by entry).
        // (update_exact built it as the product of the rows' accurate factors.)
        if !exact {
            let ht = &mut self.ht[..n * n];
            ht.fill(0.0);
            for i in 0..n {
                ht[i * n + i] = 1.0;
            }
            for j in 0..nk {
                let k = &self.kt[j * n..j * n + n];
                match prep.unit[j] {
                    Some((col, coef)) => L::sub_scaled(&mut ht[col * n..col * n + n], k, coef),
                    None => {
                        let row = &prep.rows[j * n..j * n + n];
                        for (hc, &c) in ht.chunks_exact_mut(n).zip(row) {
                            for (x, &ka) in hc.iter_mut().zip(k) {
                                *x -= ka * c;
                            }
                        }
                    }
                }
            }
        }
        // p = K' L⁻¹: pᵀ row idx[j] = Σ_{m ≥ j} (L⁻¹)_mj K'ᵀ_m.
        let nm = self.gain_t.len() / n.max(1);
        if !prep.whitened && nk == nm {
            // Every measurement in use, in order: the gains are pᵀ as they stand. (The
            // update writes each row of kt before it reads it, so kt may take any
            // contents.)
            std::mem::swap(&mut self.gain_t, &mut self.kt);
            return true;
        }
        if nk < nm {
            self.gain_t.fill(0.0);
        }
        for (j, &jj) in prep.idx.iter().enumerate() {
            let out = &mut self.gain_t[jj * n..jj * n + n];
            if !prep.whitened {
                out.copy_from_slice(&self.kt[j * n..j * n + n]);
                continue;
            }
            out.fill(0.0);
            for m in j..nk {
                let l = prep.linv[m * nk + j];
                for (x, k) in out.iter_mut().zip(&self.kt[m * n..m * n + n]) {
                    *x += l * k;
                }
            }
        }
        true
    }
}

/// The scalar Joseph updates of [`SequentialJoseph::step`] where the expanded form
/// would lose digits ([`Prepared::needs_exact`]), with h_kᵀ built alongside. For a
/// unit row c = coef·e_col the factor I − k c is taken with its one entry near
/// cancellation computed exactly — 1 − coef·k_col = d/q — and (2.7) as written:
///
/// ```text
/// N = r (I − k c)ᵀ:   N_ab = r_ab − coef k_b r_a,col  (b ≠ col),   N_a,col = (d/q) r_a,col
/// R = (I − k c) N + d k kᵀ:   R_ab = N_ab − coef k_a N_col,b  (a ≠ col),   R_col,b = (d/q) N_col,b
/// ```
///
/// Rounding error in N is multiplied by d/q on the way to R_col,·, so R keeps its
/// relative precision however far q exceeds d (a diffuse initial SKO: η₀ = 10⁸
/// against ψ = 1 left R as garbage in the expanded form; d = 0 gives R_col,col = 0).
/// The earlier gains and h = (I − k_n c_n)⋯(I − k_1 c_1) pass through the same
/// factors. A row that is not a unit row takes the expanded form, as in
/// `update_fixed`. `r` is full and symmetric on entry and on return; O(n·N²), scalar
/// code, so that every build gives the same bits.
#[cold]
#[inline(never)]
fn update_exact<const N: usize>(
    n: usize,
    r: &mut [f64],
    kt: &mut [f64],
    ht: &mut [f64],
    (s, work): (&mut [f64], &mut [f64]),
    prep: &Prepared,
) -> bool {
    // A constant when N > 0 (the engine's fixed sizes), so that the loops unroll.
    let n = if N > 0 { N } else { n };
    let r = &mut r[..n * n];
    let s = &mut s[..n];
    // Column col of r as it was (colv) and row col of N (ncol).
    let (colv, ncol) = work[..2 * n].split_at_mut(n);
    // Only r's upper triangle is current (read through `at`) until a row that is not a
    // unit row, which mirrors it first, and the end.
    let at = |r: &[f64], a: usize, b: usize| r[a.min(b) * n + a.max(b)];
    // h, built row-major here and transposed at the end.
    let h = &mut ht[..n * n];
    h.fill(0.0);
    for i in 0..n {
        h[i * n + i] = 1.0;
    }
    for j in 0..prep.len() {
        let row = &prep.rows[j * n..j * n + n];
        let d = prep.d[j];
        let unit = prep.unit[j];
        if let Some((col, coef)) = unit {
            for (a, x) in colv.iter_mut().enumerate() {
                *x = at(r, a, col);
            }
            for (x, c) in s.iter_mut().zip(colv.iter()) {
                *x = coef * c;
            }
        } else {
            mirror_upper(r, n);
            for (a, x) in s.iter_mut().enumerate() {
                *x = r[a * n..a * n + n]
                    .iter()
                    .zip(row)
                    .map(|(r, c)| r * c)
                    .sum();
            }
        }
        let q = s.iter().zip(row).map(|(a, b)| a * b).sum::<f64>() + d;
        if !(q > 0.0 && q < f64::INFINITY) {
            return false;
        }
        let (done, rest) = kt.split_at_mut(j * n);
        let k = &mut rest[..n];
        for (k, s) in k.iter_mut().zip(s.iter()) {
            *k = s / q;
        }
        match unit {
            Some((col, coef)) => {
                let hc = d / q;
                let rcc = colv[col];
                for (b, x) in ncol.iter_mut().enumerate() {
                    *x = at(r, col, b) - coef * k[b] * rcc;
                }
                ncol[col] = hc * rcc;
                // Rows a ≠ col of the upper triangle: N_ab − coef k_a N_col,b + d k_a k_b
                // with N_ab = r_ab − s_a k_b, except N_a,col = (d/q) r_a,col (below).
                for a in (0..n).filter(|&a| a != col) {
                    let (sa, ck, dk) = (s[a], coef * k[a], d * k[a]);
                    let ra = &mut r[a * n + a..a * n + n];
                    for ((x, kb), nb) in ra.iter_mut().zip(&k[a..]).zip(&ncol[a..]) {
                        *x = *x - sa * kb - ck * nb + dk * kb;
                    }
                    if col > a {
                        r[a * n + col] = hc * colv[a] - ck * ncol[col] + dk * k[col];
                    }
                }
                let kc = d * k[col];
                for b in col..n {
                    r[col * n + b] = hc * ncol[b] + kc * k[b];
                }
                // Earlier gains and h: x := (I − k c) x, entry col by d/q.
                for km in done.chunks_exact_mut(n) {
                    let xc = km[col];
                    for (v, ka) in km.iter_mut().zip(k.iter()) {
                        *v -= coef * ka * xc;
                    }
                    km[col] = hc * xc;
                }
                let (above, from_col) = h.split_at_mut(col * n);
                let (hcol, below) = from_col.split_at_mut(n);
                for (ha, ka) in above
                    .chunks_exact_mut(n)
                    .zip(&k[..col])
                    .chain(below.chunks_exact_mut(n).zip(&k[col + 1..]))
                {
                    let f = coef * ka;
                    for (x, c) in ha.iter_mut().zip(hcol.iter()) {
                        *x -= f * c;
                    }
                }
                for x in hcol.iter_mut() {
                    *x *= hc;
                }
            }
            None => {
                for a in 0..n {
                    let (ka, beta) = (k[a], q * k[a] - s[a]);
                    for b in a..n {
                        r[a * n + b] = r[a * n + b] - ka * s[b] + beta * k[b];
                    }
                }
                for km in done.chunks_exact_mut(n) {
                    let ck: f64 = km.iter().zip(row).map(|(a, b)| a * b).sum();
                    for (x, ka) in km.iter_mut().zip(k.iter()) {
                        *x -= ka * ck;
                    }
                }
                // h := h − k (c h)
                let ch = &mut *ncol;
                for (b, x) in ch.iter_mut().enumerate() {
                    *x = (0..n).map(|l| row[l] * h[l * n + b]).sum();
                }
                for (a, ha) in h.chunks_exact_mut(n).enumerate() {
                    for (x, c) in ha.iter_mut().zip(ch.iter()) {
                        *x -= k[a] * c;
                    }
                }
            }
        }
    }
    mirror_upper(r, n);
    for a in 1..n {
        for b in 0..a {
            h.swap(a * n + b, b * n + a);
        }
    }
    true
}

/// The lower triangle of an n × n row-major matrix := its upper triangle.
fn mirror_upper(r: &mut [f64], n: usize) {
    for a in 1..n {
        for b in 0..a {
            r[a * n + b] = r[b * n + a];
        }
    }
}

/// The scalar Joseph updates of [`SequentialJoseph::step`] on fixed-size arrays.
#[inline(always)]
fn update_fixed<const N: usize>(
    r: &mut [[f64; N]; N],
    kt: &mut [[f64; N]],
    prep: &Prepared,
    compose: bool,
) -> bool {
    for j in 0..prep.len() {
        let row: &[f64; N] = prep.rows[j * N..j * N + N].try_into().expect("row");
        let unit = prep.unit[j];
        // Only the upper triangle (a ≤ b) is current until the mirror at the end.
        let s: [f64; N] = match unit {
            Some((col, coef)) => {
                // column col above the diagonal, row col from it
                let mut s = [0.0; N];
                for b in 0..col {
                    s[b] = coef * r[b][col];
                }
                for b in col..N {
                    s[b] = coef * r[col][b];
                }
                s
            }
            None => {
                let mut s = [0.0; N];
                for a in 0..N {
                    s[a] += r[a][a] * row[a];
                    for b in a + 1..N {
                        s[a] += r[a][b] * row[b];
                        s[b] += r[a][b] * row[a];
                    }
                }
                s
            }
        };
        let q = match unit {
            Some((col, coef)) => coef * s[col],
            None => (0..N).map(|b| s[b] * row[b]).sum::<f64>(),
        } + prep.d[j];
        // (Two comparisons, which NaN fails too: `is_finite` compiles to ≈ 20
        // integer instructions here.)
        if !(q > 0.0 && q < f64::INFINITY) {
            return false;
        }
        let k: [f64; N] = s.map(|x| x / q);
        let beta: [f64; N] = std::array::from_fn(|a| q * k[a] - s[a]);
        for a in 0..N {
            // r_a· − k_a s − s_a k + q k_a k, grouped as r_a· − k_a s + (q k_a − s_a) k
            let (ka, beta) = (k[a], beta[a]);
            let ra = &mut r[a];
            for b in a..N {
                ra[b] = ra[b] - ka * s[b] + beta * k[b];
            }
        }
        // Earlier gains pass through (I − k c): the block gain's columns.
        let (done, rest) = kt.split_at_mut(j);
        let done = if compose { done } else { &mut [] };
        for km in done.iter_mut() {
            let ck = match unit {
                Some((col, coef)) => coef * km[col],
                None => (0..N).map(|b| km[b] * row[b]).sum(),
            };
            for b in 0..N {
                km[b] -= k[b] * ck;
            }
        }
        rest[0] = k;
    }
    mirror(r, true);
    true
}

/// The scalar Joseph updates of [`SequentialJoseph::step`] for a runtime dimension.
#[inline(always)]
fn update_slices<L: Lanes>(
    n: usize,
    big_r: &mut [f64],
    kt: &mut [f64],
    s: &mut [f64],
    prep: &Prepared,
    compose: bool,
) -> bool {
    let s = &mut s[..n];
    for j in 0..prep.len() {
        let row = &prep.rows[j * n..j * n + n];
        // Only the upper triangle (a ≤ b) is current until the mirror at the end.
        let q = match prep.unit[j] {
            Some((col, coef)) => {
                // column col above the diagonal, row col from it
                for b in 0..col {
                    s[b] = coef * big_r[b * n + col];
                }
                for (x, r) in s[col..].iter_mut().zip(&big_r[col * n + col..col * n + n]) {
                    *x = coef * r;
                }
                coef * s[col] + prep.d[j]
            }
            None => {
                s.fill(0.0);
                for a in 0..n {
                    let ra = &big_r[a * n..a * n + n];
                    s[a] += ra[a] * row[a];
                    let mut acc = 0.0;
                    for b in a + 1..n {
                        acc += ra[b] * row[b];
                        s[b] += ra[b] * row[a];
                    }
                    s[a] += acc;
                }
                s.iter().zip(row).map(|(a, b)| a * b).sum::<f64>() + prep.d[j]
            }
        };
        if !(q > 0.0 && q < f64::INFINITY) {
            return false;
        }
        let (done, rest) = kt.split_at_mut(j * n);
        let k = &mut rest[..n];
        for (k, s) in k.iter_mut().zip(s.iter()) {
            *k = s / q;
        }
        for a in 0..n {
            // as in `update_fixed`: r_a· − k_a s + (q k_a − s_a) k
            let (ka, beta) = (k[a], q * k[a] - s[a]);
            L::sub_add(
                &mut big_r[a * n + a..a * n + n],
                &s[a..n],
                ka,
                &k[a..n],
                beta,
            );
        }
        // Earlier gains pass through (I − k c): the block gain's columns.
        let done = if compose { done } else { &mut [] };
        for km in done.chunks_exact_mut(n) {
            let ck = match prep.unit[j] {
                Some((col, coef)) => coef * km[col],
                None => km.iter().zip(row).map(|(a, b)| a * b).sum(),
            };
            L::sub_scaled(km, k, ck);
        }
    }
    for a in 1..n {
        for b in 0..a {
            big_r[a * n + b] = big_r[b * n + a];
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numerics::lanes::Scalar;
    use nalgebra::DMatrix;

    /// One step with A = I and B = 0 (so r = R_prev), unit measurement rows
    /// coef·e_col, diagonal noise; returns R, the gain (N × nm) and whether the
    /// gain was read off R.
    fn one_step<const N: usize>(
        r_prev: &DMatrix<f64>,
        rows: &[(usize, f64)],
        noise: &[f64],
    ) -> (DMatrix<f64>, DMatrix<f64>, bool) {
        let (n, nm) = (r_prev.nrows(), rows.len());
        let mut c = vec![0.0; nm * n];
        let mut rv = vec![0.0; nm * nm];
        for (j, &(col, coef)) in rows.iter().enumerate() {
            c[j * n + col] = coef;
            rv[j * nm + j] = noise[j];
        }
        let mut prep = Prepared::new(n, nm);
        prep.prepare(&c, &rv, None, n, nm).unwrap();
        let mut big_r: Vec<f64> = r_prev.transpose().iter().copied().collect();
        let direct = prep.gain_from_covariance(&big_r, n);
        let mut j = SequentialJoseph::new(n, nm);
        let e = SparseRows::with_pattern(n, vec![]);
        assert!(j.step::<N, Scalar>(n, &mut big_r, &e, &vec![0.0; n * n], &prep));
        let r = DMatrix::from_row_slice(n, n, &big_r);
        let gain = DMatrix::from_fn(n, nm, |i, m| j.gain_t[m * n + i]);
        (r, gain, direct)
    }

    /// The block form (2.3)–(2.7), written plainly.
    fn block(
        r: &DMatrix<f64>,
        rows: &[(usize, f64)],
        noise: &[f64],
    ) -> (DMatrix<f64>, DMatrix<f64>) {
        let (n, nm) = (r.nrows(), rows.len());
        let c = DMatrix::from_fn(nm, n, |j, i| if rows[j].0 == i { rows[j].1 } else { 0.0 });
        let rv = DMatrix::from_fn(nm, nm, |a, b| if a == b { noise[a] } else { 0.0 });
        let q = &c * r * c.transpose() + &rv;
        let p = r * c.transpose() * q.try_inverse().unwrap();
        let h = DMatrix::identity(n, n) - &p * &c;
        (&h * r * h.transpose() + &p * &rv * p.transpose(), p)
    }

    fn check<const N: usize>(scale: f64, want_direct: bool) {
        let n = if N > 0 { N } else { 14 };
        // A well-conditioned correlated r: 1 on the diagonal, 0.3^|a−b| off it.
        let r = DMatrix::from_fn(n, n, |a, b| {
            scale * 0.3f64.powi((a as i32 - b as i32).abs())
        });
        // Measure every second state, in reverse order, with coefficients ≠ 1.
        let rows: Vec<(usize, f64)> = (0..n)
            .rev()
            .step_by(2)
            .map(|i| (i, 0.5 + 0.1 * i as f64))
            .collect();
        let noise: Vec<f64> = (0..rows.len()).map(|j| 0.2 + 0.05 * j as f64).collect();
        let (big_r, gain, direct) = one_step::<N>(&r, &rows, &noise);
        assert_eq!(direct, want_direct, "N = {n}, scale {scale}");
        let (r_ref, p_ref) = block(&r, &rows, &noise);
        let rel = |a: &DMatrix<f64>, b: &DMatrix<f64>| (a - b).amax() / b.amax();
        assert!(rel(&big_r, &r_ref) < 1e-13, "R: {:e}", rel(&big_r, &r_ref));
        assert!(rel(&gain, &p_ref) < 1e-13, "gain: {:e}", rel(&gain, &p_ref));
    }

    #[test]
    fn gain_read_off_the_covariance_equals_the_block_gain() {
        // q/d ≤ 16: p = R Cᵀ D⁻¹; fixed-size and runtime-dimension kernels.
        check::<6>(0.1, true);
        check::<0>(0.1, true);
    }

    #[test]
    fn gain_composed_from_scalar_gains_equals_the_block_gain() {
        // r ≫ d: the gains are composed through (I − k c).
        check::<6>(100.0, false);
        check::<0>(100.0, false);
    }
}
