//! Small dense kernels on row-major flat slices, written so that the compiler
//! vectorises them and, when called with a compile-time dimension, unrolls them.
//! No allocation; callers own the buffers.

use crate::numerics::lanes::Lanes;

/// c (r×p) = a (r×k) · b (k×p).
#[inline(always)]
pub fn mul(c: &mut [f64], a: &[f64], b: &[f64], r: usize, k: usize, p: usize) {
    for i in 0..r {
        let ci = &mut c[i * p..i * p + p];
        ci.fill(0.0);
        let ai = &a[i * k..i * k + k];
        for l in 0..k {
            let ail = ai[l];
            let bl = &b[l * p..l * p + p];
            for j in 0..p {
                ci[j] += ail * bl[j];
            }
        }
    }
}

/// Symmetric c (r×r) = a (r×k) · bᵀ where b is r×k, plus `add` (r×r, may be empty):
/// only the upper triangle is computed, then mirrored, so c is exactly symmetric.
#[inline(always)]
pub fn mul_abt_sym(c: &mut [f64], a: &[f64], b: &[f64], add: Option<&[f64]>, r: usize, k: usize) {
    for i in 0..r {
        let ai = &a[i * k..i * k + k];
        for j in i..r {
            let bj = &b[j * k..j * k + k];
            let mut s = 0.0;
            for l in 0..k {
                s += ai[l] * bj[l];
            }
            if let Some(add) = add {
                s += add[i * r + j];
            }
            c[i * r + j] = s;
            c[j * r + i] = s;
        }
    }
}

/// The non-zeros (row, col, value) of a sparse N×N matrix, sorted by row, with the
/// start of each row's run.
#[derive(Clone, Debug, Default)]
pub struct SparseRows {
    /// Written only through [`SparseRows::set_values`], which keeps the diagonals'
    /// copy equal to it.
    nz: Vec<(usize, usize, f64)>,
    /// Each non-zero's index i·N + j in a dense row-major N×N matrix.
    flat: Vec<usize>,
    start: Vec<usize>,
    /// The pattern's diagonals when there are at most [`MAX_DIAGONALS`].
    diagonals: Option<Diagonals>,
}

/// At most this many diagonals: [`predict_cov`] forms R Aᵀ by shifted row operations
/// (one per diagonal) instead of transposing A R.
const MAX_DIAGONALS: usize = 8;

/// A sparse pattern by diagonals: the offsets col − row present, ascending, for each
/// non-zero its slot (diagonal · N + row), and the values in that diagonals × N
/// layout (0 off the pattern), kept equal to `nz` by [`SparseRows::set_values`].
#[derive(Clone, Debug, Default)]
struct Diagonals {
    offsets: Vec<isize>,
    slot: Vec<usize>,
    values: Vec<f64>,
}

impl Diagonals {
    /// Each diagonal's offset d, values, and the rows a in lo..hi that keep a + d
    /// inside the matrix.
    #[inline(always)]
    fn each(&self, n: usize) -> impl Iterator<Item = (usize, usize, usize, &[f64])> {
        self.offsets
            .iter()
            .zip(self.values.chunks_exact(n.max(1)))
            .filter_map(move |(&d, vals)| {
                let lo = d.min(0).unsigned_abs();
                let hi = n - d.max(0).unsigned_abs().min(n);
                (lo < hi).then(|| (lo, hi, (lo as isize + d) as usize, vals))
            })
    }
}

impl SparseRows {
    /// A matrix with the given non-zero positions (values 0 until set).
    pub fn with_pattern(n: usize, mut pattern: Vec<(usize, usize)>) -> Self {
        pattern.sort_unstable();
        let mut start = vec![0; n + 1];
        for &(i, _) in &pattern {
            start[i + 1] += 1;
        }
        for i in 0..n {
            start[i + 1] += start[i];
        }
        let mut offsets: Vec<isize> = pattern
            .iter()
            .map(|&(i, j)| j as isize - i as isize)
            .collect();
        offsets.sort_unstable();
        offsets.dedup();
        let diagonals = (offsets.len() <= MAX_DIAGONALS).then(|| Diagonals {
            values: vec![0.0; offsets.len() * n],
            slot: pattern
                .iter()
                .map(|&(i, j)| {
                    let d = offsets
                        .binary_search(&(j as isize - i as isize))
                        .expect("offset");
                    d * n + i
                })
                .collect(),
            offsets,
        });
        SparseRows {
            flat: pattern.iter().map(|&(i, j)| i * n + j).collect(),
            nz: pattern.into_iter().map(|(i, j)| (i, j, 0.0)).collect(),
            start,
            diagonals,
        }
    }

    /// The non-zeros (row, col, value), sorted by row and column.
    pub fn nonzeros(&self) -> &[(usize, usize, f64)] {
        &self.nz
    }

    /// The non-zeros of row i.
    #[inline(always)]
    pub fn row(&self, i: usize) -> &[(usize, usize, f64)] {
        &self.nz[self.start[i]..self.start[i + 1]]
    }

    /// Sets every non-zero (i, j) to f(m_ij, i = j), for a dense row-major N×N m
    /// (entries off the pattern are not read). Each non-zero's index into m is
    /// computed once, at construction: a time-varying a(t) sets E and |A| every step.
    #[inline(always)]
    pub fn set_values(&mut self, m: &[f64], mut f: impl FnMut(f64, bool) -> f64) {
        match &mut self.diagonals {
            Some(dia) => {
                for ((e, &slot), &at) in self.nz.iter_mut().zip(&dia.slot).zip(&self.flat) {
                    e.2 = f(m[at], e.0 == e.1);
                    dia.values[slot] = e.2;
                }
            }
            None => {
                for (e, &at) in self.nz.iter_mut().zip(&self.flat) {
                    e.2 = f(m[at], e.0 == e.1);
                }
            }
        }
    }

    /// y = M x, each row's non-zeros summed in column order from 0.0: by shifted
    /// row operations (one per diagonal) when the pattern has few diagonals. An entry
    /// off the pattern there adds 0·x_j, which leaves the sum (finite x; a sum that
    /// starts at +0.0 is never −0.0), so both ways give the same bits.
    #[inline(always)]
    pub(crate) fn mul_vec<L: Lanes>(&self, y: &mut [f64], x: &[f64], n: usize) {
        let y = &mut y[..n];
        y.fill(0.0);
        match &self.diagonals {
            Some(dia) => {
                for (lo, hi, shift, vals) in dia.each(n) {
                    L::add_prod(&mut y[lo..hi], &vals[lo..hi], &x[shift..shift + hi - lo]);
                }
            }
            None => {
                for &(i, j, v) in &self.nz {
                    y[i] += v * x[j];
                }
            }
        }
    }
}

impl SparseRows {
    /// [`SparseRows::mul_vec`] on fixed-size arrays (N ≤ 12, every loop unrolled): the
    /// same terms in the same order, so the same bits. With few diagonals, x padded
    /// with zeros makes each diagonal one whole-row operation (as in
    /// [`predict_cov`]): a row whose column falls outside adds 0·0.
    #[inline(always)]
    pub(crate) fn mul_vec_fixed<const N: usize>(&self, y: &mut [f64; N], x: &[f64; N]) {
        match &self.diagonals {
            Some(dia) => {
                let mut w = [0.0f64; N];
                for (&d, vals) in dia.offsets.iter().zip(dia.values.chunks_exact(N)) {
                    add_shifted(&mut w, vals.try_into().expect("N"), x, d);
                }
                *y = w;
            }
            None => {
                *y = [0.0; N];
                for &(i, j, v) in &self.nz {
                    y[i] += v * x[j];
                }
            }
        }
    }
}

/// w_j += v_j x_{j+d} for j in 0..N, x_{j+d} = 0 outside 0..N (N ≤ 12): one
/// diagonal of a sparse product as a whole-row operation. The diagonals ±1 and 0 read
/// x itself; others read a zero-padded copy (a load across the copy's fresh stores
/// waits for them: store forwarding fails on a shifted load, ≈ a third of a frozen
/// step when the chain's diagonals took that path).
#[inline(always)]
fn add_shifted<const N: usize>(w: &mut [f64; N], v: &[f64; N], x: &[f64; N], d: isize) {
    match d {
        0 => {
            for j in 0..N {
                w[j] += v[j] * x[j];
            }
        }
        1 => {
            for j in 0..N - 1 {
                w[j] += v[j] * x[j + 1];
            }
            w[N - 1] += v[N - 1] * 0.0;
        }
        -1 => {
            w[0] += v[0] * 0.0;
            for j in 1..N {
                w[j] += v[j] * x[j - 1];
            }
        }
        _ => {
            let mut pad = [0.0f64; 36];
            pad[12..12 + N].copy_from_slice(x);
            let src: &[f64; N] = pad[(12 + d) as usize..][..N].try_into().expect("N");
            for j in 0..N {
                w[j] += v[j] * src[j];
            }
        }
    }
}

/// View the first N entries of a slice as an array (N > 0).
#[inline(always)]
pub fn arr<const N: usize>(v: &[f64]) -> &[f64; N] {
    v[..N].try_into().expect("N")
}

/// Mutable [`arr`].
#[inline(always)]
pub fn arr_mut<const N: usize>(v: &mut [f64]) -> &mut [f64; N] {
    (&mut v[..N]).try_into().expect("N")
}

/// A work buffer for [`predict_cov`] of an n-state model.
pub(crate) fn predict_work(n: usize) -> Vec<f64> {
    vec![0.0; n * n]
}

/// out = A R Aᵀ + B for A = I + E with E sparse and R, B symmetric: the prediction
/// (2.1) in O(nnz(E)·N + N²) instead of O(N³). U = A R = R + E R by row operations,
/// then the upper triangle of U Aᵀ, (U Aᵀ)_ab = U_ab + Σ_c E_bc U_ac, mirrored — so
/// the result is exactly symmetric. `u` is a [`predict_work`] buffer.
/// `N > 0`: the compile-time dimension (n = N).
#[inline(always)]
pub(crate) fn predict_cov<const N: usize, L: Lanes>(
    out: &mut [f64],
    r: &[f64],
    e: &SparseRows,
    b: &[f64],
    u: &mut [f64],
    n: usize,
) {
    predict_first::<N, L>(u, r, e, n);
    predict_second::<N, L>(out, u, e, b, n, true);
}

/// [`predict_cov`] in place, P ← A P Aᵀ + B: the first half reads all of P before
/// the second writes it, so no second buffer (and no copy or swap of one) is needed.
/// For fixed N the result is not re-symmetrised: every entry is its own row's
/// (A P Aᵀ)_ab, so P keeps an antisymmetric part at rounding level, which never
/// reaches the diagonal (A S Aᵀ of an antisymmetric S is antisymmetric: its diagonal
/// is 0) — for callers that read only the diagonal. Copying the upper triangle onto
/// the lower one entry at a time made the next step's whole-row loads wait for those
/// stores (store forwarding fails on a load spanning several of them): ≈ 45 ns of a
/// 170 ns frozen analysis step.
#[inline(always)]
pub(crate) fn predict_in_place<const N: usize, L: Lanes>(
    p: &mut [f64],
    e: &SparseRows,
    b: &[f64],
    u: &mut [f64],
    n: usize,
) {
    predict_first::<N, L>(u, p, e, n);
    predict_second::<N, L>(p, u, e, b, n, false);
}

/// The prediction's first half: V = (A R)ᵀ in `u`, or U = A R itself for fixed N
/// with few diagonals (what [`predict_second`] reads).
#[inline(always)]
fn predict_first<const N: usize, L: Lanes>(u: &mut [f64], r: &[f64], e: &SparseRows, n: usize) {
    if N > 0 {
        return fixed_first::<N>(mat_mut(u), mat(r), e);
    }
    // Runtime N: the same sums, arranged as row operations for the row kernels L.
    // V = Uᵀ (transposed in place); W = A V = V + E V row by row, of which row b's
    // first b + 1 entries are needed: W_ba = U_ab + Σ_c E_bc U_ac = (U Aᵀ)_ab with
    // the same terms in the same order; then + B (exactly symmetric) and mirrored.
    let (r, u) = (&r[..n * n], &mut u[..n * n]);
    if let Some(dia) = &e.diagonals {
        // V = Uᵀ = R Aᵀ directly, no transpose: row c, V_ca = R_ca + Σ_d E_a,a+d R_c,a+d
        // over the diagonals d ascending, one shifted row operation each. These are
        // U_ac = R_ac + Σ_k E_ak R_kc's terms in the same order (R is exactly
        // symmetric); an entry off E's pattern adds 0·R_c,a+d, which leaves the sum.
        for c in 0..n {
            let (vc, rc) = (&mut u[c * n..c * n + n], &r[c * n..c * n + n]);
            vc.copy_from_slice(rc);
            for (lo, hi, shift, ed) in dia.each(n) {
                L::add_prod(&mut vc[lo..hi], &ed[lo..hi], &rc[shift..shift + hi - lo]);
            }
        }
    } else {
        mul_transpose_into::<L>(u, r, e, n);
    }
}

/// The prediction's second half: out = A V + B from [`predict_first`]'s `u`;
/// `symmetric`: mirrored to be exactly symmetric (always so for runtime N, which
/// computes only one triangle).
#[inline(always)]
fn predict_second<const N: usize, L: Lanes>(
    out: &mut [f64],
    u: &[f64],
    e: &SparseRows,
    b: &[f64],
    n: usize,
    symmetric: bool,
) {
    if N > 0 {
        return fixed_second::<N>(mat_mut(out), mat(u), e, mat(b), symmetric);
    }
    second_half::<L>(out, &u[..n * n], e, &b[..n * n], n);
}

/// V = (A R)ᵀ for A = I + E: U = R + E R by row operations, transposed in place.
#[inline(always)]
fn mul_transpose_into<L: Lanes>(u: &mut [f64], r: &[f64], e: &SparseRows, n: usize) {
    // (Each row's first term is fused with the copy it adds to: the same sums.)
    for i in 0..n {
        let (ui, ri) = (&mut u[i * n..i * n + n], &r[i * n..i * n + n]);
        match e.row(i).split_first() {
            None => ui.copy_from_slice(ri),
            Some((&(_, k, v), rest)) => {
                L::set_scaled(ui, ri, &r[k * n..k * n + n], v);
                for &(_, k, v) in rest {
                    L::add_scaled(ui, &r[k * n..k * n + n], v);
                }
            }
        }
    }
    for i in 0..n {
        for j in i + 1..n {
            u.swap(i * n + j, j * n + i);
        }
    }
}

/// out = A V + B with V = (A R)ᵀ in `u`: row b's first b + 1 entries, mirrored.
#[inline(always)]
fn second_half<L: Lanes>(out: &mut [f64], u: &[f64], e: &SparseRows, b: &[f64], n: usize) {
    for bb in 0..n {
        let w = &mut out[bb * n..bb * n + bb + 1];
        let (ub, b_row) = (&u[bb * n..bb * n + bb + 1], &b[bb * n..bb * n + bb + 1]);
        // + B_b· (1·x is exact, so this is the plain sum)
        match e.row(bb).split_first() {
            None => L::set_scaled(w, ub, b_row, 1.0),
            Some((&(_, c, v), rest)) => {
                L::set_scaled(w, ub, &u[c * n..c * n + bb + 1], v);
                for &(_, c, v) in rest {
                    L::add_scaled(w, &u[c * n..c * n + bb + 1], v);
                }
                L::add_scaled(w, b_row, 1.0);
            }
        }
    }
    for a in 1..n {
        for bb in 0..a {
            out[bb * n + a] = out[a * n + bb];
        }
    }
}

/// [`predict_first`] on fixed-size arrays (every loop over N unrolled): U = A R by
/// row operations; without few diagonals, transposed as the runtime path does.
#[inline(always)]
fn fixed_first<const N: usize>(u: &mut [[f64; N]; N], r: &[[f64; N]; N], e: &SparseRows) {
    if let Some(dia) = &e.diagonals {
        // U row by row: R_i + E_i,i+d R_i+d over the diagonals d ascending — the
        // non-zeros' terms in column order, as below (an entry off the pattern adds
        // 0·R, which leaves the sum) — built in registers, with no copy of R first.
        for (i, ui) in u.iter_mut().enumerate() {
            let mut w = r[i];
            for (&d, vals) in dia.offsets.iter().zip(dia.values.chunks_exact(N)) {
                let k = i as isize + d;
                if (0..N as isize).contains(&k) {
                    let (v, rk) = (vals[i], &r[k as usize]);
                    for j in 0..N {
                        w[j] += v * rk[j];
                    }
                }
            }
            *ui = w;
        }
        return;
    }
    // U = R, then + E_ik R_k for the non-zeros in order (sorted by row and column,
    // so each row's terms are added as the row loop would): one flat loop, no
    // per-row slicing.
    *u = *r;
    for &(i, k, v) in &e.nz {
        let (ui, rk) = (&mut u[i], &r[k]);
        for j in 0..N {
            ui[j] += v * rk[j];
        }
    }
    // As in `predict_cov`'s runtime branch: transpose, then row b of A·Uᵀ.
    for i in 0..N {
        for j in i + 1..N {
            let x = u[i][j];
            u[i][j] = u[j][i];
            u[j][i] = x;
        }
    }
}

/// [`predict_second`] on fixed-size arrays: when E has few diagonals, the rows of
/// U Aᵀ by one whole-row operation per diagonal, else the rows of A·Uᵀ.
#[inline(always)]
fn fixed_second<const N: usize>(
    out: &mut [[f64; N]; N],
    u: &[[f64; N]; N],
    e: &SparseRows,
    b: &[[f64; N]; N],
    symmetric: bool,
) {
    if let Some(dia) = &e.diagonals {
        // Row a of U Aᵀ directly: (U Aᵀ)_ab = U_ab + Σ_d E_b,b+d U_a,b+d over the
        // diagonals d ascending — the terms, in the order, of the transposing path
        // below; then + B and the upper triangle mirrored.
        // Row a padded with zeros (N ≤ 12), so each diagonal is a whole-row operation:
        // an entry whose b + d falls outside adds 0·0.
        for a in 0..N {
            let ua = &u[a];
            let mut w = *ua;
            for (&d, vals) in dia.offsets.iter().zip(dia.values.chunks_exact(N)) {
                add_shifted(&mut w, vals.try_into().expect("N"), ua, d);
            }
            let b_row = &b[a];
            for j in 0..N {
                w[j] += b_row[j];
            }
            out[a] = w;
        }
        if symmetric {
            mirror(out, true);
        }
        return;
    }
    // Whole rows (fixed length, so unrolled): the entries right of the diagonal are
    // overwritten by the mirror below.
    for bb in 0..N {
        let mut w = u[bb];
        for &(_, c, v) in e.row(bb) {
            let uc = &u[c];
            for a in 0..N {
                w[a] += v * uc[a];
            }
        }
        let bb_row = &b[bb];
        for a in 0..N {
            w[a] += bb_row[a];
        }
        out[bb] = w;
    }
    if symmetric {
        mirror(out, false);
    }
}

/// Copies the upper triangle onto the lower (`from_upper`), or the lower onto the upper.
#[inline(always)]
pub(crate) fn mirror<const N: usize>(m: &mut [[f64; N]; N], from_upper: bool) {
    if from_upper {
        for a in 1..N {
            for b in 0..a {
                m[a][b] = m[b][a];
            }
        }
    } else {
        for a in 1..N {
            for b in 0..a {
                m[b][a] = m[a][b];
            }
        }
    }
}

/// View the first N·N entries of a row-major slice as an N×N array (N > 0).
#[inline(always)]
pub fn mat<const N: usize>(v: &[f64]) -> &[[f64; N]; N] {
    v[..N * N].as_chunks::<N>().0.try_into().expect("N×N")
}

/// Mutable [`mat`].
#[inline(always)]
pub fn mat_mut<const N: usize>(v: &mut [f64]) -> &mut [[f64; N]; N] {
    v[..N * N].as_chunks_mut::<N>().0.try_into().expect("N×N")
}

/// In-place Cholesky factorisation of the symmetric positive-definite m×m matrix `q`
/// (lower triangle holds L on success). Returns false if q is not positive definite.
#[inline(always)]
pub fn cholesky(q: &mut [f64], m: usize) -> bool {
    for j in 0..m {
        let mut d = q[j * m + j];
        for k in 0..j {
            d -= q[j * m + k] * q[j * m + k];
        }
        if !(d > 0.0) || !d.is_finite() {
            return false;
        }
        let d = d.sqrt();
        q[j * m + j] = d;
        for i in j + 1..m {
            let mut s = q[i * m + j];
            for k in 0..j {
                s -= q[i * m + k] * q[j * m + k];
            }
            q[i * m + j] = s / d;
        }
    }
    true
}

/// Solve L Lᵀ X = S in place for X (m×p), with L from [`cholesky`].
#[inline(always)]
pub fn cholesky_solve(l: &[f64], x: &mut [f64], m: usize, p: usize) {
    solve_lower(l, x, m, p);
    // backward: Lᵀ X = Y
    for i in (0..m).rev() {
        for k in i + 1..m {
            let lki = l[k * m + i];
            let (head, tail) = x.split_at_mut(k * p);
            let xk = &tail[..p];
            for (xi, &xkj) in head[i * p..i * p + p].iter_mut().zip(xk) {
                *xi -= lki * xkj;
            }
        }
        let d = l[i * m + i];
        for v in &mut x[i * p..i * p + p] {
            *v /= d;
        }
    }
}

/// The inverse of a symmetric positive-definite m×m matrix, by its Cholesky factor;
/// None when it is not positive definite (made once per result, not per step).
pub fn inverse_spd(a: &[f64], m: usize) -> Option<Vec<f64>> {
    let mut l = a.to_vec();
    if !cholesky(&mut l, m) {
        return None;
    }
    let mut x = vec![0.0; m * m];
    for i in 0..m {
        x[i * m + i] = 1.0;
    }
    cholesky_solve(&l, &mut x, m, m);
    Some(x)
}

/// Solve L Y = S in place for Y (m×p), L lower triangular (the lower triangle of `l`,
/// as [`cholesky`] leaves it): Y = L⁻¹ S, e.g. S whitened by its covariance's factor.
#[inline(always)]
pub fn solve_lower(l: &[f64], x: &mut [f64], m: usize, p: usize) {
    for i in 0..m {
        for k in 0..i {
            let lik = l[i * m + k];
            let (head, tail) = x.split_at_mut(i * p);
            let xk = &head[k * p..k * p + p];
            for (xi, &xkj) in tail[..p].iter_mut().zip(xk) {
                *xi -= lik * xkj;
            }
        }
        let d = l[i * m + i];
        for v in &mut x[i * p..i * p + p] {
            *v /= d;
        }
    }
}

/// y (r) = a (r×k) · x (k).
#[inline(always)]
pub fn mul_vec(y: &mut [f64], a: &[f64], x: &[f64], r: usize, k: usize) {
    let x = &x[..k];
    for i in 0..r {
        let ai = &a[i * k..i * k + k];
        let mut s = 0.0;
        for l in 0..k {
            s += ai[l] * x[l];
        }
        y[i] = s;
    }
}

/// Largest relative entry-wise difference max|a−b| / max|a| (0 if both are zero).
pub fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let mut num: f64 = 0.0;
    let mut den: f64 = 0.0;
    for (x, y) in a.iter().zip(b) {
        num = num.max((x - y).abs());
        den = den.max(x.abs());
    }
    if den == 0.0 {
        if num == 0.0 { 0.0 } else { f64::INFINITY }
    } else {
        num / den
    }
}

/// Largest difference of two covariances relative to their diagonal scale:
/// max_ij |a_ij − b_ij| / sqrt(b_ii b_jj) (entries with a zero scale must be equal).
pub fn cov_rel_diff(a: &[f64], b: &[f64], n: usize) -> f64 {
    let mut worst: f64 = 0.0;
    for i in 0..n {
        for j in 0..n {
            let d = (a[i * n + j] - b[i * n + j]).abs();
            let scale = (b[i * n + i] * b[j * n + j]).abs().sqrt();
            let r = if scale > 0.0 {
                d / scale
            } else if d == 0.0 {
                0.0
            } else {
                f64::INFINITY
            };
            worst = worst.max(r);
        }
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dense row-major n×n matrix with entries f(i, j).
    fn dense_of(n: usize, f: impl Fn(usize, usize) -> f64) -> Vec<f64> {
        (0..n * n).map(|x| f(x / n, x % n)).collect()
    }

    #[test]
    fn cholesky_solves_a_known_system() {
        // q = [[4, 2], [2, 3]]; q x = s for s = [[2, 8], [1, 7]] (columns are RHS)
        let mut q = vec![4.0, 2.0, 2.0, 3.0];
        assert!(cholesky(&mut q, 2));
        let mut x = vec![2.0, 8.0, 1.0, 7.0];
        cholesky_solve(&q, &mut x, 2, 2);
        // check q·x = s
        let qq = [4.0, 2.0, 2.0, 3.0];
        let mut s = vec![0.0; 4];
        mul(&mut s, &qq, &x, 2, 2, 2);
        for (a, b) in s.iter().zip([2.0, 8.0, 1.0, 7.0]) {
            assert!((a - b).abs() < 1e-14, "{s:?}");
        }
    }

    /// The runtime-dimension prediction by diagonals gives the transposing path's
    /// bits, and both equal A R Aᵀ + B written plainly.
    #[test]
    fn prediction_by_diagonals_equals_the_transposing_path_and_the_plain_product() {
        use crate::numerics::lanes::Scalar;
        use nalgebra::DMatrix;
        let n = 14;
        let f = |i: usize, j: usize, s: f64| ((i * 31 + j * 17) as f64 * 0.37 + s).sin();
        // R symmetric positive definite-ish, B symmetric: exactly symmetric entries.
        let r: Vec<f64> = (0..n * n)
            .map(|x| {
                let (i, j) = (x / n, x % n);
                let (a, b) = (i.min(j), i.max(j));
                f(a, b, 0.1) + if i == j { 3.0 } else { 0.0 }
            })
            .collect();
        let b: Vec<f64> = (0..n * n)
            .map(|x| f((x / n).min(x % n), (x / n).max(x % n), 0.7) * 1e-3)
            .collect();
        // Offsets −2, 0 and 1, with holes in the pattern.
        let pattern: Vec<(usize, usize)> = (0..n)
            .flat_map(|i| {
                let mut v = vec![(i, i)];
                if i + 1 < n && i % 3 != 1 {
                    v.push((i, i + 1));
                }
                if i >= 2 && i % 4 != 0 {
                    v.push((i, i - 2));
                }
                v
            })
            .collect();
        let mut e = SparseRows::with_pattern(n, pattern);
        assert_eq!(
            e.diagonals.as_ref().map(|d| d.offsets.clone()),
            Some(vec![-2, 0, 1])
        );
        e.set_values(&dense_of(n, |i, j| f(i, j, 2.3) * 0.01), |v, _| v);
        let mut by_diag = vec![0.0; n * n];
        let mut work = predict_work(n);
        predict_cov::<0, Scalar>(&mut by_diag, &r, &e, &b, &mut work, n);
        let mut transposing = vec![0.0; n * n];
        mul_transpose_into::<Scalar>(&mut work[..n * n], &r, &e, n);
        second_half::<Scalar>(&mut transposing, &work[..n * n], &e, &b, n);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&by_diag), bits(&transposing));
        let mut a = DMatrix::<f64>::identity(n, n);
        for &(i, j, v) in &e.nz {
            a[(i, j)] += v;
        }
        let rr = DMatrix::from_row_slice(n, n, &r);
        let plain = &a * rr * a.transpose() + DMatrix::from_row_slice(n, n, &b);
        let got = DMatrix::from_row_slice(n, n, &by_diag);
        assert!(
            (&got - &plain).amax() < 1e-14 * plain.amax(),
            "{:e}",
            (got - plain).amax()
        );
        // A pattern with more than MAX_DIAGONALS diagonals takes the transposing path.
        let dense = SparseRows::with_pattern(
            n,
            (0..n).flat_map(|i| (0..n).map(move |j| (i, j))).collect(),
        );
        assert!(dense.diagonals.is_none());
        // The fixed-size path (N ≤ 12): by diagonals, the bits of its transposing path.
        const M: usize = 11;
        let sub = |v: &[f64]| -> Vec<f64> { (0..M * M).map(|x| v[(x / M) * n + x % M]).collect() };
        let (r, b) = (sub(&r), sub(&b));
        let mut e = SparseRows::with_pattern(
            M,
            e.nz.iter()
                .filter(|&&(i, j, _)| i < M && j < M)
                .map(|&(i, j, _)| (i, j))
                .collect(),
        );
        e.set_values(&dense_of(n, |i, j| f(i, j, 2.3) * 0.01), |v, _| v);
        let mut transposing_e = e.clone();
        transposing_e.diagonals = None;
        let (mut by_diag, mut transposing) = (vec![0.0; M * M], vec![0.0; M * M]);
        predict_cov::<M, Scalar>(&mut by_diag, &r, &e, &b, &mut work, M);
        predict_cov::<M, Scalar>(&mut transposing, &r, &transposing_e, &b, &mut work, M);
        assert_eq!(bits(&by_diag), bits(&transposing));
        assert!(by_diag.iter().all(|x| x.is_finite()) && by_diag[0] != r[0]);
    }

    /// M x by diagonals gives the bits of the plain loop over the non-zeros, for a
    /// pattern with holes and signed zeros among the values.
    #[test]
    fn matrix_vector_product_by_diagonals_equals_the_row_loop() {
        use crate::numerics::lanes::Scalar;
        let n = 11;
        let pattern: Vec<(usize, usize)> = (0..n)
            .flat_map(|i| {
                let mut v = vec![(i, i)];
                if i + 3 < n && i % 2 == 0 {
                    v.push((i, i + 3));
                }
                if i >= 1 && i % 3 != 0 {
                    v.push((i, i - 1));
                }
                v
            })
            .collect();
        let mut m = SparseRows::with_pattern(n, pattern);
        assert_eq!(
            m.diagonals.as_ref().map(|d| d.offsets.clone()),
            Some(vec![-1, 0, 3])
        );
        let values = dense_of(n, |i, j| match (i + j) % 5 {
            0 => -0.0,
            1 => 0.0,
            _ => ((i * 7 + j * 3) as f64 * 0.41).cos(),
        });
        m.set_values(&values, |v, _| v);
        let x: Vec<f64> = (0..n)
            .map(|i| {
                if i % 4 == 0 {
                    -0.0
                } else {
                    (i as f64).sqrt() - 1.5
                }
            })
            .collect();
        let mut by_diag = vec![f64::NAN; n];
        m.mul_vec::<Scalar>(&mut by_diag, &x, n);
        let mut plain = vec![0.0; n];
        for &(i, j, v) in &m.nz {
            plain[i] += v * x[j];
        }
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&by_diag), bits(&plain));
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            let mut avx = vec![f64::NAN; n];
            // SAFETY: the CPU has AVX2 (checked above).
            unsafe { avx2_mul_vec(&m, &mut avx, &x, n) };
            assert_eq!(bits(&avx), bits(&plain));
        }
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn avx2_mul_vec(m: &SparseRows, y: &mut [f64], x: &[f64], n: usize) {
        m.mul_vec::<crate::numerics::lanes::Avx2>(y, x, n);
    }

    #[test]
    fn cholesky_rejects_indefinite() {
        let mut q = vec![1.0, 2.0, 2.0, 1.0];
        assert!(!cholesky(&mut q, 2));
        let mut z = vec![0.0];
        assert!(!cholesky(&mut z, 1));
    }
}
