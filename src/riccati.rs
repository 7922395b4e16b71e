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
