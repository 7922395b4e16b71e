//! The mismatched filter's recursion: the design's gains, the truth's world.
//!
//! With x the true state and e = x − x̂ the filter's error, one step of the truth
//! (A^t, u^t, C^t, B^t, Rv^t) and of the filter designed on (A^d, u^d, C^d), whose
//! gain K and h = I − K C^d come from the design's own Riccati step:
//!
//! ```text
//! x_k = A^t x + u^t Δt + w                                       w ~ (0, B^t)
//! ε⁻  = x_k − (A^d x̂ + u^d Δt) = ΔA x + A^d e + Δu + w           ΔA = A^t − A^d, Δu = (u^t − u^d) Δt
//! e_k = h ε⁻ − K (ΔC x_k + v)                                    ΔC = C^t − C^d, v ~ (0, Rv^t)
//!     = (h ΔA − K ΔC A^t) x + h A^d e + (h Δu − K ΔC u^t Δt) + (h − K ΔC) w − K v
//! ```
//!
//! so z = [x; e] follows z_k = F z + c + G_w w + G_v v, and its mean and covariance
//! μ_k = F μ + c, S_k = F S Fᵀ + G_w B^t G_wᵀ + G_v Rv^t G_vᵀ (2N × 2N). The error's
//! block is computed as itself, not as the difference of x's and x̂'s (which would
//! cancel). With the same A, C and u the e-block is the Joseph form with the design's
//! gains and the truth's noises, e = h (A e + w) − K v.

use crate::analysis::gains::{Available, Filter};
use crate::analysis::inputs::Inputs;
use crate::error::Error;
use crate::model::compile::CompiledModel;
use crate::numerics::lanes::Scalar;

/// What the pass gives per step: the error's covariance diagonal and the mean of the
/// filtered error x̂ − x (the Monte Carlo's X − Y), the truth's
/// open-loop variance (S's x-block), each measurement's true SKO and availability, and
/// the filtered variances the design believes and the truth's own filter reaches.
pub(crate) struct Step<'a> {
    pub k: u64,
    pub err_var: &'a [f64],
    pub believed_var: &'a [f64],
    pub optimal_var: &'a [f64],
    pub err_mean: &'a [f64],
    pub open_var: &'a [f64],
    pub meas_sko: &'a [f64],
    pub avail: &'a [bool],
}

/// Runs the recursion over `steps` steps, calling `each` after every step. Returns
/// whether the structure differed (ΔA, ΔC, Δu or y0 not 0 at some step) and whether
/// the truth was the model at every step ([`Pass::same`]). Errors are
/// placed in the request: the model's at `model.…`, the truth's by `place`
/// ([`super::place_in`]), a failed filter step at `truth`.
pub(super) fn run(
    design: &CompiledModel,
    truth: &CompiledModel,
    steps: u64,
    place: impl Fn(Error) -> Error,
    mut each: impl FnMut(Step) -> Result<(), Error>,
) -> Result<(bool, bool), Error> {
    let mut pass = Pass::new(design, truth, steps, true);
    for k in 1..=steps {
        each(pass.step(design, truth, k, &place)?)?;
    }
    Ok((pass.structural, pass.same))
}

/// The recursion's state, advanced one step at a time ([`Pass::step`]): the Monte
/// Carlo with a truth steps it beside its own plan, and reads the truth's inputs of
/// each step from it ([`Pass::truth_inputs`], [`Pass::truth_a`], [`Pass::truth_mean`]).
pub(crate) struct Pass {
    n: usize,
    nm: usize,
    dt: f64,
    t0: f64,
    di: Inputs,
    ti: Inputs,
    /// The filter designed on the model, and (where asked for) the one designed on
    /// the truth (the optimal), beside; both see the model's availability.
    filter: Filter,
    optimal: Option<Filter>,
    avail: Available,
    /// z = [x; e]: its mean and covariance.
    mu: Vec<f64>,
    s: Vec<f64>,
    dc: Vec<f64>,
    /// ΔA, ΔC, Δu or y0 not 0 at some step so far.
    pub(crate) structural: bool,
    /// The truth has been the model so far: the same y0, η0, C and, at every step, the
    /// same A, u, B and Rv, bit for bit.
    same: bool,
    // Work: A^t and A^d dense, F, G_w (2N × N), G_v (2N × n), products.
    at: Vec<f64>,
    ad: Vec<f64>,
    f: Vec<f64>,
    kdc: Vec<f64>,
    gw: Vec<f64>,
    gv: Vec<f64>,
    tmp: Vec<f64>,
    gq: Vec<f64>,
    mu_next: Vec<f64>,
    err_var: Vec<f64>,
    err_mean: Vec<f64>,
    open_var: Vec<f64>,
    believed_var: Vec<f64>,
    optimal_var: Vec<f64>,
}

impl Pass {
    /// The pass before step 1: x_0 ~ (y0^t, P0^t), x̂_0 = y0^d; with the optimal filter
    /// beside if `optimal` (else its variances stay 0).
    pub(crate) fn new(
        design: &CompiledModel,
        truth: &CompiledModel,
        steps: u64,
        optimal: bool,
    ) -> Self {
        let n = design.n_states();
        let nm = design.n_measurements();
        let n2 = 2 * n;
        let dt = (design.t_end - design.t0) / steps as f64;
        let mut mu = vec![0.0; n2];
        let mut s = vec![0.0; n2 * n2];
        for i in 0..n {
            mu[i] = truth.y0[i];
            mu[n + i] = truth.y0[i] - design.y0[i];
            let v = truth.eta0[i] * truth.eta0[i];
            for (a, b) in [(i, i), (i, n + i), (n + i, i), (n + i, n + i)] {
                s[a * n2 + b] = v;
            }
        }
        let dc: Vec<f64> = truth.c.iter().zip(&design.c).map(|(t, d)| t - d).collect();
        let structural = truth.y0 != design.y0 || dc.iter().any(|&x| x != 0.0);
        let same = !structural && truth.eta0 == design.eta0;
        Pass {
            n,
            nm,
            dt,
            t0: design.t0,
            di: Inputs::new(design, n, dt),
            ti: Inputs::new(truth, n, dt),
            filter: Filter::new(design),
            optimal: optimal.then(|| Filter::new(truth)),
            avail: Available::new(design),
            mu,
            s,
            dc,
            structural,
            same,
            at: vec![0.0; n * n],
            ad: vec![0.0; n * n],
            f: vec![0.0; n2 * n2],
            kdc: vec![0.0; n * n],
            gw: vec![0.0; n2 * n],
            gv: vec![0.0; n2 * nm],
            tmp: vec![0.0; n2 * n2],
            gq: vec![0.0; n2 * n.max(nm)],
            mu_next: vec![0.0; n2],
            err_var: vec![0.0; n],
            err_mean: vec![0.0; n],
            open_var: vec![0.0; n],
            believed_var: vec![0.0; n],
            optimal_var: vec![0.0; n],
        }
    }

    /// The truth's inputs of the last step (uΔt, bΔt, Γ, …).
    pub(crate) fn truth_inputs(&self) -> &Inputs {
        &self.ti
    }

    /// The truth's A = I + aΔt of the last step, dense (N × N).
    pub(crate) fn truth_a(&self) -> &[f64] {
        &self.at
    }

    /// The truth's mean state after the last step (x's mean).
    pub(crate) fn truth_mean(&self) -> &[f64] {
        &self.mu[..self.n]
    }

    /// Step k (1, 2, … in order) of both models and the joint recursion.
    pub(crate) fn step(
        &mut self,
        design: &CompiledModel,
        truth: &CompiledModel,
        k: u64,
        place: impl Fn(Error) -> Error,
    ) -> Result<Step<'_>, Error> {
        let (n, nm) = (self.n, self.nm);
        let n2 = 2 * n;
        let t_k = self.t0 + k as f64 * self.dt;
        let (di, ti) = (&mut self.di, &mut self.ti);
        di.at(design, k, k == 1).map_err(crate::request::locate)?;
        ti.at(truth, k, k == 1).map_err(place)?;
        self.avail.at(k, t_k)?;
        if !self.filter.step::<0, Scalar>(design, di, &self.avail) {
            return Err(lost(k, t_k, "the model's"));
        }
        if let Some(o) = &mut self.optimal
            && !o.step::<0, Scalar>(truth, ti, &self.avail)
        {
            return Err(lost(k, t_k, "the truth's"));
        }
        let joseph = &self.filter.joseph;
        let (at, ad, f, kdc, dc) = (
            &mut self.at,
            &mut self.ad,
            &mut self.f,
            &mut self.kdc,
            &self.dc,
        );
        ti.dense_a_into(at);
        di.dense_a_into(ad);
        self.structural |= at != ad || ti.u_dt != di.u_dt;
        self.same &= !self.structural && ti.big_b == di.big_b && ti.rv == di.rv;
        // K (N × n) = gain_tᵀ; h = htᵀ.
        let kk = |i: usize, j: usize| joseph.gain_t[j * n + i];
        let h = |i: usize, b: usize| joseph.ht[b * n + i];
        // K ΔC (N × N), once a step: F's, G_w's and c's lower blocks use it.
        for i in 0..n {
            for j in 0..n {
                kdc[i * n + j] = (0..nm).map(|r| kk(i, r) * dc[r * n + j]).sum();
            }
        }
        // F = [[A^t, 0], [h ΔA − K ΔC A^t, h A^d]]
        f.fill(0.0);
        for i in 0..n {
            for j in 0..n {
                f[i * n2 + j] = at[i * n + j];
                let (mut lower_left, mut lower_right) = (0.0, 0.0);
                for b in 0..n {
                    lower_left +=
                        h(i, b) * (at[b * n + j] - ad[b * n + j]) - kdc[i * n + b] * at[b * n + j];
                    lower_right += h(i, b) * ad[b * n + j];
                }
                f[(n + i) * n2 + j] = lower_left;
                f[(n + i) * n2 + n + j] = lower_right;
            }
        }
        // G_w = [I; h − K ΔC], G_v = [0; −K]
        let (gw, gv) = (&mut self.gw, &mut self.gv);
        gw.fill(0.0);
        gv.fill(0.0);
        for i in 0..n {
            gw[i * n + i] = 1.0;
            for j in 0..n {
                gw[(n + i) * n + j] = h(i, j) - kdc[i * n + j];
            }
            for r in 0..nm {
                gv[(n + i) * nm + r] = -kk(i, r);
            }
        }
        // μ ← F μ + c, c = [u^t Δt; h Δu − K ΔC u^t Δt]
        let (mu, mu_next) = (&mut self.mu, &mut self.mu_next);
        for i in 0..n2 {
            mu_next[i] = (0..n2).map(|j| f[i * n2 + j] * mu[j]).sum();
        }
        for i in 0..n {
            mu_next[i] += ti.u_dt[i];
            let du: f64 = (0..n).map(|b| h(i, b) * (ti.u_dt[b] - di.u_dt[b])).sum();
            let kdcu: f64 = (0..n).map(|b| kdc[i * n + b] * ti.u_dt[b]).sum();
            mu_next[n + i] += du - kdcu;
        }
        mu.copy_from_slice(mu_next);
        // S ← F S Fᵀ + G_w B^t G_wᵀ + G_v Rv^t G_vᵀ, the upper triangle mirrored
        let (s, tmp) = (&mut self.s, &mut self.tmp);
        for i in 0..n2 {
            for j in 0..n2 {
                tmp[i * n2 + j] = (0..n2).map(|b| f[i * n2 + b] * s[b * n2 + j]).sum();
            }
        }
        for i in 0..n2 {
            for j in i..n2 {
                s[i * n2 + j] = (0..n2).map(|b| tmp[i * n2 + b] * f[j * n2 + b]).sum();
            }
        }
        add_gqgt(s, gw, &ti.big_b, &mut self.gq, n2, n);
        add_gqgt(s, gv, &ti.rv, &mut self.gq, n2, nm);
        for i in 1..n2 {
            for j in 0..i {
                s[i * n2 + j] = s[j * n2 + i];
            }
        }
        // Where the truth has been the model so far, the filter's error covariance is
        // its own R_k: reported as the filter computed it (the recursion above, which
        // goes on for the steps after, agrees to rounding).
        let own = self.same.then_some(&self.filter.big_r);
        for i in 0..n {
            self.err_var[i] = own.map_or(s[(n + i) * n2 + n + i], |r| r[i * n + i]);
            // The filtered error's mean in METHOD §1.8's sign, X − Y = x̂ − x = −e.
            self.err_mean[i] = -mu[n + i];
            self.open_var[i] = s[i * n2 + i];
            self.believed_var[i] = self.filter.big_r[i * n + i];
            if let Some(o) = &self.optimal {
                self.optimal_var[i] = o.big_r[i * n + i];
            }
        }
        Ok(Step {
            k,
            err_var: &self.err_var,
            believed_var: &self.believed_var,
            optimal_var: &self.optimal_var,
            err_mean: &self.err_mean,
            open_var: &self.open_var,
            meas_sko: &ti.meas_sko,
            avail: self.avail.each(),
        })
    }
}

/// S's upper triangle += G Q Gᵀ (G: m × q, Q: q × q); `gq` holds G Q.
fn add_gqgt(s: &mut [f64], g: &[f64], q: &[f64], gq: &mut [f64], m: usize, k: usize) {
    for i in 0..m {
        for j in 0..k {
            gq[i * k + j] = (0..k).map(|b| g[i * k + b] * q[b * k + j]).sum();
        }
    }
    for i in 0..m {
        for j in i..m {
            s[i * m + j] += (0..k).map(|b| gq[i * k + b] * g[j * k + b]).sum::<f64>();
        }
    }
}

/// `whose` filter's step failed in the pass where its analysis's did not.
#[cold]
fn lost(k: u64, t: f64, whose: &str) -> Error {
    Error::Numerical {
        step: k,
        t,
        path: "truth".into(),
        message: format!(
            "{whose} filter's covariance recursion failed in the mismatch's pass where its analysis did not"
        ),
    }
}
