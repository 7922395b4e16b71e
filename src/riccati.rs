//! The stationary solution of the filter's Riccati recursion for a time-invariant
//! model, by the structure-preserving doubling algorithm (SDA). Used by the
//! steady-state shortcut (analysis) and checked against scipy's DARE in the tests.
//!
//! The predicted covariance r of (2.1)–(2.7) is stationary when
//!     r = A r Aᵀ − A r Cᵀ (C r Cᵀ + Rv)⁻¹ C r Aᵀ + B,
//! a DARE in the dual (control) form with A_c = Aᵀ, B_c = Cᵀ, R_c = Rv, Q_c = B. SDA:
//!     A₀ = Aᵀ, G₀ = Cᵀ Rv⁻¹ C, H₀ = B,  W = I + G_k H_k,
//!     A_{k+1} = A_k W⁻¹ A_k,  G_{k+1} = G_k + A_k W⁻¹ G_k A_kᵀ,
//!     H_{k+1} = H_k + A_kᵀ H_k W⁻¹ A_k  →  r∞ (quadratic convergence).

use nalgebra::DMatrix;

/// r∞ (N×N, row-major), or None when no stabilising solution is found
/// (Rv singular, divergence, or no convergence in 100 doublings).
pub fn dare_doubling(
    a: &[f64],
    c_nz: &[(usize, usize, f64)],
    b: &[f64],
    rv: &[f64],
    n: usize,
    nm: usize,
) -> Option<Vec<f64>> {
    let a_f = DMatrix::from_row_slice(n, n, a);
    let mut c = DMatrix::zeros(nm, n);
    for &(j, i, v) in c_nz {
        c[(j, i)] = v;
    }
    let rv = DMatrix::from_row_slice(nm, nm, rv);
    let rv_inv_c = rv.clone().cholesky()?.solve(&c);
    let mut ak = a_f.transpose();
    let mut gk = c.transpose() * rv_inv_c;
    gk = (&gk + gk.transpose()) * 0.5;
    let mut hk = DMatrix::from_row_slice(n, n, b);
    let id = DMatrix::<f64>::identity(n, n);
    for _ in 0..100 {
        let w = &id + &gk * &hk;
        let lu = w.lu();
        let w_a = lu.solve(&ak)?;
        let w_g = lu.solve(&gk)?;
        let a_next = &ak * &w_a;
        let mut g_next = &gk + &ak * &w_g * ak.transpose();
        let mut h_next = &hk + ak.transpose() * &hk * &w_a;
        g_next = (&g_next + g_next.transpose()) * 0.5;
        h_next = (&h_next + h_next.transpose()) * 0.5;
        if !h_next.iter().all(|x| x.is_finite()) || !a_next.iter().all(|x| x.is_finite()) {
            return None;
        }
        let change = (&h_next - &hk).amax();
        let scale = h_next.amax();
        ak = a_next;
        gk = g_next;
        hk = h_next;
        if change <= 1e-15 * scale || scale == 0.0 {
            // row-major out
            let mut out = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..n {
                    out[i * n + j] = hk[(i, j)];
                }
            }
            return Some(out);
        }
    }
    None
}

use crate::linalg::{cholesky, cholesky_solve, mul, mul_abt_sym, predict_cov};

/// Work buffers and outputs of one step of the filter's covariance recursion
/// (2.1)–(2.7) in Joseph form. Allocated once; `step` allocates nothing.
#[derive(Clone, Debug)]
pub struct JosephStep {
    n: usize,
    tmp: Vec<f64>,
    /// r_k, the predicted (a-priori) covariance (2.1).
    pub r_pred: Vec<f64>,
    s_cr: Vec<f64>,
    /// After `step`: the Cholesky factor of q_k (lower triangle), nm_k×nm_k.
    pub q_chol: Vec<f64>,
    x: Vec<f64>,
    mm: Vec<f64>,
    e: Vec<f64>,
    /// p_k, N×nm_k (2.5), for the measurements used at this step.
    pub gain: Vec<f64>,
    /// I − p_k C (N×N).
    pub h: Vec<f64>,
}

impl JosephStep {
    pub fn new(n: usize, nm: usize) -> Self {
        JosephStep {
            n,
            tmp: vec![0.0; n * n],
            r_pred: vec![0.0; n * n],
            s_cr: vec![0.0; nm * n],
            q_chol: vec![0.0; nm * nm],
            x: vec![0.0; nm * n],
            mm: vec![0.0; n * n],
            e: vec![0.0; n * nm],
            gain: vec![0.0; n * nm],
            h: vec![0.0; n * n],
        }
    }

    /// One step: from R_{k−1} (`big_r`, overwritten with R_k), A_{k−1} = I + E given
    /// as the non-zeros of E = a(t_{k−1})Δt (row, col, value), B_{k−1}, the
    /// measurements' non-zeros of C as (row, col, value) with rows 0..nm, and Rv_k
    /// (nm×nm). Returns false if q_k is not positive definite.
    ///
    /// ```text
    /// r = A R Aᵀ + B                       (2.1)
    /// q = C r Cᵀ + Rv                      (2.3)
    /// p = r Cᵀ q⁻¹   (Cholesky solve)      (2.5)
    /// R = h r hᵀ + p Rv pᵀ,  h = I − pC    (2.7), Joseph form
    /// ```
    /// computed as M = h r = r − p S (S = C r), h r hᵀ = M − M Cᵀ pᵀ,
    /// R = M + (p Rv − M Cᵀ) pᵀ, upper triangle mirrored so R stays symmetric.
    /// `n` is the state dimension (pass a compile-time constant where possible: the
    /// caller's const-generic N lets the compiler unroll every loop here).
    #[inline(always)]
    pub fn step(
        &mut self,
        n: usize,
        big_r: &mut [f64],
        e_nz: &[(usize, usize, f64)],
        big_b: &[f64],
        c_nz: &[(usize, usize, f64)],
        rv: &[f64],
        nm: usize,
    ) -> bool {
        debug_assert_eq!(n, self.n);
        predict_cov(&mut self.r_pred, big_r, e_nz, big_b, &mut self.tmp, n);
        if nm == 0 {
            big_r[..n * n].copy_from_slice(&self.r_pred[..n * n]);
            for i in 0..n {
                for j in 0..n {
                    self.h[i * n + j] = if i == j { 1.0 } else { 0.0 };
                }
            }
            return true;
        }
        let s_cr = &mut self.s_cr[..nm * n];
        s_cr.fill(0.0);
        for &(j, i, c) in c_nz {
            for (s, r) in s_cr[j * n..j * n + n]
                .iter_mut()
                .zip(&self.r_pred[i * n..i * n + n])
            {
                *s += c * r;
            }
        }
        let q = &mut self.q_chol[..nm * nm];
        q.copy_from_slice(&rv[..nm * nm]);
        for &(l, i, c) in c_nz {
            for j in 0..nm {
                q[j * nm + l] += c * s_cr[j * n + i];
            }
        }
        if !cholesky(q, nm) {
            return false;
        }
        let x = &mut self.x[..nm * n];
        x.copy_from_slice(s_cr);
        cholesky_solve(q, x, nm, n);
        let gain = &mut self.gain[..n * nm];
        for i in 0..n {
            for j in 0..nm {
                gain[i * nm + j] = x[j * n + i];
            }
        }
        mul(&mut self.mm, gain, s_cr, n, nm, n);
        for (m, r) in self.mm.iter_mut().zip(&self.r_pred) {
            *m = r - *m;
        }
        let e = &mut self.e[..n * nm];
        mul(e, gain, rv, n, nm, nm);
        for &(l, i, c) in c_nz {
            for a in 0..n {
                e[a * nm + l] -= c * self.mm[a * n + i];
            }
        }
        mul_abt_sym(big_r, e, gain, None, n, nm);
        for i in 0..n {
            for j in i..n {
                let v = big_r[i * n + j] + 0.5 * (self.mm[i * n + j] + self.mm[j * n + i]);
                big_r[i * n + j] = v;
                big_r[j * n + i] = v;
            }
        }
        for i in 0..n {
            for j in 0..n {
                self.h[i * n + j] = if i == j { 1.0 } else { 0.0 };
            }
        }
        for &(l, j, c) in c_nz {
            for i in 0..n {
                self.h[i * n + j] -= gain[i * nm + l] * c;
            }
        }
        true
    }
}
