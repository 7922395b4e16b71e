//! The square-root information filter and the likelihood from its arrays (METHOD §3,
//! seed 003 (2.1.10)–(2.1.15), (2.2.3)–(2.2.4)).
//!
//! The information array [R̃ | z̃] (P̃ = R̃⁻¹R̃⁻ᵀ, x̃ = R̃⁻¹z̃) is updated by orthogonal
//! transformations only ([`triangularise`]); no covariance is formed, so the
//! likelihood stays accurate where a covariance filter's P loses positive
//! definiteness (a vague prior with a nearly exact sensor).

use super::model::{Data, Discrete, Prior, PriorAt};
use crate::error::Error;
use crate::numerics::householder::triangularise;
use crate::numerics::linalg::{cholesky, solve_lower};

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
}

impl Likelihood {
    /// J less the 2π constant: ½ Σ (νᵀS⁻¹ν + ln det S).
    pub fn j_without_constant(&self) -> f64 {
        self.data_part + self.model_part
    }
}

/// The filter's arrays and buffers, sized once for a model; [`Srif::likelihood`]
/// then allocates nothing per step.
pub struct Srif {
    n: usize,
    l: usize,
    m: usize,
    /// [R̃ | z̃] or [R̂ | ẑ]: N × (N + 1).
    info: Vec<f64>,
    /// The measurement-update array: (N + m) × (N + 1).
    meas: Vec<f64>,
    /// The time-update array: (L + N) × (L + N + 1).
    time: Vec<f64>,
    /// Φ⁻¹ (N × N), −Φ⁻¹G (N × L) and Φ⁻¹u (N), made once.
    phi_inv: Vec<f64>,
    phi_inv_g: Vec<f64>,
    phi_inv_u: Vec<f64>,
    /// R_w, with R_wᵀR_w = Q⁻¹ (L × L; R_w = L_Q⁻¹, lower triangular).
    r_w: Vec<f64>,
    /// The factor of the available measurements' R, the mask it is of, and ln det.
    r_chol: Vec<f64>,
    r_mask: Vec<bool>,
    r_ln_det: f64,
    /// The available measurements' indices, and the whitened H rows and z.
    avail: Vec<usize>,
    h_w: Vec<f64>,
    z_w: Vec<f64>,
}

impl Srif {
    /// The filter for `model`, with Φ⁻¹ and R_w made (the time update (2.1.13) needs
    /// both: Φ must be invertible and Q positive definite).
    pub fn new(model: &Discrete) -> Result<Srif, Error> {
        let (n, l, m) = (model.n, model.l, model.m);
        let phi_inv = invert(&model.phi, n).ok_or_else(|| {
            model_error(
                "system.transition",
                "the transition Φ is singular; the SRIF's time update (METHOD §3 (2.1.13)) needs Φ⁻¹",
            )
        })?;
        let mut phi_inv_g = vec![0.0; n * l];
        let mut phi_inv_u = vec![0.0; n];
        for i in 0..n {
            for k in 0..n {
                let p = phi_inv[i * n + k];
                for c in 0..l {
                    phi_inv_g[i * l + c] -= p * model.g[k * l + c];
                }
                phi_inv_u[i] += p * model.u[k];
            }
        }
        let mut r_w = model.q.clone();
        if !cholesky(&mut r_w, l) {
            return Err(model_error(
                "system.w",
                "the process noise's covariance Q is not positive definite; the SRIF's time update (METHOD §3 (2.1.13)) needs Q⁻¹",
            ));
        }
        let mut eye = vec![0.0; l * l];
        for i in 0..l {
            eye[i * l + i] = 1.0;
        }
        solve_lower(&r_w, &mut eye, l, l);
        Ok(Srif {
            n,
            l,
            m,
            info: vec![0.0; n * (n + 1)],
            meas: vec![0.0; (n + m) * (n + 1)],
            time: vec![0.0; (l + n) * (l + n + 1)],
            phi_inv,
            phi_inv_g,
            phi_inv_u,
            r_w: eye,
            r_chol: vec![0.0; m * m],
            r_mask: Vec::new(),
            r_ln_det: 0.0,
            avail: Vec::with_capacity(m),
            h_w: vec![0.0; m * n],
            z_w: vec![0.0; m],
        })
    }

    /// J(θ) of `data` under `model` (the model this filter was made for), from `prior`.
    pub fn likelihood(
        &mut self,
        model: &Discrete,
        prior: &Prior,
        data: &Data,
    ) -> Result<Likelihood, Error> {
        let m = self.m;
        debug_assert_eq!(data.m, m);
        self.set_prior(prior)?;
        self.r_mask.clear();
        let mut out = Likelihood {
            j: 0.0,
            data_part: 0.0,
            model_part: 0.0,
            measurements: 0,
        };
        for k in 0..data.rows() {
            if k > 0 || prior.at == PriorAt::T0 {
                self.time_update();
            }
            let z = &data.z[k * m..k * m + m];
            self.avail.clear();
            self.avail.extend((0..m).filter(|&j| !z[j].is_nan()));
            if !self.avail.is_empty() {
                let (e2, ln_det_s) = self.measurement_update(model, z, data.t[k], k)?;
                out.data_part += 0.5 * e2;
                out.model_part += 0.5 * ln_det_s;
                out.measurements += self.avail.len();
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

    /// [R̃ | z̃] of x ~ N(x0, P0): R̃ = T L⁻¹ (P0 = L Lᵀ, T orthogonal, R̃ upper
    /// triangular), z̃ = R̃ x0.
    fn set_prior(&mut self, prior: &Prior) -> Result<(), Error> {
        let n = self.n;
        let mut l = prior.p0.clone();
        if !cholesky(&mut l, n) {
            return Err(model_error(
                "system.eta0",
                "the initial covariance P0 is not positive definite; the SRIF starts from its inverse (every initial SKO must be positive)",
            ));
        }
        // [L⁻¹ | L⁻¹x0] = L⁻¹ [I | x0]
        let cols = n + 1;
        self.info.fill(0.0);
        for i in 0..n {
            self.info[i * cols + i] = 1.0;
            self.info[i * cols + n] = prior.x0[i];
        }
        solve_lower(&l, &mut self.info, n, cols);
        // Lower triangular so far: made upper, as every array after an update is.
        triangularise(&mut self.info, n, cols, n);
        Ok(())
    }

    /// The measurement update (2.1.10)–(2.1.12) with the available measurements:
    /// T [R̃ z̃; H̄ z̄] = [R̂ ẑ; 0 e]. Returns ‖e‖² and ln det S.
    fn measurement_update(
        &mut self,
        model: &Discrete,
        z: &[f64],
        t: f64,
        k: usize,
    ) -> Result<(f64, f64), Error> {
        let (n, m) = (self.n, self.m);
        let ma = self.avail.len();
        let cols = n + 1;
        if self.r_mask.len() != m || (0..m).any(|j| self.r_mask[j] == z[j].is_nan()) {
            self.factor_r(model, z, t, k)?;
        }
        // H̄ = L⁻¹ H_a, z̄ = L⁻¹ z_a (2.1.11)–(2.1.12)
        for (r, &j) in self.avail.iter().enumerate() {
            self.h_w[r * n..r * n + n].copy_from_slice(&model.h[j * n..j * n + n]);
            self.z_w[r] = z[j];
        }
        solve_lower(&self.r_chol, &mut self.h_w[..ma * n], ma, n);
        solve_lower(&self.r_chol, &mut self.z_w[..ma], ma, 1);
        let rows = n + ma;
        let a = &mut self.meas[..rows * cols];
        a[..n * cols].copy_from_slice(&self.info);
        let ln_det_prior: f64 = (0..n).map(|i| self.info[i * cols + i].abs().ln()).sum();
        for r in 0..ma {
            let row = &mut a[(n + r) * cols..(n + r + 1) * cols];
            row[..n].copy_from_slice(&self.h_w[r * n..r * n + n]);
            row[n] = self.z_w[r];
        }
        triangularise(a, rows, cols, n);
        self.info.copy_from_slice(&a[..n * cols]);
        let e2: f64 = (n..rows).map(|r| a[r * cols + n] * a[r * cols + n]).sum();
        let ln_det_post: f64 = (0..n).map(|i| a[i * cols + i].abs().ln()).sum();
        Ok((e2, self.r_ln_det + 2.0 * ln_det_post - 2.0 * ln_det_prior))
    }

    /// The Cholesky factor of R over the available measurements, and its ln det.
    fn factor_r(&mut self, model: &Discrete, z: &[f64], t: f64, k: usize) -> Result<(), Error> {
        let m = self.m;
        let ma = self.avail.len();
        for (a, &i) in self.avail.iter().enumerate() {
            for (b, &j) in self.avail.iter().enumerate() {
                self.r_chol[a * ma + b] = model.r[i * m + j];
            }
        }
        if !cholesky(&mut self.r_chol[..ma * ma], ma) {
            return Err(Error::Numerical {
                step: k as u64 + 1,
                t,
                path: "measurement.v".into(),
                message: "the measurement noise's covariance R (of the measurements available at this step) is not positive definite; the likelihood needs R⁻¹".into(),
            });
        }
        self.r_ln_det = (0..ma).map(|i| 2.0 * self.r_chol[i * ma + i].ln()).sum();
        self.r_mask.clear();
        self.r_mask.extend(z.iter().map(|v| !v.is_nan()));
        Ok(())
    }

    /// The time update (2.1.13): with x_k = Φ⁻¹(x_{k+1} − u − G w),
    /// T [R_w 0 0; −R̂Φ⁻¹G R̂Φ⁻¹ ẑ + R̂Φ⁻¹u] = [R̃_w R̃_wx z̃_w; 0 R̃_{k+1} z̃_{k+1}].
    fn time_update(&mut self) {
        let (n, l) = (self.n, self.l);
        let cols = l + n + 1;
        let ic = n + 1;
        let a = &mut self.time;
        a.fill(0.0);
        for i in 0..l {
            a[i * cols..i * cols + l].copy_from_slice(&self.r_w[i * l..i * l + l]);
        }
        for i in 0..n {
            let row = &mut a[(l + i) * cols..(l + i + 1) * cols];
            let info = &self.info[i * ic..i * ic + ic];
            // R̂ is upper triangular: its row i starts at column i.
            for k in i..n {
                let r = info[k];
                for c in 0..l {
                    row[c] += r * self.phi_inv_g[k * l + c];
                }
                for c in 0..n {
                    row[l + c] += r * self.phi_inv[k * n + c];
                }
                row[l + n] += r * self.phi_inv_u[k];
            }
            row[l + n] += info[n];
        }
        triangularise(a, l + n, cols, l + n);
        for i in 0..n {
            let src = &a[(l + i) * cols + l..(l + i + 1) * cols];
            self.info[i * ic..i * ic + ic].copy_from_slice(src);
        }
    }
}

/// The likelihood of `data` under `model` from `prior` (a filter made for the call).
pub fn likelihood(model: &Discrete, prior: &Prior, data: &Data) -> Result<Likelihood, Error> {
    Srif::new(model)?.likelihood(model, prior, data)
}

fn model_error(path: &str, message: &str) -> Error {
    Error::Invalid(vec![crate::error::FieldError::new(path, message)])
}

/// A⁻¹ of the N × N row-major `a` (LU with partial pivoting, nalgebra), or None if
/// it is singular or its inverse is not finite.
fn invert(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let m = nalgebra::DMatrix::from_row_slice(n, n, a);
    let inv = m.try_inverse()?;
    let out: Vec<f64> = (0..n * n).map(|k| inv[(k / n, k % n)]).collect();
    out.iter().all(|v| v.is_finite()).then_some(out)
}
