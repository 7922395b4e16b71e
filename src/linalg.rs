//! Small dense kernels on row-major flat slices, written so that the compiler
//! vectorises them and, when called with a compile-time dimension, unrolls them.
//! No allocation; callers own the buffers.

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

/// out = A R Aᵀ + B for A = I + E with E sparse, given as (row, col, value), and R
/// symmetric: the prediction (2.1) in O(nnz(E)·N) instead of O(N³). With T = A R,
/// A R Aᵀ = A Tᵀ, so both products are row operations. `t` is an N×N work buffer.
/// The result is symmetrised so it stays exactly symmetric.
#[inline(always)]
pub fn predict_cov(
    out: &mut [f64],
    r: &[f64],
    e_nz: &[(usize, usize, f64)],
    b: &[f64],
    t: &mut [f64],
    n: usize,
) {
    let (r, b, t) = (&r[..n * n], &b[..n * n], &mut t[..n * n]);
    // T = A R = R + E R
    t.copy_from_slice(r);
    for &(i, k, v) in e_nz {
        let src = &r[k * n..k * n + n];
        let dst = &mut t[i * n..i * n + n];
        for j in 0..n {
            dst[j] += v * src[j];
        }
    }
    // out = Tᵀ, then out = A Tᵀ = Tᵀ + E Tᵀ (rows of Tᵀ are read from `out` before any
    // row of `out` is changed: use B's slot afterwards) — so build Tᵀ in `out` first.
    let out = &mut out[..n * n];
    for i in 0..n {
        for j in 0..n {
            out[i * n + j] = t[j * n + i];
        }
    }
    // t := Tᵀ (copy), out := Tᵀ + B, then out += E Tᵀ row by row.
    t.copy_from_slice(out);
    for (o, x) in out.iter_mut().zip(b) {
        *o += x;
    }
    for &(i, k, v) in e_nz {
        let src = &t[k * n..k * n + n];
        let dst = &mut out[i * n..i * n + n];
        for j in 0..n {
            dst[j] += v * src[j];
        }
    }
    for i in 0..n {
        for j in i + 1..n {
            let m = 0.5 * (out[i * n + j] + out[j * n + i]);
            out[i * n + j] = m;
            out[j * n + i] = m;
        }
    }
}

/// y = M x for a sparse M given as (row, col, value).
#[inline(always)]
pub fn sparse_mul_vec(y: &mut [f64], m_nz: &[(usize, usize, f64)], x: &[f64], n: usize) {
    y[..n].fill(0.0);
    for &(i, j, v) in m_nz {
        y[i] += v * x[j];
    }
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
    // forward: L Y = S
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

    #[test]
    fn cholesky_rejects_indefinite() {
        let mut q = vec![1.0, 2.0, 2.0, 1.0];
        assert!(!cholesky(&mut q, 2));
        let mut z = vec![0.0];
        assert!(!cholesky(&mut z, 1));
    }
}
