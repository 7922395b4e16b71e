//! A model of kea's format at one θ, as the SRIF reads it: its [`Discrete`] matrices
//! and [`Prior`] (METHOD §3 (1.4.1)–(1.4.2): Φ = `transition`, G = `b`, Q = W, H = C,
//! R = Γ V Γᵀ, x0 = y0, P0 = diag η0²) — or, for a continuous model (`a`), the
//! analysis's discretisation (METHOD §1.2: Φ = I + aΔt, u Δt, G = bΔt, Q = W) — and
//! their derivatives with respect to the estimated params, from the entries'
//! expressions (`expr::compile_const_with_derivatives`: exact, never a finite
//! difference).

use super::model::{Discrete, Partial, Prior};
use crate::error::{Error, FieldError};
use crate::expr::compile_const_with_derivatives;
use crate::model::compile::{CompiledModel, MeasurementNoise};
use crate::model::params::{EntryRef, Member};
use crate::model::{Model, Overrides};

/// The model compiled in its own form: a discrete one (`system.transition`, or
/// neither `transition` nor `a`: the error says what is missing) by
/// [`crate::model::compile_discrete`], a continuous one (`a`) by
/// [`crate::model::compile`].
pub fn compile(model: &Model, params: &Overrides) -> Result<CompiledModel, Error> {
    if model.system.transition.is_some() || model.system.a.is_empty() {
        crate::model::compile_discrete(model, params)
    } else {
        crate::model::compile(model, params)
    }
}

/// Δt of a continuous model's discretisation, None for a discrete model.
fn step(c: &CompiledModel) -> Option<f64> {
    c.transition
        .is_none()
        .then(|| (c.t_end - c.t0) / c.max_steps() as f64)
}

/// What the identification needs of a compiled model beyond what compiling checks:
/// entries constant in t, no schedule, a fixed number of steps.
pub fn check(c: &CompiledModel) -> Result<(), Error> {
    let mut errors = Vec::new();
    let constant = [
        ("system.a", c.a.is_constant()),
        ("system.u", c.u.is_constant()),
        ("system.b", c.b.is_constant()),
        (noise_path(&c.noise), c.noise.matrix().is_constant()),
    ];
    for (path, ok) in constant {
        if !ok {
            errors.push(FieldError::new(
                path,
                "the identification's model is time-invariant: its entries may depend on the params, not on t",
            ));
        }
    }
    if c.schedule.is_some() {
        errors.push(FieldError::new(
            "measurement.schedule",
            "the identification reads missing measurements from the data (an empty cell): leave the schedule out",
        ));
    }
    if matches!(c.steps, crate::model::compile::StepPlan::Auto { .. }) {
        errors.push(FieldError::new(
            "time.steps",
            "the identification's data sit on a fixed grid: give the number of steps D, not \"auto\"",
        ));
    }
    match errors.is_empty() {
        true => Ok(()),
        false => Err(Error::Invalid(errors)),
    }
}

/// The model at the params `params` (the model's own with the overrides applied):
/// compiled in its form ([`compile`]), checked for what the SRIF needs ([`check`]),
/// with ∂/∂θ_i of every entry for each name in `estimated`.
pub fn at(
    model: &Model,
    params: &Overrides,
    estimated: &[&str],
) -> Result<(Discrete, Prior, Vec<Partial>), Error> {
    let compiled = compile(model, params)?;
    let (discrete, prior) = matrices(&compiled)?;
    let mut values = model.params.clone();
    values.extend(params.iter().map(|(k, v)| (k.clone(), *v)));
    let partials = estimated
        .iter()
        .enumerate()
        .map(|(i, name)| partial(model, &compiled, &discrete, &values, estimated, i, name))
        .collect::<Result<Vec<_>, _>>()?;
    Ok((discrete, prior, partials))
}

/// The SRIF's matrices from a compiled model ([`check`]ed: missing measurements are
/// the data's empty cells).
fn matrices(c: &CompiledModel) -> Result<(Discrete, Prior), Error> {
    check(c)?;
    let (n, nm) = (c.n_states(), c.n_measurements());
    let l = c.b.cols;
    let gamma = gamma(c, &c.noise.matrix().values, &c.c);
    let mm = c.noise.sources();
    // A continuous model discretised as the analysis does (METHOD §1.2, (1.11)).
    let dt = step(c);
    let scaled = |v: &[f64]| -> Vec<f64> { v.iter().map(|x| x * dt.unwrap_or(1.0)).collect() };
    let phi = match &c.transition {
        Some(phi) => phi.clone(),
        None => (0..n * n)
            .map(|k| f64::from(u8::from(k / n == k % n)) + c.a.values[k] * dt.unwrap_or(1.0))
            .collect(),
    };
    let discrete = Discrete {
        n,
        l,
        m: nm,
        phi,
        u: scaled(&c.u.values),
        g: scaled(&c.b.values),
        q: c.w.clone(),
        h: c.c.clone(),
        r: sandwich(&gamma, &c.v, None, nm, mm),
    };
    let prior = Prior {
        x0: c.y0.clone(),
        p0: diagonal_squares(&c.eta0),
        at: c.prior_at,
    };
    Ok((discrete, prior))
}

fn noise_path(noise: &MeasurementNoise) -> &'static str {
    match noise {
        MeasurementNoise::Gamma(_) => "measurement.gamma",
        MeasurementNoise::SeedG(_) => "measurement.g",
    }
}

/// Γ (n × M): `gamma` itself, or C g in the seed's form.
fn gamma(c: &CompiledModel, noise: &[f64], h: &[f64]) -> Vec<f64> {
    let (n, nm, mm) = (c.n_states(), c.n_measurements(), c.noise.sources());
    match c.noise {
        MeasurementNoise::Gamma(_) => noise.to_vec(),
        MeasurementNoise::SeedG(_) => {
            let mut out = vec![0.0; nm * mm];
            crate::numerics::linalg::mul(&mut out, h, noise, nm, n, mm);
            out
        }
    }
}

/// A V Bᵀ (r × r) with A, B r × k (B = A when `b` is None) and V k × k.
fn sandwich(a: &[f64], v: &[f64], b: Option<&[f64]>, r: usize, k: usize) -> Vec<f64> {
    let b = b.unwrap_or(a);
    let mut av = vec![0.0; r * k];
    crate::numerics::linalg::mul(&mut av, a, v, r, k, k);
    let mut out = vec![0.0; r * r];
    for i in 0..r {
        for j in 0..r {
            out[i * r + j] = (0..k).map(|q| av[i * k + q] * b[j * k + q]).sum();
        }
    }
    out
}

fn diagonal_squares(sko: &[f64]) -> Vec<f64> {
    let n = sko.len();
    let mut out = vec![0.0; n * n];
    for i in 0..n {
        out[i * n + i] = sko[i] * sko[i];
    }
    out
}

/// ∂(model, prior)/∂θ_i: each entry that names θ_i differentiated, then the derived
/// matrices by the product rule — ∂Q_ll = 2φ_l ∂φ_l (SKOs), ∂P0_ii = 2η0_i ∂η0_i,
/// ∂R = ∂Γ V Γᵀ + Γ ∂V Γᵀ + Γ V ∂Γᵀ with ∂Γ = ∂C g + C ∂g in the seed's form.
fn partial(
    model: &Model,
    c: &CompiledModel,
    d: &Discrete,
    params: &Overrides,
    estimated: &[&str],
    i: usize,
    name: &str,
) -> Result<Partial, Error> {
    let mut p = Partial::zero(d);
    let (n, l, nm, mm) = (d.n, d.l, d.m, c.noise.sources());
    // ∂(I + aΔt) = ∂a Δt, ∂(u Δt) = ∂u Δt, ∂(bΔt) = ∂b Δt; 1 in a discrete model.
    let dt = step(c).unwrap_or(1.0);
    let mut d_noise = vec![0.0; c.noise.matrix().values.len()];
    let mut d_v = vec![0.0; mm * mm];
    let mut errors = Vec::new();
    for entry in c.param_dependence.entries(name) {
        let Some(value) = entry.value(model) else {
            continue;
        };
        let dx = match compile_const_with_derivatives(value, params, estimated, &entry.path()) {
            Ok((_, dx)) => dx[i],
            Err(e) => {
                errors.push(e);
                continue;
            }
        };
        let EntryRef { member, row, col } = *entry;
        match member {
            Member::Transition => p.phi[row * n + col] = dx,
            Member::A => p.phi[row * n + col] = dx * dt,
            Member::U => p.u[row] = dx * dt,
            Member::B => p.g[row * l + col] = dx * dt,
            Member::W => p.q[row * l + col] = dx,
            Member::Phi => p.q[row * l + row] = 2.0 * c.phi[row] * dx,
            Member::C => p.h[row * n + col] = dx,
            Member::Gamma => d_noise[row * mm + col] = dx,
            Member::G => d_noise[row * mm + col] = dx,
            Member::V => d_v[row * mm + col] = dx,
            Member::Psi => d_v[row * mm + row] = 2.0 * c.psi[row] * dx,
            Member::Y0 => p.x0[row] = dx,
            Member::Eta0 => p.p0[row * n + row] = 2.0 * c.eta0[row] * dx,
            // Refused by `check` (a schedule).
            Member::When => {}
        }
    }
    if !errors.is_empty() {
        return Err(Error::Invalid(errors));
    }
    let g = gamma(c, &c.noise.matrix().values, &c.c);
    // ∂Γ = ∂gamma, or ∂C g + C ∂g.
    let dg = match c.noise {
        MeasurementNoise::Gamma(_) => d_noise,
        MeasurementNoise::SeedG(_) => {
            let mut a = gamma(c, &c.noise.matrix().values, &p.h);
            let b = gamma(c, &d_noise, &c.c);
            a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
            a
        }
    };
    let one = sandwich(&dg, &c.v, Some(&g), nm, mm);
    let two = sandwich(&g, &d_v, None, nm, mm);
    for a in 0..nm {
        for b in 0..nm {
            p.r[a * nm + b] = one[a * nm + b] + one[b * nm + a] + two[a * nm + b];
        }
    }
    Ok(p)
}
