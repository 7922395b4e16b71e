//! The model's inputs at a step, for the analysis and the Monte Carlo's plan: the time
//! functions evaluated on the grid (several steps at a time) and what is derived from
//! them — METHOD (1.11)–(1.15), (3.16), (3.17).

use crate::error::Error;
use crate::expr::TimeMatrix;
use crate::model::compile::{CompiledModel, MeasurementNoise};
use crate::numerics::linalg::{SparseRows, mul, mul_abt_sym};

/// The model's inputs at a step — A = I + aΔt (1.11), B = bΔt W (bΔt)ᵀ (1.15),
/// uΔt, Rv = Γ V Γᵀ, and the bound's |A|, |bΔt| φ (3.16), ζ = |Γ| ψ (3.17) — at
/// t_{k−1} (Γ at t_k). Constant parts are computed once; `at` re-evaluates the rest.
pub(crate) struct Inputs {
    pub(crate) n: usize,
    pub(crate) nm: usize,
    pub(crate) dt: f64,
    pub(crate) a_fn: TimeMatrix,
    pub(crate) b_fn: TimeMatrix,
    pub(crate) u_fn: TimeMatrix,
    pub(crate) noise_fn: MeasurementNoise,
    /// C's non-zeros (row, col, value).
    pub(crate) c_nz: Vec<(usize, usize, f64)>,
    /// E = aΔt and |A| = |I + aΔt| on a's pattern (the diagonal always in |A|).
    pub(crate) e: SparseRows,
    pub(crate) abs_a: SparseRows,
    pub(crate) bd: Vec<f64>,
    pub(crate) bw: Vec<f64>,
    pub(crate) big_b: Vec<f64>,
    pub(crate) b_phi: Vec<f64>,
    pub(crate) gamma: Vec<f64>,
    pub(crate) gv: Vec<f64>,
    pub(crate) rv: Vec<f64>,
    /// Rv was re-evaluated at the last `at`.
    pub(crate) rv_changed: bool,
    pub(crate) zeta: Vec<f64>,
    pub(crate) inv_zeta: Vec<f64>,
    /// sqrt(diag Rv) and its reciprocal.
    pub(crate) meas_sko: Vec<f64>,
    pub(crate) inv_meas: Vec<f64>,
    pub(crate) u: Vec<f64>,
    pub(crate) u_dt: Vec<f64>,
}

impl Inputs {
    pub(crate) fn new(m: &CompiledModel, n: usize, dt: f64) -> Self {
        let nm = m.n_measurements();
        let (nl, ms) = (m.b.cols, m.noise.sources());
        let c_nz = (0..nm)
            .flat_map(|j| (0..n).map(move |i| (j, i)))
            .filter_map(|(j, i)| {
                let v = m.c[j * n + i];
                (v != 0.0).then_some((j, i, v))
            })
            .collect();
        let in_a = |i: usize, j: usize| m.a.values[i * n + j] != 0.0 || m.a.varies(i * n + j);
        let all = (0..n).flat_map(|i| (0..n).map(move |j| (i, j)));
        Inputs {
            n,
            nm,
            dt,
            a_fn: m.a.clone(),
            b_fn: m.b.clone(),
            u_fn: m.u.clone(),
            noise_fn: m.noise.clone(),
            c_nz,
            e: SparseRows::with_pattern(n, all.clone().filter(|&(i, j)| in_a(i, j)).collect()),
            abs_a: SparseRows::with_pattern(
                n,
                all.filter(|&(i, j)| i == j || in_a(i, j)).collect(),
            ),
            bd: vec![0.0; n * nl],
            bw: vec![0.0; n * nl],
            big_b: vec![0.0; n * n],
            b_phi: vec![0.0; n],
            gamma: vec![0.0; nm * ms],
            gv: vec![0.0; nm * ms],
            rv: vec![0.0; nm * nm],
            rv_changed: true,
            zeta: vec![0.0; nm],
            inv_zeta: vec![0.0; nm],
            meas_sko: vec![0.0; nm],
            inv_meas: vec![0.0; nm],
            u: vec![0.0; n],
            u_dt: vec![0.0; n],
        }
    }

    /// Inputs of step k (a, b, u at t_{k−1}, Γ at t_k): everything when `first`,
    /// else only what depends on t.
    #[inline(always)]
    pub(crate) fn at(&mut self, m: &CompiledModel, k: u64, first: bool) -> Result<(), Error> {
        let (n, nm, dt) = (self.n, self.nm, self.dt);
        // t_{k−1} and t_k are grid points k − 1 and k: `update_grid` evaluates the
        // expressions for several steps at a time (the same values as one by one).
        if first || !self.a_fn.is_constant() {
            self.a_fn
                .update_grid(m.t0, dt, k - 1)
                .map_err(|(p, t)| time_err(p, k, t))?;
            let a = &self.a_fn.values;
            self.e.set_values(a, |a, _| a * dt);
            self.abs_a
                .set_values(a, |a, diag| (a * dt + if diag { 1.0 } else { 0.0 }).abs());
        }
        if first || !self.b_fn.is_constant() {
            self.b_fn
                .update_grid(m.t0, dt, k - 1)
                .map_err(|(p, t)| time_err(p, k, t))?;
            let nl = self.b_fn.cols;
            for (d, s) in self.bd.iter_mut().zip(&self.b_fn.values) {
                *d = s * dt;
            }
            mul(&mut self.bw, &self.bd, &m.w, n, nl, nl);
            mul_abt_sym(&mut self.big_b, &self.bw, &self.bd, None, n, nl);
            for i in 0..n {
                self.b_phi[i] = (0..nl).map(|l| self.bd[i * nl + l].abs() * m.phi[l]).sum();
            }
            // B (1.15) and |bΔt| φ (3.16) must be finite (noise levels too large).
            if !(finite(&self.big_b) && finite(&self.b_phi)) {
                return Err(self.process_noise_overflow(m, k));
            }
        }
        if first || !self.u_fn.is_constant() {
            self.u_fn
                .update_grid(m.t0, dt, k - 1)
                .map_err(|(p, t)| time_err(p, k, t))?;
            for i in 0..n {
                self.u[i] = self.u_fn.values[i];
                self.u_dt[i] = self.u[i] * dt;
            }
        }
        self.rv_changed = first || !self.noise_fn.matrix().is_constant();
        if self.rv_changed {
            update_noise(&mut self.noise_fn, m.t0, dt, k).map_err(|(p, t)| time_err(&p, k, t))?;
            let ms = self.gamma.len() / nm.max(1);
            match &self.noise_fn {
                MeasurementNoise::Gamma(g) => self.gamma.copy_from_slice(&g.values),
                // Γ = C g (the seed's form Z = c (y + gΦ))
                MeasurementNoise::SeedG(g) => mul(&mut self.gamma, &m.c, &g.values, nm, n, ms),
            }
            mul(&mut self.gv, &self.gamma, &m.v, nm, ms, ms);
            mul_abt_sym(&mut self.rv, &self.gv, &self.gamma, None, nm, ms);
            for j in 0..nm {
                self.zeta[j] = (0..ms)
                    .map(|l| self.gamma[j * ms + l].abs() * m.psi[l])
                    .sum();
                self.meas_sko[j] = self.rv[j * nm + j].max(0.0).sqrt();
                self.inv_zeta[j] = 1.0 / self.zeta[j];
                self.inv_meas[j] = 1.0 / self.meas_sko[j];
            }
            // (Checked here, not only where the filter fails on it: a measurement that
            // is never available would carry an infinite SKO into the result.)
            if !(finite(&self.rv) && finite(&self.zeta)) {
                return Err(self.measurement_noise_overflow(m, k));
            }
            // A variance below f64's normal range keeps a few digits or none, and its
            // whitening (1/√d) and the gain turn it into inf or NaN. Below about
            // 1e-162 it is 0 outright, and would pass for a noise-free measurement:
            // so also when every term |γ_jl| ψ_l is non-zero only below √2.2e-308.
            let squares_underflow = |j: usize| {
                let big = (0..ms)
                    .map(|l| self.gamma[j * ms + l].abs() * m.psi[l])
                    .fold(0.0, f64::max);
                big > 0.0 && big < f64::MIN_POSITIVE.sqrt()
            };
            if let Some(j) = (0..nm).find(|&j| {
                (self.rv[j * nm + j] > 0.0 && self.rv[j * nm + j] < f64::MIN_POSITIVE)
                    || squares_underflow(j)
            }) {
                let var = self.rv[j * nm + j];
                let value = if var == 0.0 {
                    "underflows to 0 (its terms |γ|ψ are below 1.5e-154)".to_string()
                } else {
                    format!("is {var:e}")
                };
                let what = format!(
                    "the measurement-noise variance of \"{}\", a diagonal entry of Γ V Γᵀ, {value}, below f64's normal range (2.2e-308): the noise levels are too small to square; give 0 for a noise-free measurement, or rescale",
                    m.measurements[j]
                );
                return Err(at_step("measurement", what, m, k, dt));
            }
        }
        Ok(())
    }

    /// B or |bΔt| φ left f64's range at step k: the error, naming the largest term.
    /// (Cold and out of line, as the step loop's other error paths: `at` is inlined
    /// into the loop.)
    #[cold]
    #[inline(never)]
    fn process_noise_overflow(&self, m: &CompiledModel, k: u64) -> Error {
        let (nl, dt) = (self.b_fn.cols, self.dt);
        let what = if finite(&self.b_phi) {
            "the process-noise covariance B = bΔt W (bΔt)ᵀ overflowed f64 (a variance above 1.8e308)"
        } else {
            "the bound's model-error SKO |bΔt| φ overflowed f64 (above 1.8e308)"
        };
        let (i, l, x) = largest_term(&self.bd, nl, &m.phi);
        let what = format!(
            "{what}; its largest term |bΔt| φ is {} (state \"{}\": b = {}, Δt = {}, φ = {})",
            crate::text::short(x),
            m.states[i],
            crate::text::short(self.b_fn.values[i * nl + l]),
            crate::text::short(dt),
            crate::text::short(m.phi[l]),
        );
        overflow(&format!("system.b[{i}][{l}]"), &what, m, k, dt)
    }

    /// Γ V Γᵀ or ζ left f64's range at step k: the error, naming the largest term.
    #[cold]
    #[inline(never)]
    fn measurement_noise_overflow(&self, m: &CompiledModel, k: u64) -> Error {
        let ms = self.gamma.len() / self.nm.max(1);
        let what = if finite(&self.zeta) {
            "the measurement-noise covariance Γ V Γᵀ overflowed f64 (a variance above 1.8e308)"
        } else {
            "the bound's measurement SKO ζ = |Γ| ψ (3.17) overflowed f64 (above 1.8e308)"
        };
        let (j, l, x) = largest_term(&self.gamma, ms, &m.psi);
        let (path, gamma) = match &self.noise_fn {
            MeasurementNoise::Gamma(_) => (format!("measurement.gamma[{j}][{l}]"), "Γ"),
            MeasurementNoise::SeedG(_) => (format!("measurement.c[{j}]"), "Γ = c g"),
        };
        let what = format!(
            "{what}; its largest term |Γ| ψ is {} (measurement \"{}\": {gamma} = {}, ψ = {})",
            crate::text::short(x),
            m.measurements[j],
            crate::text::short(self.gamma[j * ms + l]),
            crate::text::short(m.psi[l]),
        );
        overflow(&path, &what, m, k, self.dt)
    }

    /// A = I + aΔt, dense (for the stationary solution).
    pub(crate) fn dense_a(&self) -> Vec<f64> {
        let mut a = vec![0.0; self.n * self.n];
        self.dense_a_into(&mut a);
        a
    }

    /// A = I + aΔt into a dense n × n buffer.
    pub(crate) fn dense_a_into(&self, a: &mut [f64]) {
        let n = self.n;
        a.fill(0.0);
        for i in 0..n {
            a[i * n + i] = 1.0;
        }
        for &(i, j, v) in self.e.nonzeros() {
            a[i * n + j] += v;
        }
    }
}

/// The largest |x_il| σ_l of a row-major matrix with `cols` columns and the sources'
/// SKOs σ: (row, column, value) — the term that put a noise covariance out of range.
fn largest_term(x: &[f64], cols: usize, sko: &[f64]) -> (usize, usize, f64) {
    let mut best = (0, 0, -1.0);
    for (i, row) in x.chunks_exact(cols.max(1)).enumerate() {
        for (l, (v, s)) in row.iter().zip(sko).enumerate() {
            let term = v.abs() * s;
            // (NaN-safe: a term that is not a number is never the largest.)
            if term > best.2 {
                best = (i, l, term);
            }
        }
    }
    best
}

fn finite(v: &[f64]) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// A step's noise input that left f64's range, at step k (t_k).
fn overflow(path: &str, what: &str, m: &CompiledModel, k: u64, dt: f64) -> Error {
    at_step(
        path,
        format!("{what}: the noise levels are too large"),
        m,
        k,
        dt,
    )
}

/// An error of step k's inputs (at t_k).
fn at_step(path: &str, message: String, m: &CompiledModel, k: u64, dt: f64) -> Error {
    Error::Numerical {
        step: k,
        t: m.t0 + k as f64 * dt,
        path: path.to_string(),
        message,
    }
}

/// An expression that is not finite at step k (time t).
pub(crate) fn time_err(path: &str, k: u64, t: f64) -> Error {
    Error::Numerical {
        step: k,
        t,
        path: path.to_string(),
        message: "the expression is not finite here".to_string(),
    }
}

/// Γ (or the seed's g) at the grid point t0 + k·Δt.
fn update_noise(
    noise: &mut MeasurementNoise,
    t0: f64,
    dt: f64,
    k: u64,
) -> Result<(), (String, f64)> {
    match noise {
        MeasurementNoise::Gamma(g) | MeasurementNoise::SeedG(g) => g
            .update_grid(t0, dt, k)
            .map_err(|(p, t)| (p.to_string(), t)),
    }
}
