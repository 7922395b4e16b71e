//! A bank of extended Kalman filters stepped together over the same measurements
//! (METHOD §4, the discrete form): the procedure's K filters, the plain EKF and the
//! Q-scale baselines are all rows of one bank, so the data are read once.
//!
//! Each step n, first every filter predicts from its posterior at t_{n−1} (Euler map):
//!
//! ```text
//!     x⁻ = x⁺ + f(x⁺, t_{n−1}) Δt,   Φ = I + F(x⁺, t_{n−1}) Δt,   P⁻ = Φ P⁺ Φᵀ + q W Δt
//! ```
//!
//! then, in the bank's order, each updates with the measured components a of y_n:
//!
//! ```text
//!     R = r V_aa,   S = H_a P⁻ H_aᵀ + R,   G = P⁻ H_aᵀ S⁻¹      (H = ∂h/∂x at x⁻, t_n)
//!     x⁺ = x⁻ + G [ (y − h(x⁻)) + Σ_c w_c ρ_c ]
//!     P⁺ = (I − G H_a) P⁻ (I − G H_a)ᵀ + G R Gᵀ                  (Joseph form)
//! ```
//!
//! where ρ_c is the residual y − h(·) of an earlier filter c of the bank at step n, at
//! its posterior ([`Residuals::Posterior`], METHOD's default) or its prediction. A
//! plain EKF is a filter with q = r = 1 and no couplings.
//!
//! Nothing is allocated per step: every buffer is sized when the bank is built.

use crate::error::Error;
use crate::expr::StateFn;
use crate::numerics::linalg::{cholesky, cholesky_solve, mul, mul_abt_sym};

/// Which residual of an earlier filter enters a later one's update.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Residuals {
    /// y_n − h(x_i⁺): the implicit-Euler step of the continuous form (METHOD §4).
    Posterior,
    /// y_n − h(x_i⁻).
    Prior,
}

/// One filter's design.
#[derive(Clone, Debug)]
pub struct Design {
    /// What reports call it ("iterate 2", "EKF, Q × 0.1").
    pub label: String,
    /// The process noise's scale: W·q.
    pub q: f64,
    /// The measurement noise's scale: V·r (the procedure's 1/γ_k^k).
    pub r: f64,
    /// Earlier filters of the bank (index, weight w) whose residuals enter.
    pub couplings: Vec<(usize, f64)>,
}

/// One filter's state and sums.
#[derive(Clone, Debug)]
pub struct Filter {
    pub design: Design,
    /// x⁺ (after [`Bank::step`]: at t_n), and x⁻ of the last step.
    pub x: Vec<f64>,
    pub x_prior: Vec<f64>,
    /// P⁺ and P⁻ (N×N).
    pub p: Vec<f64>,
    pub p_prior: Vec<f64>,
    /// y − h(x⁻) and y − h(x⁺) of the last step per measurement (NaN: not measured).
    pub residual_prior: Vec<f64>,
    pub residual_posterior: Vec<f64>,
    /// Σ (y − h(x⁻))² and Σ (y − h(x⁺))² per measurement, over the measured steps.
    pub sum_prior: Vec<f64>,
    pub sum_posterior: Vec<f64>,
}

/// The bank and its scratch buffers.
pub struct Bank {
    n: usize,
    m: usize,
    dt: f64,
    f: Vec<StateFn>,
    h: Vec<StateFn>,
    states: Vec<String>,
    w_dt: Vec<f64>,
    v: Vec<f64>,
    residuals: Residuals,
    pub filters: Vec<Filter>,
    /// How many measurements of each name were used (the same for every filter).
    pub measured: Vec<u64>,
    // Scratch.
    /// Every filter's x⁺ (K × N), and f and ∂f/∂x there: per component i, the K
    /// values and the K gradient rows.
    xs: Vec<f64>,
    f_values: Vec<f64>,
    f_grads: Vec<f64>,
    phi: Vec<f64>,
    tmp: Vec<f64>,
    hx: Vec<f64>,
    hj: Vec<f64>,
    ha: Vec<f64>,
    s: Vec<f64>,
    hp: Vec<f64>,
    gain: Vec<f64>,
    rho: Vec<f64>,
    a: Vec<usize>,
    imkh: Vec<f64>,
    grad: Vec<f64>,
}

impl Bank {
    /// A bank of `designs` on `model`, each filter at (x⁰, P⁰).
    pub fn new(model: &super::model::Compiled, designs: Vec<Design>, residuals: Residuals) -> Bank {
        let (n, m) = (model.n_states(), model.n_measurements());
        let count = designs.len();
        let filters = designs
            .into_iter()
            .map(|design| Filter {
                design,
                x: model.y0.clone(),
                x_prior: model.y0.clone(),
                p: model.p0.clone(),
                p_prior: model.p0.clone(),
                residual_prior: vec![f64::NAN; m],
                residual_posterior: vec![f64::NAN; m],
                sum_prior: vec![0.0; m],
                sum_posterior: vec![0.0; m],
            })
            .collect();
        Bank {
            n,
            m,
            dt: model.dt,
            f: model.f.clone(),
            h: model.h.clone(),
            states: model.states.clone(),
            w_dt: model.w.iter().map(|w| w * model.dt).collect(),
            v: model.v.clone(),
            residuals,
            filters,
            measured: vec![0; m],
            xs: vec![0.0; count * n],
            f_values: vec![0.0; n * count],
            f_grads: vec![0.0; n * count * n],
            phi: vec![0.0; n * n],
            tmp: vec![0.0; n * n],
            hx: vec![0.0; m],
            hj: vec![0.0; m * n],
            ha: vec![0.0; m * n],
            s: vec![0.0; m * m],
            hp: vec![0.0; m * n],
            gain: vec![0.0; n * m],
            rho: vec![0.0; m],
            a: Vec::with_capacity(m),
            imkh: vec![0.0; n * n],
            grad: vec![0.0; n],
        }
    }

    /// Step every filter from t_{n−1} to t_n = `t` with the measurements `y` (m
    /// values, NaN: not measured). `step` is n, for errors.
    pub fn step(&mut self, step: u64, t_prev: f64, t: f64, y: &[f64]) -> Result<(), Error> {
        // N known at compile time for the small models (the loops unrolled: ≈ 3× at
        // N = 2, BENCHMARKS.md); 0 is any N.
        match self.n {
            1 => self.step_n::<1>(step, t_prev, t, y),
            2 => self.step_n::<2>(step, t_prev, t, y),
            3 => self.step_n::<3>(step, t_prev, t, y),
            4 => self.step_n::<4>(step, t_prev, t, y),
            6 => self.step_n::<6>(step, t_prev, t, y),
            _ => self.step_n::<0>(step, t_prev, t, y),
        }
    }

    fn step_n<const N: usize>(
        &mut self,
        step: u64,
        t_prev: f64,
        t: f64,
        y: &[f64],
    ) -> Result<(), Error> {
        self.predict_all::<N>(step, t_prev)?;
        self.a.clear();
        self.a.extend((0..self.m).filter(|&j| y[j].is_finite()));
        for &j in &self.a {
            self.measured[j] += 1;
        }
        for k in 0..self.filters.len() {
            self.update::<N>(k, step, t, y)?;
        }
        Ok(())
    }

    /// Every filter's prediction from its posterior at t_{n−1}: f and F at all the
    /// filters' states first (one evaluation per block of filters,
    /// `StateFn::eval_many_with_gradient`), then each filter's x⁻ and P⁻.
    #[inline(always)]
    fn predict_all<const N: usize>(&mut self, step: u64, t_prev: f64) -> Result<(), Error> {
        let (n, dt, count) = (if N == 0 { self.n } else { N }, self.dt, self.filters.len());
        for (k, filter) in self.filters.iter().enumerate() {
            self.xs[k * n..k * n + n].copy_from_slice(&filter.x);
        }
        for i in 0..n {
            self.f[i].eval_many_with_gradient(
                &self.xs,
                n,
                t_prev,
                &mut self.f_values[i * count..(i + 1) * count],
                &mut self.f_grads[i * count * n..(i + 1) * count * n],
            );
        }
        for k in 0..count {
            let filter = &mut self.filters[k];
            for i in 0..n {
                let v = self.f_values[i * count + k];
                let grad = &self.f_grads[(i * count + k) * n..(i * count + k + 1) * n];
                if !v.is_finite() || grad.iter().any(|g| !g.is_finite()) {
                    return Err(domain(
                        &self.f[i],
                        &format!("system.f[{i}]"),
                        &self.states,
                        &filter.x,
                        &filter.design.label,
                        step - 1,
                        t_prev,
                        "f",
                    ));
                }
                for j in 0..n {
                    self.phi[i * n + j] = grad[j] * dt;
                }
                self.phi[i * n + i] += 1.0;
                filter.x_prior[i] = filter.x[i] + v * dt;
            }
            // P⁻ = Φ P⁺ Φᵀ + q W Δt
            mul(&mut self.tmp, &self.phi, &filter.p, n, n, n);
            mul_abt_sym(&mut filter.p_prior, &self.tmp, &self.phi, None, n, n);
            let q = filter.design.q;
            for (p, w) in filter.p_prior.iter_mut().zip(&self.w_dt) {
                *p += q * w;
            }
        }
        Ok(())
    }

    #[inline(always)]
    fn update<const N: usize>(
        &mut self,
        k: usize,
        step: u64,
        t: f64,
        y: &[f64],
    ) -> Result<(), Error> {
        let (n, m) = (if N == 0 { self.n } else { N }, self.m);
        let (earlier, rest) = self.filters.split_at_mut(k);
        let filter = &mut rest[0];
        for j in 0..m {
            let v = self.h[j].eval_with_gradient(&filter.x_prior, t, &mut self.grad);
            if !v.is_finite() || self.grad.iter().any(|g| !g.is_finite()) {
                return Err(domain(
                    &self.h[j],
                    &format!("measurement.h[{j}]"),
                    &self.states,
                    &filter.x_prior,
                    &filter.design.label,
                    step,
                    t,
                    "h",
                ));
            }
            self.hx[j] = v;
            self.hj[j * n..j * n + n].copy_from_slice(&self.grad);
            filter.residual_prior[j] = y[j] - v;
        }
        let ma = self.a.len();
        if ma == 0 {
            filter.x.copy_from_slice(&filter.x_prior);
            filter.p.copy_from_slice(&filter.p_prior);
            filter.residual_posterior.fill(f64::NAN);
            return Ok(());
        }
        // The pseudo-innovation ρ and H_a.
        for (r, &j) in self.a.iter().enumerate() {
            let mut rho = filter.residual_prior[j];
            for &(c, w) in &filter.design.couplings {
                let other = match self.residuals {
                    Residuals::Posterior => earlier[c].residual_posterior[j],
                    Residuals::Prior => earlier[c].residual_prior[j],
                };
                rho += w * other;
            }
            self.rho[r] = rho;
            self.ha[r * n..r * n + n].copy_from_slice(&self.hj[j * n..j * n + n]);
        }
        if ma == 1 {
            // One measured value, the common case: S is a number (no factorisation).
            let j = self.a[0];
            let h = &self.ha[..n];
            let p = &filter.p_prior;
            let r_value = filter.design.r * self.v[j * m + j];
            let mut s = r_value;
            for c in 0..n {
                let mut hp = 0.0;
                for i in 0..n {
                    hp += h[i] * p[i * n + c];
                }
                self.hp[c] = hp;
                s += hp * h[c];
            }
            if !(s > 0.0 && s.is_finite()) {
                return Err(not_positive(&filter.design.label, step, t));
            }
            let rho = self.rho[0];
            for i in 0..n {
                let g = self.hp[i] / s;
                self.gain[i] = g;
                filter.x[i] = filter.x_prior[i] + g * rho;
            }
            // P⁺ = (I − G h) P⁻ (I − G h)ᵀ + G r Gᵀ.
            for i in 0..n {
                for c in 0..n {
                    let delta = if i == c { 1.0 } else { 0.0 };
                    self.imkh[i * n + c] = delta - self.gain[i] * h[c];
                }
            }
            mul(&mut self.tmp, &self.imkh, p, n, n, n);
            mul_abt_sym(&mut filter.p, &self.tmp, &self.imkh, None, n, n);
            for i in 0..n {
                for c in i..n {
                    let v = filter.p[i * n + c] + self.gain[i] * r_value * self.gain[c];
                    filter.p[i * n + c] = v;
                    filter.p[c * n + i] = v;
                }
            }
        } else {
            let (ha, s, hp) = (
                &self.ha[..ma * n],
                &mut self.s[..ma * ma],
                &mut self.hp[..ma * n],
            );
            // HP = H_a P⁻ (ma×N); S = HP H_aᵀ + r V_aa.
            mul(hp, ha, &filter.p_prior, ma, n, n);
            mul_abt_sym(s, hp, ha, None, ma, n);
            let r_scale = filter.design.r;
            for (r1, &j1) in self.a.iter().enumerate() {
                for (r2, &j2) in self.a.iter().enumerate() {
                    s[r1 * ma + r2] += r_scale * self.v[j1 * m + j2];
                }
            }
            if !cholesky(s, ma) {
                return Err(Error::Numerical {
                    step,
                    t,
                    path: "measurement".into(),
                    message: format!(
                        "{}: the innovation covariance H P Hᵀ + R is not positive definite (the covariance P diverged)",
                        filter.design.label
                    ),
                });
            }
            // Gᵀ = S⁻¹ H_a P⁻ (P⁻ symmetric): solve in place in hp.
            cholesky_solve(s, hp, ma, n);
            let gain = &mut self.gain[..n * ma];
            for r in 0..ma {
                for i in 0..n {
                    gain[i * ma + r] = hp[r * n + i];
                }
            }
            for i in 0..n {
                let mut dx = 0.0;
                for r in 0..ma {
                    dx += gain[i * ma + r] * self.rho[r];
                }
                filter.x[i] = filter.x_prior[i] + dx;
            }
            // P⁺ = (I − G H_a) P⁻ (I − G H_a)ᵀ + G R Gᵀ.
            mul(&mut self.imkh, gain, ha, n, ma, n);
            for v in self.imkh.iter_mut() {
                *v = -*v;
            }
            for i in 0..n {
                self.imkh[i * n + i] += 1.0;
            }
            mul(&mut self.tmp, &self.imkh, &filter.p_prior, n, n, n);
            mul_abt_sym(&mut filter.p, &self.tmp, &self.imkh, None, n, n);
            for i in 0..n {
                for j in i..n {
                    let mut grg = 0.0;
                    for (r1, &j1) in self.a.iter().enumerate() {
                        let gi = gain[i * ma + r1];
                        for (r2, &j2) in self.a.iter().enumerate() {
                            grg += gi * r_scale * self.v[j1 * m + j2] * gain[j * ma + r2];
                        }
                    }
                    filter.p[i * n + j] += grg;
                    if i != j {
                        filter.p[j * n + i] = filter.p[i * n + j];
                    }
                }
            }
        }
        if filter.p.iter().any(|v| !v.is_finite()) || filter.x.iter().any(|v| !v.is_finite()) {
            return Err(Error::Numerical {
                step,
                t,
                path: "system".into(),
                message: format!(
                    "{}: the estimate or its covariance is not finite (the filter diverged)",
                    filter.design.label
                ),
            });
        }
        // The posterior residuals and the sums.
        filter.residual_posterior.fill(f64::NAN);
        for &j in &self.a {
            let rp = y[j] - self.h[j].value(&filter.x, t);
            if !rp.is_finite() {
                return Err(domain(
                    &self.h[j],
                    &format!("measurement.h[{j}]"),
                    &self.states,
                    &filter.x,
                    &filter.design.label,
                    step,
                    t,
                    "h",
                ));
            }
            filter.residual_posterior[j] = rp;
            let r0 = filter.residual_prior[j];
            filter.sum_prior[j] += r0 * r0;
            filter.sum_posterior[j] += rp * rp;
        }
        Ok(())
    }
}

/// The error for an innovation covariance that is not positive definite.
fn not_positive(filter: &str, step: u64, t: f64) -> Error {
    Error::Numerical {
        step,
        t,
        path: "measurement".into(),
        message: format!(
            "{filter}: the innovation covariance H P Hᵀ + R is not positive definite (the covariance P diverged)"
        ),
    }
}

/// The error for an expression that is not finite (or has no finite derivative) at a
/// filter's state: the step, the time, the state and the expression.
#[allow(clippy::too_many_arguments)]
fn domain(
    f: &StateFn,
    path: &str,
    states: &[String],
    x: &[f64],
    filter: &str,
    step: u64,
    t: f64,
    what: &str,
) -> Error {
    let state: Vec<String> = states
        .iter()
        .zip(x)
        .map(|(s, v)| format!("{s} = {}", crate::text::num(*v)))
        .collect();
    Error::Numerical {
        step,
        t,
        path: path.into(),
        message: format!(
            "{filter}: {what} = \"{}\" or its derivative is not finite at {}: the state left the expression's domain",
            f.text(),
            state.join(", ")
        ),
    }
}
