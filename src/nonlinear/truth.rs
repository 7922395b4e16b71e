//! Data simulated from a *truth* (`data.truth`), seeded and reproducible: a model
//! that may differ from the filter's — another f, other params (`set`), unmodelled
//! inputs u(x, t) added to f, other noises — so that the procedure can be tried where
//! the filter's model is wrong, with the true errors known.
//!
//! ```text
//!     dx = (f_true(x, t) + u(x, t)) dt + dβ,  dβ of intensity W_true;  y_n = h_true(x(t_n)) + v_n
//! ```
//!
//! integrated by Euler–Maruyama at Δt/`substeps` (default 10). The draws, from one
//! ChaCha8 stream of `seed`: the initial state (only when `y0` is not given: then
//! x(t0) ~ N(y0, P0) of the model), then per step n = 1…D each substep's N process
//! normals, then the m measurement normals at t_n. A truth leaving f's domain is an
//! error at `data.truth`'s path with the step and the state.

use super::data::Measured;
use super::model::{Compiled, NonlinearModel, compile};
use crate::error::{Error, FieldError, member_path};
use crate::expr::{StateFn, Value};
use crate::json::from_value_at;
use crate::model::Overrides;
use crate::numerics::linalg::cholesky;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::Deserialize;

/// The most substeps per step.
pub const MAX_SUBSTEPS: u64 = 1000;

/// `data.truth` as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthSpec {
    pub seed: u64,
    #[serde(default)]
    pub set: Overrides,
    #[serde(default)]
    pub f: Option<Vec<Value>>,
    #[serde(default)]
    pub input: Option<Vec<Value>>,
    #[serde(default)]
    pub y0: Option<Vec<Value>>,
    #[serde(default)]
    pub phi: Option<Vec<Value>>,
    #[serde(default, rename = "W")]
    pub w: Option<Vec<Vec<Value>>>,
    #[serde(default)]
    pub psi: Option<Vec<Value>>,
    #[serde(default, rename = "V")]
    pub v: Option<Vec<Vec<Value>>>,
    #[serde(default = "default_substeps")]
    pub substeps: u64,
}

fn default_substeps() -> u64 {
    10
}

/// A truth ready to simulate.
#[derive(Clone, Debug)]
pub struct Truth {
    pub model: Compiled,
    pub input: Option<Vec<StateFn>>,
    pub draw_initial: bool,
    pub seed: u64,
    pub substeps: usize,
    /// Where f sits in the request (`data.truth.f` or `model.system.f`), for errors.
    pub f_path: String,
}

/// Read and compile `value` (at `path`, `data.truth`) against the filter's `model`
/// and its overrides `set`.
pub fn read(
    value: &serde_json::Value,
    model: &NonlinearModel,
    set: &Overrides,
    path: &str,
) -> Result<Truth, Error> {
    let spec: TruthSpec = from_value_at(
        value.clone(),
        &[("seed", "the random stream's seed, a whole number")],
    )
    .map_err(|e| e.with_prefix(path))?;
    if !(1..=MAX_SUBSTEPS).contains(&spec.substeps) {
        return Err(Error::invalid(
            member_path(path, "substeps"),
            format!(
                "expected 1 to {MAX_SUBSTEPS} substeps, got {}",
                spec.substeps
            ),
        ));
    }
    let mut truth = model.clone();
    let mut given: Vec<(&str, &str)> = Vec::new();
    if let Some(f) = &spec.f {
        truth.system.f = f.clone();
        given.push(("system.f", "f"));
    }
    if let Some(y0) = &spec.y0 {
        truth.system.y0 = y0.clone();
        given.push(("system.y0", "y0"));
    }
    if spec.phi.is_some() || spec.w.is_some() {
        truth.system.phi = spec.phi.clone();
        truth.system.w = spec.w.clone();
        given.push(("system.phi", "phi"));
        given.push(("system.W", "W"));
    }
    if spec.psi.is_some() || spec.v.is_some() {
        truth.measurement.psi = spec.psi.clone();
        truth.measurement.v = spec.v.clone();
        given.push(("measurement.psi", "psi"));
        given.push(("measurement.V", "V"));
    }
    let mut all = set.clone();
    all.extend(spec.set.iter().map(|(k, v)| (k.clone(), *v)));
    let compiled = compile(&truth, &all).map_err(|e| {
        e.map_paths(|p| {
            for (model_path, member) in &given {
                if let Some(rest) = p.strip_prefix(model_path) {
                    return format!("{path}.{member}{rest}");
                }
            }
            if p.starts_with("set") && spec.set.keys().any(|k| p == member_path("set", k)) {
                return format!("{path}.{p}");
            }
            member_path("model", p)
        })
    })?;
    let input = match &spec.input {
        None => None,
        Some(u) => {
            let n = compiled.n_states();
            if u.len() != n {
                return Err(Error::invalid(
                    member_path(path, "input"),
                    format!("has {} expressions, expected {n} (N = {n})", u.len()),
                ));
            }
            let mut out = Vec::with_capacity(n);
            let mut errors: Vec<FieldError> = Vec::new();
            for (i, v) in u.iter().enumerate() {
                let p = format!("{path}.input[{i}]");
                match StateFn::compile(v, &compiled.states, &compiled.params, &p) {
                    Ok(f) => out.push(f),
                    Err(e) => errors.push(e),
                }
            }
            if !errors.is_empty() {
                return Err(Error::Invalid(errors));
            }
            Some(out)
        }
    };
    Ok(Truth {
        model: compiled,
        input,
        draw_initial: spec.y0.is_none(),
        seed: spec.seed,
        substeps: spec.substeps as usize,
        f_path: if spec.f.is_some() {
            format!("{path}.f")
        } else {
            "model.system.f".into()
        },
    })
}

/// A square-root factor L (L Lᵀ = c, k×k lower): the Cholesky factor, or for a
/// diagonal c with zeros the square roots of its diagonal.
fn factor(c: &[f64], k: usize, path: &str) -> Result<Vec<f64>, Error> {
    let diagonal = (0..k).all(|i| (0..k).all(|j| i == j || c[i * k + j] == 0.0));
    if diagonal {
        let mut f = vec![0.0; k * k];
        for i in 0..k {
            f[i * k + i] = c[i * k + i].sqrt();
        }
        return Ok(f);
    }
    let mut f = c.to_vec();
    if !cholesky(&mut f, k) {
        return Err(Error::invalid(
            path,
            "a covariance with correlations must be positive definite to be simulated (a diagonal one may have zeros)",
        ));
    }
    for i in 0..k {
        for j in i + 1..k {
            f[i * k + j] = 0.0;
        }
    }
    Ok(f)
}

/// Simulate the truth on its grid: the measurements and the true states at t_0…t_D.
/// `path` is `data.truth`, for errors.
pub fn simulate(truth: &Truth, path: &str) -> Result<Measured, Error> {
    // (A copy: evaluating an expression writes its buffers.)
    let mut model = truth.model.clone();
    let mut input = truth.input.clone();
    let (n, m, d) = (model.n_states(), model.n_measurements(), model.steps);
    let lw = factor(&model.w, n, &format!("{path}.W"))?;
    let lv = factor(&model.v, m, &format!("{path}.V"))?;
    let lp = factor(&model.p0, n, "model.system.P0")?;
    let mut rng = ChaCha8Rng::seed_from_u64(truth.seed);
    let mut normal = move || -> f64 { StandardNormal.sample(&mut rng) };
    let mut xi = vec![0.0; n.max(m)];
    let mut x = model.y0.clone();
    if truth.draw_initial {
        for v in xi[..n].iter_mut() {
            *v = normal();
        }
        for i in 0..n {
            x[i] += (0..=i).map(|j| lp[i * n + j] * xi[j]).sum::<f64>();
        }
    }
    let h = model.dt / truth.substeps as f64;
    let sqrt_h = h.sqrt();
    let mut states = vec![0.0; (d + 1) * n];
    states[..n].copy_from_slice(&x);
    let mut y = vec![f64::NAN; d * m];
    let mut dx = vec![0.0; n];
    for step in 1..=d {
        let t_start = model.t(step - 1);
        for s in 0..truth.substeps {
            let t = t_start + s as f64 * h;
            for i in 0..n {
                let mut v = model.f[i].value(&x, t);
                let mut what = (
                    "f",
                    format!("{}[{i}]", truth.f_path),
                    model.f[i].text().to_string(),
                );
                if let Some(u) = &mut input {
                    let ui = u[i].value(&x, t);
                    if !ui.is_finite() {
                        what = (
                            "input",
                            format!("{path}.input[{i}]"),
                            u[i].text().to_string(),
                        );
                    }
                    v += ui;
                }
                if !v.is_finite() {
                    return Err(out_of_domain(&model, &x, step as u64, t, what));
                }
                dx[i] = v * h;
            }
            for v in xi[..n].iter_mut() {
                *v = normal();
            }
            for i in 0..n {
                let noise: f64 = (0..=i).map(|j| lw[i * n + j] * xi[j]).sum();
                x[i] += dx[i] + sqrt_h * noise;
            }
        }
        let t = model.t(step);
        states[step * n..(step + 1) * n].copy_from_slice(&x);
        for v in xi[..m].iter_mut() {
            *v = normal();
        }
        for j in 0..m {
            let hv = model.h[j].value(&x, t);
            if !hv.is_finite() {
                let what = (
                    "h",
                    format!("model.measurement.h[{j}]"),
                    model.h[j].text().to_string(),
                );
                return Err(out_of_domain(&model, &x, step as u64, t, what));
            }
            let noise: f64 = (0..=j).map(|k| lv[j * m + k] * xi[k]).sum();
            y[(step - 1) * m + j] = hv + noise;
        }
    }
    Ok(Measured {
        y,
        truth: Some(states),
        ignored: Vec::new(),
    })
}

fn out_of_domain(
    model: &Compiled,
    x: &[f64],
    step: u64,
    t: f64,
    (what, path, text): (&str, String, String),
) -> Error {
    let state: Vec<String> = model
        .states
        .iter()
        .zip(x)
        .map(|(s, v)| format!("{s} = {}", crate::text::num(*v)))
        .collect();
    Error::Numerical {
        step,
        t,
        path,
        message: format!(
            "the truth's {what} = \"{text}\" is not finite at {}: the simulated state left the expression's domain",
            state.join(", ")
        ),
    }
}
