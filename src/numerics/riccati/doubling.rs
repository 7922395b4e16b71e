//! The stationary solution r∞ of the filter's Riccati recursion (2.1)–(2.7) for a
//! time-invariant model, by the structure-preserving doubling algorithm (SDA): the
//! analysis's steady-state shortcut.
//!
//! The predicted covariance r is stationary when
//!     r = A r Aᵀ − A r Cᵀ (C r Cᵀ + Rv)⁻¹ C r Aᵀ + B,
//! a DARE in the dual (control) form with A_c = Aᵀ, B_c = Cᵀ, R_c = Rv, Q_c = B. SDA:
//!     A₀ = Aᵀ, G₀ = Cᵀ Rv⁻¹ C, H₀ = B,  W = I + G_k H_k,
//!     A_{k+1} = A_k W⁻¹ A_k,  G_{k+1} = G_k + A_k W⁻¹ G_k A_kᵀ,
//!     H_{k+1} = H_k + A_kᵀ H_k W⁻¹ A_k  →  r∞ (quadratic convergence).

use nalgebra::DMatrix;

/// The most doublings [`dare_doubling`] ever takes (2¹⁰⁰ steps of the recursion).
pub const MAX_DOUBLINGS: u32 = 100;

/// The doublings worth taking for an analysis of D steps: after k of them the iterate
/// is the recursion's covariance after 2^k steps (from zero), and one that has not
/// settled by 16·D steps is not reached within D either (a geometric convergence
/// within D steps to the steady-state test's 1e-13 is, by 16·D, far below the
/// doubling's 1e-15). Each doubling costs about 2N³; without this bound a model with
/// no stationary solution (an unmeasured integrator) took all 100 — 1.2 s at N = 200
/// for an analysis of one step.
pub fn doublings_for(steps: u64) -> u32 {
    let log2 = u64::BITS - steps.max(1).saturating_sub(1).leading_zeros(); // ⌈log₂ D⌉
    (log2 + 4).min(MAX_DOUBLINGS)
}

/// Why [`dare_doubling`] gives no r∞.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoStationary {
    /// Rv singular, a singular step or a divergence: no stabilising solution found.
    Failed,
    /// Still changing after `max_doublings`: there may be none, or the recursion gets
    /// there later than the steps an analysis takes (it reports no steady state then).
    NotSettled,
}

/// r∞ (N×N, row-major), or why there is none within `max_doublings`.
pub fn dare_doubling(
    a: &[f64],
    c_nz: &[(usize, usize, f64)],
    b: &[f64],
    rv: &[f64],
    n: usize,
    nm: usize,
    max_doublings: u32,
) -> Result<Vec<f64>, NoStationary> {
    let a_f = DMatrix::from_row_slice(n, n, a);
    let mut c = DMatrix::zeros(nm, n);
    for &(j, i, v) in c_nz {
        c[(j, i)] = v;
    }
    let rv = DMatrix::from_row_slice(nm, nm, rv);
    let rv_inv_c = rv.clone().cholesky().ok_or(NoStationary::Failed)?.solve(&c);
    let mut ak = a_f.transpose();
    let mut gk = c.transpose() * rv_inv_c;
    gk = (&gk + gk.transpose()) * 0.5;
    let mut hk = DMatrix::from_row_slice(n, n, b);
    let id = DMatrix::<f64>::identity(n, n);
    for _ in 0..max_doublings {
        let w = &id + &gk * &hk;
        let lu = w.lu();
        let w_a = lu.solve(&ak).ok_or(NoStationary::Failed)?;
        let w_g = lu.solve(&gk).ok_or(NoStationary::Failed)?;
        let a_next = &ak * &w_a;
        let mut g_next = &gk + &ak * &w_g * ak.transpose();
        let mut h_next = &hk + ak.transpose() * &hk * &w_a;
        g_next = (&g_next + g_next.transpose()) * 0.5;
        h_next = (&h_next + h_next.transpose()) * 0.5;
        if !h_next.iter().all(|x| x.is_finite()) || !a_next.iter().all(|x| x.is_finite()) {
            return Err(NoStationary::Failed);
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
            return Ok(out);
        }
    }
    Err(NoStationary::NotSettled)
}
