//! The plan (METHOD §1.8): the deterministic part, the same for every run — the mean
//! (3.3), the Riccati recursion (2.1)–(2.7) with the schedule, the bound (3.16)–(3.19)
//! and the open-loop covariance — advanced once per step, and the records it writes.
//! With a truth (a mismatched filter), the world the runs imitate is the truth's: the
//! plan steps the mismatch's recursion beside (its actual error covariance, and the
//! truth's mean and inputs for the records), and the filter stays the model's.

use crate::analysis::inputs::{Inputs, time_err};
use crate::analysis::mismatch::pass::Pass;
use crate::analysis::overflowed;
use crate::error::Error;
use crate::model::compile::CompiledModel;
use crate::numerics::linalg::{cholesky, cholesky_solve, mul, mul_abt_sym, mul_vec};

/// Dimensions shared by the plan and the blocks: N, n, and the world's L (columns of
/// b, sources of F) and M (sources of Φ).
#[derive(Clone, Copy, Debug)]
pub(super) struct Dims {
    pub(super) n: usize,
    pub(super) nm: usize,
    pub(super) nl: usize,
    pub(super) ms: usize,
}

/// Layout of one step's inputs in a chunk (offsets into a flat f64 record). The
/// filter's A and u are the model's; the world's (`wa`, `wu`, and bΔt, Γ, y) are the
/// truth's where there is one, else the same entries as the filter's.
#[derive(Clone, Copy, Debug)]
pub(super) struct Layout {
    pub(super) a: usize,      // A_{k−1}, N×N
    pub(super) u: usize,      // u_{k−1}Δt, N
    pub(super) wa: usize,     // the world's A_{k−1}, N×N
    pub(super) wu: usize,     // the world's u_{k−1}Δt, N
    pub(super) bd: usize,     // the world's b_{k−1}Δt, N×L
    pub(super) gamma: usize,  // the world's Γ_k, n×M
    pub(super) gain: usize,   // p_k, N×n (zero columns for unavailable measurements)
    pub(super) avail: usize,  // n flags (1.0 / 0.0)
    pub(super) y: usize,      // the world's mean y_k, N
    pub(super) r_chol: usize, // Cholesky factor of R_k, N×N (valid if flag), 1/L_ii on the diagonal
    pub(super) q_chol: usize, // Cholesky factor of q_k, masked, n×n, 1/L_ii on the diagonal
    pub(super) flags: usize,  // [R_k factor valid, q_k factor valid, measurements available]
    pub(super) size: usize,
}

impl Layout {
    /// The layout; `world`: the world is a truth of its own (its A and u stored too).
    pub(super) fn new(d: Dims, world: bool) -> Self {
        let mut o = 0;
        let mut take = |len: usize| {
            let at = o;
            o += len;
            at
        };
        let a = take(d.n * d.n);
        let u = take(d.n);
        let (wa, wu) = if world {
            (take(d.n * d.n), take(d.n))
        } else {
            (a, u)
        };
        let bd = take(d.n * d.nl);
        let gamma = take(d.nm * d.ms);
        let gain = take(d.n * d.nm);
        let avail = take(d.nm);
        let y = take(d.n);
        let r_chol = take(d.n * d.n);
        let q_chol = take(d.nm * d.nm);
        let flags = take(3);
        Layout {
            a,
            u,
            wa,
            wu,
            bd,
            gamma,
            gain,
            avail,
            y,
            r_chol,
            q_chol,
            flags,
            size: o,
        }
    }
}

/// Per-step sums a block returns, per step: Σ(Y−y)²_i, Σe²_i, Σe_i (N each),
/// Σ(ΓΦ)²_j (n), Σ NEES, Σ NIS.
#[derive(Clone, Copy, Debug)]
pub(super) struct SumLayout {
    pub(super) apriori: usize,
    pub(super) filt2: usize,
    pub(super) filt1: usize,
    pub(super) meas2: usize,
    pub(super) nees: usize,
    pub(super) nis: usize,
    pub(super) size: usize,
}

impl SumLayout {
    pub(super) fn new(d: Dims) -> Self {
        SumLayout {
            apriori: 0,
            filt2: d.n,
            filt1: 2 * d.n,
            meas2: 3 * d.n,
            nees: 3 * d.n + d.nm,
            nis: 3 * d.n + d.nm + 1,
            size: 3 * d.n + d.nm + 2,
        }
    }
}

/// The truth of a mismatched filter, as the plan steps it.
struct World<'m> {
    truth: &'m CompiledModel,
    truth_is_model: bool,
    pass: Pass,
}

/// The deterministic part, advanced once per step for all runs: time functions, the
/// mean (3.3), the Riccati recursion (2.1)–(2.7) with the schedule, the bound
/// (3.16)–(3.19) and the open-loop covariance.
pub(super) struct Plan<'m> {
    m: &'m CompiledModel,
    world: Option<World<'m>>,
    /// The world's open-loop variances diag P^Y_k (the model's, or the truth's).
    pub(super) open: Vec<f64>,
    /// With a truth: the actual error variances and means of the filter (the
    /// mismatch's recursion) at step k; empty without.
    pub(super) actual: Vec<f64>,
    pub(super) bias: Vec<f64>,
    pub(super) d: Dims,
    pub(super) dt: f64,
    /// A = I + aΔt (dense here), uΔt, bΔt, B, Γ, Rv, ζ: the analysis' inputs.
    pub(super) inp: Inputs,
    schedule: Option<crate::model::schedule::Schedules>,
    big_a: Vec<f64>,
    pub(super) y: Vec<f64>,
    pub(super) big_r: Vec<f64>,
    pub(super) p_y: Vec<f64>,
    pub(super) chi: Vec<f64>,
    gain: Vec<f64>,
    avail: Vec<bool>,
    // work buffers
    tmp_nn: Vec<f64>,
    tmp_nn2: Vec<f64>,
    r_pred: Vec<f64>,
    s_cr: Vec<f64>,
    q: Vec<f64>,
    x_solve: Vec<f64>,
    /// p Rv (n × nm), for the Joseph form's p Rv pᵀ.
    prv: Vec<f64>,
    xi: Vec<f64>,
    tmp_n: Vec<f64>,
    /// Whether the next step is the first of this run (from the start, or from a kept
    /// state): its inputs are then evaluated whole.
    fresh: bool,
}

impl<'m> Plan<'m> {
    /// The plan of the filter designed on `m`, in the world `truth` (a truth model
    /// and whether it is one of its own, `truth.model`) or, without, in `m`'s.
    pub(super) fn new(
        m: &'m CompiledModel,
        truth: Option<(&'m CompiledModel, bool)>,
        steps: u64,
    ) -> Self {
        let n = m.n_states();
        let w = truth.map_or(m, |t| t.0);
        let d = Dims {
            n,
            nm: m.n_measurements(),
            nl: w.b.cols,
            ms: w.noise.sources(),
        };
        let mut big_r = vec![0.0; n * n];
        for i in 0..n {
            big_r[i * n + i] = m.eta0[i] * m.eta0[i];
        }
        let dt = (m.t_end - m.t0) / steps as f64;
        let world = truth.map(|(truth, truth_is_model)| World {
            truth,
            truth_is_model,
            // (The filter designed on the truth is the analysis's concern, not the runs'.)
            pass: Pass::new(m, truth, steps, false),
        });
        let with = if world.is_some() { n } else { 0 };
        Plan {
            m,
            world,
            open: vec![0.0; n],
            actual: vec![0.0; with],
            bias: vec![0.0; with],
            d,
            dt,
            inp: Inputs::new(m, n, dt),
            schedule: m.schedule.clone(),
            big_a: vec![0.0; n * n],
            y: m.y0.clone(),
            p_y: big_r.clone(),
            big_r,
            chi: vec![0.0; n],
            gain: vec![0.0; n * d.nm],
            avail: vec![true; d.nm],
            tmp_nn: vec![0.0; n * n],
            tmp_nn2: vec![0.0; n * n],
            r_pred: vec![0.0; n * n],
            s_cr: vec![0.0; d.nm * n],
            q: vec![0.0; d.nm * d.nm],
            x_solve: vec![0.0; d.nm * n],
            prv: vec![0.0; n * d.nm],
            xi: vec![0.0; n],
            tmp_n: vec![0.0; n],
            fresh: true,
        }
    }

    /// Advance to step k and write its record (layout `lay`) into `rec`.
    pub(super) fn step(&mut self, k: u64, lay: &Layout, rec: &mut [f64]) -> Result<(), Error> {
        let Dims { n, nm, nl, ms } = self.d;
        let m = self.m;
        let dt = self.dt;
        let t_k = m.t0 + k as f64 * dt;
        // (1.11)–(1.15): A, uΔt, bΔt at t_{k−1}; Γ at t_k — the analysis' inputs.
        let whole = std::mem::replace(&mut self.fresh, false);
        let a_changed = whole || !self.inp.a_fn.is_constant();
        self.inp.at(m, k, whole)?;
        if a_changed {
            self.inp.dense_a_into(&mut self.big_a);
        }
        // The measurement schedule at step k (time t_k).
        if let Some(sched) = &mut self.schedule {
            sched
                .mask(k, t_k, &mut self.avail)
                .map_err(|p| time_err(&p, k, t_k))?;
        }
        let n_avail = self.avail.iter().filter(|a| **a).count();

        // (3.3) y_k = A y + uΔt
        mul_vec(&mut self.tmp_n, &self.big_a, &self.y, n, n);
        for i in 0..n {
            self.y[i] = self.tmp_n[i] + self.inp.u_dt[i];
        }
        // (2.1) r = A R Aᵀ + B
        mul(&mut self.tmp_nn, &self.big_a, &self.big_r, n, n, n);
        mul_abt_sym(
            &mut self.r_pred,
            &self.tmp_nn,
            &self.big_a,
            Some(&self.inp.big_b),
            n,
            n,
        );
        // S = C r; (2.3) q = S Cᵀ + Rv. An unavailable measurement j gets S_j = 0 and
        // q_jj = 1 with no coupling: its gain column is then exactly zero and the
        // other columns are the Kalman gain of the available measurements alone.
        self.s_cr.fill(0.0);
        for &(j, i, c) in &self.inp.c_nz {
            if self.avail[j] {
                for (s, r) in self.s_cr[j * n..j * n + n]
                    .iter_mut()
                    .zip(&self.r_pred[i * n..i * n + n])
                {
                    *s += c * r;
                }
            }
        }
        self.q.copy_from_slice(&self.inp.rv);
        for &(l, i, c) in &self.inp.c_nz {
            for j in 0..nm {
                self.q[j * nm + l] += c * self.s_cr[j * n + i];
            }
        }
        for j in 0..nm {
            if !self.avail[j] {
                for l in 0..nm {
                    self.q[j * nm + l] = 0.0;
                    self.q[l * nm + j] = 0.0;
                }
                self.q[j * nm + j] = 1.0;
            }
        }
        let q_ok = nm == 0 || cholesky(&mut self.q, nm);
        if !q_ok {
            return Err(crate::analysis::singular(k, t_k));
        }
        // (2.5) pᵀ = q⁻¹ S
        self.x_solve.copy_from_slice(&self.s_cr);
        if nm > 0 {
            cholesky_solve(&self.q, &mut self.x_solve, nm, n);
        }
        for i in 0..n {
            for j in 0..nm {
                self.gain[i * nm + j] = self.x_solve[j * n + i];
            }
        }
        // (2.7) Joseph form R = h r hᵀ + p Rv pᵀ, h = I − pC (available columns only:
        // unavailable gain columns are zero, so they drop out of both terms).
        // h
        for i in 0..n {
            for j in 0..n {
                self.tmp_nn[i * n + j] = if i == j { 1.0 } else { 0.0 };
            }
        }
        for &(l, j, c) in &self.inp.c_nz {
            for i in 0..n {
                self.tmp_nn[i * n + j] -= self.gain[i * nm + l] * c;
            }
        }
        mul(&mut self.tmp_nn2, &self.tmp_nn, &self.r_pred, n, n, n); // h r
        mul_abt_sym(&mut self.big_r, &self.tmp_nn2, &self.tmp_nn, None, n, n); // h r hᵀ
        if nm > 0 {
            mul(&mut self.prv, &self.gain, &self.inp.rv, n, nm, nm);
            mul_abt_sym(&mut self.tmp_nn2, &self.prv, &self.gain, None, n, nm);
            for (r, a) in self.big_r.iter_mut().zip(&self.tmp_nn2) {
                *r += a;
            }
        }
        // P^Y = A P Aᵀ + B
        mul(&mut self.tmp_nn2, &self.big_a, &self.p_y, n, n, n);
        mul_abt_sym(
            &mut self.p_y,
            &self.tmp_nn2,
            &self.big_a,
            Some(&self.inp.big_b),
            n,
            n,
        );
        // Bound (3.18)–(3.19): ξ = |A| χ, χ = |h| ξ + |p| ζ
        for i in 0..n {
            self.xi[i] = (0..n)
                .map(|j| self.big_a[i * n + j].abs() * self.chi[j])
                .sum();
        }
        for i in 0..n {
            let mut s: f64 = (0..n)
                .map(|j| self.tmp_nn[i * n + j].abs() * self.xi[j])
                .sum();
            for j in 0..nm {
                s += self.gain[i * nm + j].abs() * self.inp.zeta[j];
            }
            self.chi[i] = s;
        }
        if !self.big_r.iter().all(|v| v.is_finite()) || !self.y.iter().all(|v| v.is_finite()) {
            return Err(overflowed(
                "the filtered covariance or the mean",
                "system",
                k,
                t_k,
            ));
        }

        // The record for the blocks: the filter's A and u, the world's inputs and mean.
        rec[lay.a..lay.a + n * n].copy_from_slice(&self.big_a);
        rec[lay.u..lay.u + n].copy_from_slice(&self.inp.u_dt);
        if let Some(w) = &mut self.world {
            // The mismatch's step k: the truth's inputs, mean, open-loop and the
            // filter's actual error (its own errors placed at `truth…`).
            let truth_is_model = w.truth_is_model;
            let place = |e| crate::analysis::mismatch::place_in(e, truth_is_model);
            let st = w.pass.step(m, w.truth, k, place)?;
            self.open.copy_from_slice(st.open_var);
            self.actual.copy_from_slice(st.err_var);
            self.bias.copy_from_slice(st.err_mean);
            let ti = w.pass.truth_inputs();
            rec[lay.wa..lay.wa + n * n].copy_from_slice(w.pass.truth_a());
            rec[lay.wu..lay.wu + n].copy_from_slice(&ti.u_dt);
            rec[lay.bd..lay.bd + n * nl].copy_from_slice(&ti.bd);
            rec[lay.gamma..lay.gamma + nm * ms].copy_from_slice(&ti.gamma);
            rec[lay.y..lay.y + n].copy_from_slice(w.pass.truth_mean());
        } else {
            for i in 0..n {
                self.open[i] = self.p_y[i * n + i];
            }
            rec[lay.bd..lay.bd + n * nl].copy_from_slice(&self.inp.bd);
            rec[lay.gamma..lay.gamma + nm * ms].copy_from_slice(&self.inp.gamma);
            rec[lay.y..lay.y + n].copy_from_slice(&self.y);
        }
        rec[lay.gain..lay.gain + n * nm].copy_from_slice(&self.gain);
        for j in 0..nm {
            rec[lay.avail + j] = if self.avail[j] { 1.0 } else { 0.0 };
        }
        let rc = &mut rec[lay.r_chol..lay.r_chol + n * n];
        rc.copy_from_slice(&self.big_r);
        let r_ok = cholesky(rc, n);
        // Reciprocal diagonals: the per-run solves multiply instead of divide.
        if r_ok {
            for i in 0..n {
                rc[i * n + i] = 1.0 / rc[i * n + i];
            }
        }
        let qc = &mut rec[lay.q_chol..lay.q_chol + nm * nm];
        qc.copy_from_slice(&self.q);
        if n_avail > 0 {
            for j in 0..nm {
                qc[j * nm + j] = 1.0 / qc[j * nm + j];
            }
        }
        rec[lay.flags] = if r_ok { 1.0 } else { 0.0 };
        rec[lay.flags + 1] = if n_avail > 0 { 1.0 } else { 0.0 };
        rec[lay.flags + 2] = n_avail as f64;
        Ok(())
    }
}
