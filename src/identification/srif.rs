//! The square-root information filter, the likelihood from its arrays and its
//! gradient from their derivatives (METHOD §3, seed 003 (2.1.10)–(2.1.15),
//! (2.2.3)–(2.2.4), §2.4–2.5).
//!
//! The information array [R̃ | z̃] (P̃ = R̃⁻¹R̃⁻ᵀ, x̃ = R̃⁻¹z̃) is updated by orthogonal
//! transformations only ([`triangularise`]); no covariance is formed, so the
//! likelihood stays accurate where a covariance filter's P loses positive
//! definiteness (a vague prior with a nearly exact sensor). For a gradient, every
//! array carries one derivative block per parameter to its right: the same
//! reflections transform them (the seed's M1, T1), and [`differentiate`] turns them
//! into the derivatives of the result (M2–M3, T2–T3).

use super::model::{Data, Discrete, Partial, Prior, PriorAt};
use crate::error::{Error, FieldError};
use crate::numerics::householder::{differentiate, triangularise};
use crate::numerics::linalg::{cholesky, cholesky_solve, solve_lower};

/// ln 2π, the Gaussian density's constant per scalar measurement.
const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// The negative log-likelihood of the data under a model (METHOD §3 (2.1.3)).
#[derive(Clone, Debug, PartialEq)]
pub struct Likelihood {
    /// J(θ) = ½ Σ_k (ν_kᵀS_k⁻¹ν_k + ln det S_k + m_k ln 2π): minus the log-likelihood,
    /// as other tools print it (the 2π constant included).
    pub j: f64,
    /// ½ Σ νᵀS⁻¹ν = ½ Σ ‖e_k‖² (2.2.3).
    pub data_part: f64,
    /// ½ Σ ln det S_k = ½ Σ (ln det R + 2 Σ ln|R̂_ii| − 2 Σ ln|R̃_ii|) (2.2.4).
    pub model_part: f64,
    /// The scalar measurements used (missing ones excluded): the constant is
    /// ½ · measurements · ln 2π.
    pub measurements: usize,
    /// ∂J/∂θ_i for each [`Partial`] given (empty without): the data part Σ eᵀ∂e and
    /// the model part ½ tr(R⁻¹∂R) + Σ ∂R̂_ii/R̂_ii − Σ ∂R̃_ii/R̃_ii per step (§2.5).
    pub gradient: Vec<f64>,
    /// The sample Fisher information (np × np, row-major; empty unless asked for):
    /// Σ_k [∂_iνᵀS⁻¹∂_jν + ½ tr(S⁻¹∂_iS S⁻¹∂_jS)] (seed (2.3.2) with the expected
    /// values replaced by the computed ones; Harvey's form).
    pub fisher_sample: Vec<f64>,
    /// With [`Srif::recording`]: each step's standardized innovations ν_j/√S_jj
    /// (D × m, row-major; NaN where the measurement is missing), from the information
    /// array before the update (x̃ = R̃⁻¹z̃, S = H P̃ Hᵀ + R, P̃ = R̃⁻¹R̃⁻ᵀ).
    pub innovations: Vec<f64>,
    /// With [`Srif::recording`]: each step's NIS νᵀS⁻¹ν = ‖e_k‖² (NaN where nothing
    /// was measured), χ² with as many degrees of freedom as measurements.
    pub nis: Vec<f64>,
}

impl Likelihood {
    /// J less the 2π constant: ½ Σ (νᵀS⁻¹ν + ln det S).
    pub fn j_without_constant(&self) -> f64 {
        self.data_part + self.model_part
    }
}

/// The filter's arrays and buffers, sized once for a model and its parameters'
/// [`Partial`]s; [`Srif::run`] then allocates nothing per step.
pub struct Srif {
    pub(super) n: usize,
    l: usize,
    m: usize,
    /// The parameters (derivative blocks), and whether the sample information is
    /// formed beside the gradient.
    pub(super) np: usize,
    information: bool,
    /// [R̃ | z̃] (N × (N + 1)), then each parameter's [∂R̃ | ∂z̃], side by side.
    pub(super) info: Vec<f64>,
    /// The measurement-update array: (N + m) rows, as wide as `info`.
    meas: Vec<f64>,
    /// The time-update array: (L + N) × (L + N + 1) · (1 + np).
    time: Vec<f64>,
    /// Φ⁻¹ (N × N), −Φ⁻¹G (N × L), Φ⁻¹u (N), and their derivatives per parameter.
    phi_inv: Vec<f64>,
    phi_inv_g: Vec<f64>,
    phi_inv_u: Vec<f64>,
    d_phi_inv: Vec<f64>,
    d_phi_inv_g: Vec<f64>,
    d_phi_inv_u: Vec<f64>,
    /// R_w with R_wᵀR_w = Q⁻¹ (L × L: R_w = L_Q⁻¹), and its derivatives.
    r_w: Vec<f64>,
    d_r_w: Vec<f64>,
    /// The available measurements' R factor L (ma × ma), the mask it is of, ln det R;
    /// per parameter M = Φ(L⁻¹∂R L⁻ᵀ) (∂L = L M), tr(L⁻¹∂R L⁻ᵀ) = tr(R⁻¹∂R), and
    /// L⁻¹∂H of the available rows.
    r_chol: Vec<f64>,
    pub(super) r_mask: Vec<bool>,
    r_ln_det: f64,
    m_r: Vec<f64>,
    /// Per parameter K (ma × ma) and U∂ν (ma) of a step's information term.
    k_info: Vec<f64>,
    k_tmp: Vec<f64>,
    a_info: Vec<f64>,
    /// Whether a step's information includes its data term Σ ∂_iνᵀS⁻¹∂_jν (the
    /// sample information's), or only ½ tr(S⁻¹∂_iS S⁻¹∂_jS) (the expected
    /// information's other term, [`super::expected`]).
    pub(super) data_term: bool,
    d_r_sub: Vec<f64>,
    tr_r: Vec<f64>,
    d_h_w: Vec<f64>,
    /// The available measurements' indices, the whitened H rows and z.
    pub(super) avail: Vec<usize>,
    h_w: Vec<f64>,
    z_w: Vec<f64>,
    /// Work buffers of [`differentiate`] and of the sandwiches L⁻¹ X L⁻ᵀ.
    y: Vec<f64>,
    omega: Vec<f64>,
    sq: Vec<f64>,
    /// Whether [`Srif::run`] records the innovations ([`Srif::recording`]), and its
    /// buffers (N each).
    record: bool,
    rec_x: Vec<f64>,
    rec_y: Vec<f64>,
}

impl Srif {
    /// The filter for `model` and the parameters whose `partials` are given (with
    /// `information`, also the sample information over them), with Φ⁻¹ and R_w made
    /// (the time update (2.1.13) needs both: Φ must be invertible and Q positive
    /// definite).
    pub fn new(model: &Discrete, partials: &[Partial], information: bool) -> Result<Srif, Error> {
        let (n, l, m, np) = (model.n, model.l, model.m, partials.len());
        let phi_inv = invert(&model.phi, n).ok_or_else(|| {
            model_error(
                "system.transition",
                "the transition Φ is singular; the SRIF's time update (METHOD §3 (2.1.13)) needs Φ⁻¹",
            )
        })?;
        let mut l_q = model.q.clone();
        if !cholesky(&mut l_q, l) {
            return Err(model_error(
                "system.w",
                "the process noise's covariance Q is not positive definite; the SRIF's time update (METHOD §3 (2.1.13)) needs Q⁻¹",
            ));
        }
        let mut r_w = identity(l);
        solve_lower(&l_q, &mut r_w, l, l);
        let (phi_inv_g, phi_inv_u) = inverse_terms(&phi_inv, &model.g, &model.u, n, l);
        let (mut d_phi_inv, mut d_phi_inv_g, mut d_phi_inv_u) =
            (Vec::new(), Vec::new(), Vec::new());
        let mut d_r_w = Vec::new();
        let mut sq = vec![0.0; n.max(l).max(m).pow(2)];
        for p in partials {
            // ∂(Φ⁻¹) = −Φ⁻¹ ∂Φ Φ⁻¹; ∂(−Φ⁻¹G) = −∂(Φ⁻¹)G − Φ⁻¹∂G; ∂(Φ⁻¹u) = ∂(Φ⁻¹)u + Φ⁻¹∂u
            let t = product(&phi_inv, &p.phi, n, n, n);
            let dpi: Vec<f64> = product(&t, &phi_inv, n, n, n).iter().map(|v| -v).collect();
            let (a, b) = inverse_terms(&dpi, &model.g, &model.u, n, l);
            let (c, d) = inverse_terms(&phi_inv, &p.g, &p.u, n, l);
            d_phi_inv_g.extend(a.iter().zip(&c).map(|(a, c)| a + c));
            d_phi_inv_u.extend(b.iter().zip(&d).map(|(b, d)| b + d));
            d_phi_inv.extend(dpi);
            // R_w = L_Q⁻¹: ∂R_w = −L_Q⁻¹ ∂L_Q L_Q⁻¹ = −M R_w, M = Φ(L_Q⁻¹ ∂Q L_Q⁻ᵀ)
            sandwich_factor(&l_q, &p.q, l, &mut sq);
            d_r_w.extend(product(&sq[..l * l], &r_w, l, l, l).iter().map(|v| -v));
        }
        let w = (n + 1) * (1 + np);
        let tw = (l + n + 1) * (1 + np);
        Ok(Srif {
            n,
            l,
            m,
            np,
            information: information && np > 0,
            info: vec![0.0; n * w],
            meas: vec![0.0; (n + m) * (n + 1 + m) * (1 + np)],
            time: vec![0.0; (l + n) * tw],
            phi_inv,
            phi_inv_g,
            phi_inv_u,
            d_phi_inv,
            d_phi_inv_g,
            d_phi_inv_u,
            r_w,
            d_r_w,
            r_chol: vec![0.0; m * m],
            r_mask: Vec::new(),
            r_ln_det: 0.0,
            m_r: vec![0.0; np * m * m],
            d_r_sub: vec![0.0; m * m],
            k_info: vec![0.0; np * m * m],
            k_tmp: vec![0.0; m * m],
            a_info: vec![0.0; np * m],
            data_term: true,
            tr_r: vec![0.0; np],
            d_h_w: vec![0.0; np * m * n],
            avail: Vec::with_capacity(m),
            h_w: vec![0.0; m * n],
            z_w: vec![0.0; m],
            y: vec![0.0; (n + m.max(l)) * (n + l)],
            omega: vec![0.0; (n + m.max(l)).pow(2)],
            sq,
            record: false,
            rec_x: vec![0.0; n],
            rec_y: vec![0.0; n],
        })
    }

    /// J(θ) of `data` under `model` (the model this filter was made for), from
    /// `prior`, and its gradient over the `partials` the filter was made for.
    pub fn run(
        &mut self,
        model: &Discrete,
        partials: &[Partial],
        prior: &Prior,
        data: &Data,
    ) -> Result<Likelihood, Error> {
        debug_assert_eq!((data.m, partials.len()), (self.m, self.np));
        self.set_prior(prior, partials)?;
        self.r_mask.clear();
        let mut out = Likelihood {
            j: 0.0,
            data_part: 0.0,
            model_part: 0.0,
            measurements: 0,
            gradient: vec![0.0; self.np],
            fisher_sample: if self.information {
                vec![0.0; self.np * self.np]
            } else {
                Vec::new()
            },
            innovations: Vec::new(),
            nis: Vec::new(),
        };
        if self.record {
            out.innovations = vec![f64::NAN; data.rows() * self.m];
            out.nis = vec![f64::NAN; data.rows()];
        }
        let m = self.m;
        for k in 0..data.rows() {
            if k > 0 || prior.at == PriorAt::T0 {
                self.time_update();
            }
            let z = &data.z[k * m..k * m + m];
            self.avail.clear();
            self.avail.extend((0..m).filter(|&j| !z[j].is_nan()));
            if !self.avail.is_empty() {
                if self.record {
                    self.record_innovations(model, z, k, &mut out);
                }
                let before = out.data_part;
                self.measurement_update(model, partials, z, data.t[k], k, &mut out)?;
                out.measurements += self.avail.len();
                if self.record {
                    out.nis[k] = 2.0 * (out.data_part - before);
                }
            }
            if !(out.data_part.is_finite() && out.model_part.is_finite()) {
                return Err(Error::Numerical {
                    step: k as u64 + 1,
                    t: data.t[k],
                    path: "data".into(),
                    message: "the likelihood overflowed: the model cannot explain this measurement (its innovation is beyond f64's range)".into(),
                });
            }
        }
        out.j = out.data_part + out.model_part + 0.5 * out.measurements as f64 * LN_2PI;
        Ok(out)
    }

    /// [R̃ | z̃] of x ~ N(x0, P0): L⁻¹ [I | x0] (P0 = L Lᵀ) made upper triangular; its
    /// derivative block −M L⁻¹[I | x0] + [0 | L⁻¹∂x0], M = Φ(L⁻¹∂P0 L⁻ᵀ) (∂L = L M).
    pub(super) fn set_prior(&mut self, prior: &Prior, partials: &[Partial]) -> Result<(), Error> {
        let (n, np) = (self.n, self.np);
        let ic = n + 1;
        let w = ic * (1 + np);
        let mut l = prior.p0.clone();
        if !cholesky(&mut l, n) {
            return Err(model_error(
                "system.eta0",
                "the initial covariance P0 is not positive definite; the SRIF starts from its inverse (every initial SKO must be positive)",
            ));
        }
        let mut base = vec![0.0; n * ic];
        for i in 0..n {
            base[i * ic + i] = 1.0;
            base[i * ic + n] = prior.x0[i];
        }
        solve_lower(&l, &mut base, n, ic);
        self.info.fill(0.0);
        for i in 0..n {
            self.info[i * w..i * w + ic].copy_from_slice(&base[i * ic..i * ic + ic]);
        }
        for (d, p) in partials.iter().enumerate() {
            sandwich_factor(&l, &p.p0, n, &mut self.sq);
            let mut dx = p.x0.clone();
            solve_lower(&l, &mut dx, n, 1);
            let off = ic * (1 + d);
            for i in 0..n {
                for c in 0..ic {
                    let mb: f64 = (0..n).map(|k| self.sq[i * n + k] * base[k * ic + c]).sum();
                    self.info[i * w + off + c] = -mb + if c == n { dx[i] } else { 0.0 };
                }
            }
        }
        triangularise(&mut self.info, n, w, n);
        differentiate(&mut self.info, n, ic, n, np, &mut self.y, &mut self.omega);
        Ok(())
    }

    /// The filter recording each step's innovations and NIS ([`Likelihood::innovations`],
    /// [`Likelihood::nis`]): the fit's diagnostics at θ̂, one pass.
    pub fn recording(mut self) -> Srif {
        self.record = true;
        self
    }

    /// Step k's standardized innovations, from the array before its update: x̃ by
    /// back-substitution in R̃ x̃ = z̃, ν_j = z_j − h_j x̃, and S_jj = ‖R̃⁻ᵀh_jᵀ‖² + R_jj
    /// (forward substitution in R̃ᵀ y = h_jᵀ).
    fn record_innovations(&mut self, model: &Discrete, z: &[f64], k: usize, out: &mut Likelihood) {
        let (n, m) = (self.n, self.m);
        let w = (n + 1) * (1 + self.np);
        let r = |i: usize, j: usize| self.info[i * w + j];
        let x = &mut self.rec_x;
        for i in (0..n).rev() {
            let s: f64 = (i + 1..n).map(|j| r(i, j) * x[j]).sum();
            x[i] = (r(i, n) - s) / r(i, i);
        }
        for &j in &self.avail {
            let h = &model.h[j * n..j * n + n];
            let y = &mut self.rec_y;
            for i in 0..n {
                let s: f64 = (0..i).map(|q| r(q, i) * y[q]).sum();
                y[i] = (h[i] - s) / r(i, i);
            }
            let s = y.iter().map(|v| v * v).sum::<f64>() + model.r[j * m + j];
            let nu = z[j] - (0..n).map(|i| h[i] * self.rec_x[i]).sum::<f64>();
            out.innovations[k * m + j] = nu / s.sqrt();
        }
    }

    /// The measurement update (2.1.10)–(2.1.12) with the available measurements:
    /// T [R̃ z̃; H̄ z̄] = [R̂ ẑ; 0 e], and its terms of J and of the gradient.
    pub(super) fn measurement_update(
        &mut self,
        model: &Discrete,
        partials: &[Partial],
        z: &[f64],
        t: f64,
        k: usize,
        out: &mut Likelihood,
    ) -> Result<(), Error> {
        let (n, m, np) = (self.n, self.m, self.np);
        let ma = self.avail.len();
        let ic = n + 1;
        let w = ic * (1 + np);
        if self.r_mask.len() != m || (0..m).any(|j| self.r_mask[j] == z[j].is_nan()) {
            self.factor_r(model, partials, z, t, k)?;
        }
        // H̄ = L⁻¹ H_a, z̄ = L⁻¹ z_a (2.1.11)–(2.1.12)
        for (r, &j) in self.avail.iter().enumerate() {
            self.h_w[r * n..r * n + n].copy_from_slice(&model.h[j * n..j * n + n]);
            self.z_w[r] = z[j];
        }
        solve_lower(&self.r_chol, &mut self.h_w[..ma * n], ma, n);
        solve_lower(&self.r_chol, &mut self.z_w[..ma], ma, 1);
        let rows = n + ma;
        // For the information, ma columns [0; I] ride along: T applied to them gives
        // [T12; T22], T22 the factor of the whitened S⁻¹ (T22ᵀT22 = S̄⁻¹) that the
        // sample information needs.
        let extra = if self.information { ma } else { 0 };
        let mc = ic + extra;
        let mw = mc * (1 + np);
        let a = &mut self.meas[..rows * mw];
        a.fill(0.0);
        for i in 0..n {
            for b in 0..=np {
                a[i * mw + b * mc..i * mw + b * mc + ic]
                    .copy_from_slice(&self.info[i * w + b * ic..i * w + b * ic + ic]);
            }
        }
        // −Σ ln|R̃_ii| and its derivatives, from the array before the update.
        let ln_det_prior: f64 = (0..n).map(|i| libm::log(a[i * mw + i].abs())).sum();
        for d in 0..np {
            let off = mc * (1 + d);
            out.gradient[d] -= (0..n)
                .map(|i| a[i * mw + off + i] / a[i * mw + i])
                .sum::<f64>();
        }
        for r in 0..ma {
            let row = &mut a[(n + r) * mw..(n + r + 1) * mw];
            row[..n].copy_from_slice(&self.h_w[r * n..r * n + n]);
            row[n] = self.z_w[r];
            if extra > 0 {
                row[ic + r] = 1.0;
            }
            // ∂H̄ = L⁻¹∂H − M H̄, ∂z̄ = −M z̄ (M lower triangular)
            for d in 0..np {
                let off = mc * (1 + d);
                let mr = &self.m_r[d * m * m..];
                for c in 0..n {
                    let mh: f64 = (0..=r).map(|s| mr[r * ma + s] * self.h_w[s * n + c]).sum();
                    row[off + c] = self.d_h_w[d * m * n + r * n + c] - mh;
                }
                row[off + n] = -(0..=r).map(|s| mr[r * ma + s] * self.z_w[s]).sum::<f64>();
            }
        }
        triangularise(a, rows, mw, n);
        differentiate(a, rows, mc, n, np, &mut self.y, &mut self.omega);
        let e2: f64 = (n..rows).map(|r| a[r * mw + n] * a[r * mw + n]).sum();
        let ln_det_post: f64 = (0..n).map(|i| libm::log(a[i * mw + i].abs())).sum();
        for d in 0..np {
            let off = mc * (1 + d);
            let de: f64 = (n..rows).map(|r| a[r * mw + n] * a[r * mw + off + n]).sum();
            let dr: f64 = (0..n).map(|i| a[i * mw + off + i] / a[i * mw + i]).sum();
            out.gradient[d] += de + 0.5 * self.tr_r[d] + dr;
        }
        if self.information {
            self.add_information((ma, mw, mc), (k, t), out)?;
        }
        for i in 0..n {
            for b in 0..=np {
                self.info[i * w + b * ic..i * w + b * ic + ic]
                    .copy_from_slice(&self.meas[i * mw + b * mc..i * mw + b * mc + ic]);
            }
        }
        out.data_part += 0.5 * e2;
        out.model_part += 0.5 * (self.r_ln_det + 2.0 * ln_det_post - 2.0 * ln_det_prior);
        Ok(())
    }

    /// A step's term of the sample information (seed (2.3.2), Harvey's form):
    /// Σ ∂_iνᵀS⁻¹∂_jν + ½ tr(S⁻¹∂_iS S⁻¹∂_jS), from the updated array alone. With
    /// U = T22 L⁻¹ (UᵀU = S⁻¹, e = Uν) and K = ∂U U⁻¹ = (∂T22 − T22 M) T22⁻¹:
    /// U∂ν = ∂e − K e, and U ∂S Uᵀ = −(K + Kᵀ). (The bottom rows' free rotation
    /// changes U, not these terms.) T22⁻¹ = (T22ᵀT22)⁻¹T22ᵀ, by Cholesky.
    fn add_information(
        &mut self,
        (ma, mw, mc): (usize, usize, usize),
        (k_step, t): (usize, f64),
        out: &mut Likelihood,
    ) -> Result<(), Error> {
        let (n, m, np) = (self.n, self.m, self.np);
        let ic = n + 1;
        let a = &self.meas;
        let t22 = |r: usize, c: usize| a[(n + r) * mw + ic + c];
        // G = T22ᵀT22 = S̄⁻¹, factored.
        let g = &mut self.sq[..ma * ma];
        for r in 0..ma {
            for c in 0..ma {
                g[r * ma + c] = (0..ma).map(|s| t22(s, r) * t22(s, c)).sum();
            }
        }
        if !cholesky(g, ma) {
            return Err(Error::Numerical {
                step: k_step as u64 + 1,
                t,
                path: "data".into(),
                message: "the innovation covariance of a step is singular to working precision; its information cannot be formed".into(),
            });
        }
        for d in 0..np {
            let off = mc * (1 + d);
            let mr = &self.m_r[d * m * m..];
            // Xᵀ, X = ∂T22 − T22 M, into k (ma × ma), then G⁻¹Xᵀ = (X G⁻¹)ᵀ.
            let k = &mut self.k_info[d * m * m..d * m * m + ma * ma];
            for r in 0..ma {
                for c in 0..ma {
                    let tm: f64 = (c..ma).map(|s| t22(r, s) * mr[s * ma + c]).sum();
                    k[c * ma + r] = a[(n + r) * mw + off + ic + c] - tm;
                }
            }
            cholesky_solve(g, k, ma, ma);
            // K = (X G⁻¹) T22ᵀ: K[r][c] = Σ_s (X G⁻¹)[r][s] T22[c][s]
            let kk = &mut self.k_tmp[..ma * ma];
            for r in 0..ma {
                for c in 0..ma {
                    kk[r * ma + c] = (0..ma).map(|s| k[s * ma + r] * t22(c, s)).sum();
                }
            }
            k.copy_from_slice(kk);
            // a = ∂e − K e (the sample information's data term only)
            if !self.data_term {
                continue;
            }
            for r in 0..ma {
                let ke: f64 = (0..ma).map(|s| k[r * ma + s] * a[(n + s) * mw + n]).sum();
                self.a_info[d * m + r] = a[(n + r) * mw + off + n] - ke;
            }
        }
        for i in 0..np {
            for j in 0..=i {
                let ai = &self.a_info[i * m..i * m + ma];
                let aj = &self.a_info[j * m..j * m + ma];
                let mut v: f64 = match self.data_term {
                    true => ai.iter().zip(aj).map(|(x, y)| x * y).sum(),
                    false => 0.0,
                };
                // ½ tr(W_i W_j), W = −(K + Kᵀ)
                let (ki, kj) = (&self.k_info[i * m * m..], &self.k_info[j * m * m..]);
                let mut tr = 0.0;
                for r in 0..ma {
                    for c in 0..ma {
                        let wi = ki[r * ma + c] + ki[c * ma + r];
                        let wj = kj[c * ma + r] + kj[r * ma + c];
                        tr += wi * wj;
                    }
                }
                v += 0.5 * tr;
                out.fisher_sample[i * np + j] += v;
                if i != j {
                    out.fisher_sample[j * np + i] += v;
                }
            }
        }
        Ok(())
    }

    /// The factor L of R over the available measurements, ln det R, and per
    /// parameter M = Φ(L⁻¹∂R L⁻ᵀ), its trace's double tr(R⁻¹∂R), and L⁻¹∂H.
    fn factor_r(
        &mut self,
        model: &Discrete,
        partials: &[Partial],
        z: &[f64],
        t: f64,
        k: usize,
    ) -> Result<(), Error> {
        let (n, m) = (self.n, self.m);
        let ma = self.avail.len();
        let sub = |full: &[f64], out: &mut [f64], avail: &[usize]| {
            for (a, &i) in avail.iter().enumerate() {
                for (b, &j) in avail.iter().enumerate() {
                    out[a * ma + b] = full[i * m + j];
                }
            }
        };
        sub(&model.r, &mut self.r_chol, &self.avail);
        if !cholesky(&mut self.r_chol[..ma * ma], ma) {
            return Err(Error::Numerical {
                step: k as u64 + 1,
                t,
                path: "measurement.v".into(),
                message: "the measurement noise's covariance R (of the measurements available at this step) is not positive definite; the likelihood needs R⁻¹".into(),
            });
        }
        self.r_ln_det = (0..ma)
            .map(|i| 2.0 * libm::log(self.r_chol[i * ma + i]))
            .sum();
        let dr = &mut self.d_r_sub;
        for (d, p) in partials.iter().enumerate() {
            sub(&p.r, dr, &self.avail);
            let mr = &mut self.m_r[d * m * m..d * m * m + ma * ma];
            sandwich_factor(&self.r_chol[..ma * ma], dr, ma, mr);
            // M holds half of N's diagonal: tr(R⁻¹∂R) = tr N = 2 tr M.
            self.tr_r[d] = 2.0 * (0..ma).map(|i| mr[i * ma + i]).sum::<f64>();
            let dh = &mut self.d_h_w[d * m * n..d * m * n + ma * n];
            for (r, &j) in self.avail.iter().enumerate() {
                dh[r * n..r * n + n].copy_from_slice(&p.h[j * n..j * n + n]);
            }
            solve_lower(&self.r_chol[..ma * ma], dh, ma, n);
        }
        self.r_mask.clear();
        self.r_mask.extend(z.iter().map(|v| !v.is_nan()));
        Ok(())
    }

    /// The time update (2.1.13): with x_k = Φ⁻¹(x_{k+1} − u − G w),
    /// T [R_w 0 0; −R̂Φ⁻¹G R̂Φ⁻¹ ẑ + R̂Φ⁻¹u] = [R̃_w R̃_wx z̃_w; 0 R̃_{k+1} z̃_{k+1}];
    /// the derivative blocks with ∂(R̂Φ⁻¹) = ∂R̂ Φ⁻¹ + R̂ ∂(Φ⁻¹) (the seed's T1–T3).
    pub(super) fn time_update(&mut self) {
        let (n, l, np) = (self.n, self.l, self.np);
        let ic = n + 1;
        let w = ic * (1 + np);
        let tc = l + n + 1;
        let tw = tc * (1 + np);
        let a = &mut self.time;
        a.fill(0.0);
        for i in 0..l {
            a[i * tw..i * tw + l].copy_from_slice(&self.r_w[i * l..i * l + l]);
            for d in 0..np {
                let (off, src) = (tc * (1 + d), &self.d_r_w[d * l * l + i * l..]);
                a[i * tw + off..i * tw + off + l].copy_from_slice(&src[..l]);
            }
        }
        for i in 0..n {
            let row = &mut a[(l + i) * tw..(l + i + 1) * tw];
            let info = &self.info[i * w..(i + 1) * w];
            let (r_hat, pi, pig, piu) =
                (&info[..n], &self.phi_inv, &self.phi_inv_g, &self.phi_inv_u);
            accumulate(&mut row[..tc], r_hat, pi, pig, piu, n, l);
            row[l + n] += info[n];
            for d in 0..np {
                let (off, blk) = (tc * (1 + d), ic * (1 + d));
                let block = &mut row[off..off + tc];
                // ∂R̂ with Φ⁻¹…, then R̂ with ∂(Φ⁻¹…)
                accumulate(block, &info[blk..blk + n], pi, pig, piu, n, l);
                let (dpi, dpig, dpiu) = (
                    &self.d_phi_inv[d * n * n..(d + 1) * n * n],
                    &self.d_phi_inv_g[d * n * l..(d + 1) * n * l],
                    &self.d_phi_inv_u[d * n..(d + 1) * n],
                );
                accumulate(block, r_hat, dpi, dpig, dpiu, n, l);
                block[l + n] += info[blk + n];
            }
        }
        triangularise(a, l + n, tw, l + n);
        differentiate(a, l + n, tc, l + n, np, &mut self.y, &mut self.omega);
        for i in 0..n {
            for b in 0..=np {
                let src = &a[(l + i) * tw + tc * b + l..(l + i) * tw + tc * b + tc];
                self.info[i * w + ic * b..i * w + ic * b + ic].copy_from_slice(src);
            }
        }
    }
}

/// Adds to a time-update row [w | x_{k+1} | rhs] the terms of one row `r` of R̂ (or
/// ∂R̂): r (−Φ⁻¹G), r Φ⁻¹, r Φ⁻¹u — with Φ⁻¹… or their derivatives.
fn accumulate(
    row: &mut [f64],
    r: &[f64],
    pi: &[f64],
    pig: &[f64],
    piu: &[f64],
    n: usize,
    l: usize,
) {
    for k in 0..n {
        let v = r[k];
        if v == 0.0 {
            continue;
        }
        for c in 0..l {
            row[c] += v * pig[k * l + c];
        }
        for c in 0..n {
            row[l + c] += v * pi[k * n + c];
        }
        row[l + n] += v * piu[k];
    }
}

/// The likelihood of `data` under `model` from `prior` (a filter made for the call).
pub fn likelihood(model: &Discrete, prior: &Prior, data: &Data) -> Result<Likelihood, Error> {
    Srif::new(model, &[], false)?.run(model, &[], prior, data)
}

/// The likelihood and its gradient over the parameters whose `partials` are given.
pub fn likelihood_and_gradient(
    model: &Discrete,
    partials: &[Partial],
    prior: &Prior,
    data: &Data,
) -> Result<Likelihood, Error> {
    Srif::new(model, partials, false)?.run(model, partials, prior, data)
}

/// The likelihood, its gradient and the sample information over the parameters whose
/// `partials` are given.
pub fn likelihood_gradient_information(
    model: &Discrete,
    partials: &[Partial],
    prior: &Prior,
    data: &Data,
) -> Result<Likelihood, Error> {
    Srif::new(model, partials, true)?.run(model, partials, prior, data)
}

fn model_error(path: &str, message: &str) -> Error {
    Error::Invalid(vec![FieldError::new(path, message)])
}

fn identity(k: usize) -> Vec<f64> {
    let mut e = vec![0.0; k * k];
    for i in 0..k {
        e[i * k + i] = 1.0;
    }
    e
}

/// a (r × k) · b (k × c), row-major (made once per filter, not per step).
fn product(a: &[f64], b: &[f64], r: usize, k: usize, c: usize) -> Vec<f64> {
    (0..r * c)
        .map(|x| (0..k).map(|y| a[x / c * k + y] * b[y * c + x % c]).sum())
        .collect()
}

/// (−X G, X u) for X = Φ⁻¹ or a derivative of it.
fn inverse_terms(x: &[f64], g: &[f64], u: &[f64], n: usize, l: usize) -> (Vec<f64>, Vec<f64>) {
    let xg = product(x, g, n, n, l).iter().map(|v| -v).collect();
    (xg, product(x, u, n, n, 1))
}

/// M = Φ(L⁻¹ D L⁻ᵀ) into `out` (k × k): the strictly lower part and half the diagonal,
/// so that ∂L = L M when ∂(L Lᵀ) = D, L lower triangular.
fn sandwich_factor(l: &[f64], d: &[f64], k: usize, out: &mut [f64]) {
    let x = &mut out[..k * k];
    x.copy_from_slice(&d[..k * k]);
    solve_lower(l, x, k, k); // L⁻¹ D
    for i in 0..k {
        for j in 0..i {
            x.swap(i * k + j, j * k + i);
        }
    }
    solve_lower(l, x, k, k); // L⁻¹ (L⁻¹ D)ᵀ = L⁻¹ D L⁻ᵀ (D symmetric)
    for i in 0..k {
        x[i * k + i] *= 0.5;
        for j in i + 1..k {
            x[i * k + j] = 0.0;
        }
    }
}

/// A⁻¹ of the N × N row-major `a` (LU with partial pivoting, nalgebra), or None if
/// it is singular or its inverse is not finite.
fn invert(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let m = nalgebra::DMatrix::from_row_slice(n, n, a);
    let inv = m.try_inverse()?;
    let out: Vec<f64> = (0..n * n).map(|k| inv[(k / n, k % n)]).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}
