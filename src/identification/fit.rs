//! The fit: J(θ) of the request's data through the SRIF ([`super::srif`]) minimised
//! over the estimated params ([`super::minimise`]), then the statistics at θ̂ — the
//! sample information and the standard errors it gives, the observed information, the
//! correlations and the identifiability verdict, and on request the expected
//! information with the Cramér–Rao bound (METHOD §3 (2.3.2)).

use super::discrete;
use super::minimise::{self, Bounds, Evaluation, Failure, Objective, Options};
use super::request::IdentificationRequest;
use super::result::{
    Identifiability, IdentificationResult, InnovationSeries, IterationRecord, Optimum,
    ParamEstimate,
};
use super::srif::{Likelihood, Srif};
use crate::error::Error;
use crate::kind::Timing;
use crate::progress::Progress;
use std::collections::BTreeMap;
use std::ops::ControlFlow;

/// The information's smallest eigenvalue, relative to its largest, below which the
/// data are said not to determine a direction of θ (the references' threshold).
pub const RANK_THRESHOLD: f64 = 1e-9;
/// The normal quantile of a 95 % interval.
const Z_95: f64 = 1.959_963_984_540_054;

/// The likelihood of the request's data as a function of the estimated params.
struct Likelihoods<'a> {
    request: &'a IdentificationRequest,
    names: Vec<&'a str>,
    progress: &'a mut dyn Progress,
    evaluations: usize,
    /// Evaluations at which progress is reported as done (an estimate).
    expected: f64,
}

impl Likelihoods<'_> {
    /// J (and its gradient and sample information) at θ.
    fn at(&self, theta: &[f64], gradient: bool, information: bool) -> Result<Likelihood, Error> {
        self.at_recording(theta, gradient, information, false)
    }

    /// The expected information at θ (np × np) over the data's steps and missing
    /// pattern ([`super::expected`]).
    fn expected(&self, theta: &[f64]) -> Result<Vec<f64>, Error> {
        let (model, prior, partials) = discrete::at(
            &self.request.model,
            &self.request.params_at(theta),
            &self.names,
        )?;
        super::expected::expected_information(&model, &partials, &prior, &self.request.data)
            .map_err(|e| noise_paths(e, &self.request.model))
    }

    /// [`Self::at`], the innovations recorded when `record`.
    fn at_recording(
        &self,
        theta: &[f64],
        gradient: bool,
        information: bool,
        record: bool,
    ) -> Result<Likelihood, Error> {
        let (model, prior, partials) = discrete::at(
            &self.request.model,
            &self.request.params_at(theta),
            &self.names,
        )?;
        let partials = if gradient { partials } else { Vec::new() };
        Srif::new(&model, &partials, information)
            .map(|s| if record { s.recording() } else { s })
            .and_then(|mut s| s.run(&model, &partials, &prior, &self.request.data))
            .map_err(|e| noise_paths(e, &self.request.model))
    }
}

/// The SRIF names Q and R as `system.w` and `measurement.v`: here, the member the
/// model gives them by (`phi` or `W`, `psi` or `V`).
fn noise_paths(e: Error, model: &crate::model::Model) -> Error {
    let q = if model.system.w.is_some() {
        "system.W"
    } else {
        "system.phi"
    };
    let r = if model.measurement.v.is_some() {
        "measurement.V"
    } else {
        "measurement.psi"
    };
    e.map_paths(|p| match p {
        "system.w" => q.to_string(),
        "measurement.v" => r.to_string(),
        other => other.to_string(),
    })
}

impl Objective for Likelihoods<'_> {
    type Error = Error;

    fn evaluate(&mut self, theta: &[f64], information: bool) -> Result<Evaluation, Failure<Error>> {
        self.evaluations += 1;
        let fraction = (self.evaluations as f64 / self.expected).min(0.99);
        if let ControlFlow::Break(()) = self.progress.report(fraction) {
            return Err(Failure::Abort(Error::Cancelled));
        }
        let l = self.at(theta, true, information).map_err(Failure::Domain)?;
        Ok(Evaluation {
            j: l.j,
            gradient: l.gradient,
            information: information.then_some(l.fisher_sample),
        })
    }
}

/// Fit the request: the minimiser from the initial values, then the statistics at θ̂.
pub fn identify(
    request: &IdentificationRequest,
    progress: &mut dyn Progress,
) -> Result<IdentificationResult, Error> {
    let names = request.names();
    let p = names.len();
    let theta0: Vec<f64> = request.estimate.iter().map(|e| e.initial).collect();
    let bounds = Bounds {
        min: request.estimate.iter().map(|e| e.min).collect(),
        max: request.estimate.iter().map(|e| e.max).collect(),
    };
    let options = Options {
        max_iterations: request.max_iterations,
        ..Options::default()
    };
    let mut objective = Likelihoods {
        request,
        names: names.clone(),
        progress,
        evaluations: 0,
        expected: 4.0 * request.max_iterations as f64 * (1 + request.starts.len()) as f64,
    };
    // From the initial values, then from every other start (`starts`); the lowest J
    // is the estimate, and every distinct optimum is listed.
    let mut outcomes = Vec::with_capacity(1 + request.starts.len());
    for start in std::iter::once(&theta0).chain(&request.starts) {
        let o = minimise::minimise(&mut objective, start, &bounds, request.method, &options)?;
        outcomes.push(o);
    }
    let optima = distinct_optima(&outcomes, &names);
    let best = (0..outcomes.len())
        .min_by(|&a, &b| {
            outcomes[a]
                .evaluation
                .j
                .total_cmp(&outcomes[b].evaluation.j)
        })
        .expect("one start at least");
    let outcome = outcomes.swap_remove(best);
    let theta = outcome.theta.clone();
    let mut at_hat = objective.at_recording(&theta, true, true, true)?;
    let measurement_names = request.measurement_names();
    let innovations = (at_hat.measurements > 0).then(|| {
        super::innovations::check(
            &at_hat.innovations,
            &at_hat.nis,
            &measurement_names,
            &request.data.t,
        )
    });
    let observed = observed_information(&objective, &theta);
    let expected = match request.expected_information {
        true => Some(objective.expected(&theta)?),
        false => None,
    };
    let bound = expected.as_ref().and_then(|m| {
        identifiability(m, &names, &theta)
            .identifiable
            .then(|| crate::numerics::linalg::inverse_spd(m, p))
            .flatten()
    });
    let evaluations = objective.evaluations;
    let _ = objective.progress.report(1.0);

    let fisher = std::mem::take(&mut at_hat.fisher_sample);
    let identifiability = identifiability(&fisher, &names, &theta);
    let inverse = identifiability
        .identifiable
        .then(|| crate::numerics::linalg::inverse_spd(&fisher, p))
        .flatten();
    let estimate = request
        .estimate
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let se = inverse.as_ref().map(|m| m[i * p + i].sqrt());
            let v = theta[i];
            (
                e.name.clone(),
                ParamEstimate {
                    value: v,
                    std_error: se,
                    interval: se.map(|s| [v - Z_95 * s, v + Z_95 * s]),
                    cramer_rao_sko: bound.as_ref().map(|m| m[i * p + i].sqrt()),
                    initial: e.initial,
                    min: e.min.is_finite().then_some(e.min),
                    max: e.max.is_finite().then_some(e.max),
                    at_bound: v <= e.min || v >= e.max,
                },
            )
        })
        .collect();
    let correlation = inverse.as_ref().map(|m| {
        (0..p)
            .map(|i| {
                (0..p)
                    .map(|j| m[i * p + j] / (m[i * p + i] * m[j * p + j]).sqrt())
                    .collect()
            })
            .collect()
    });
    let by_name = |v: &[f64]| -> BTreeMap<String, f64> {
        names
            .iter()
            .zip(v)
            .map(|(n, x)| (n.to_string(), *x))
            .collect()
    };
    let iterations = outcome
        .iterations
        .iter()
        .map(|it| IterationRecord {
            neg_log_likelihood: it.j,
            params: by_name(&it.theta),
            gradient_norm: it.gradient_norm,
            step: it.step,
        })
        .collect();
    Ok(IdentificationResult {
        parameters: names.iter().map(|s| s.to_string()).collect(),
        estimate,
        neg_log_likelihood: at_hat.j,
        gradient: by_name(&at_hat.gradient),
        fisher_information: rows(&fisher, p),
        observed_information: observed.map(|m| rows(&m, p)),
        expected_information: expected.map(|m| rows(&m, p)),
        correlation,
        identifiability,
        innovations,
        optima,
        method: request.method,
        converged: outcome.converged,
        stop_reason: outcome.stop.describe().to_string(),
        stop: outcome.stop,
        iterations,
        evaluations,
        steps: request.data.rows(),
        measurements: at_hat.measurements,
        timing: Timing::default(),
        series: Some(InnovationSeries {
            measurements: measurement_names,
            t: request.data.t.clone(),
            nis: std::mem::take(&mut at_hat.nis),
            innovations: std::mem::take(&mut at_hat.innovations),
        }),
    })
}

/// The distinct optima the starts reached, by J: two are one where J agrees to 1e-9
/// relatively and every param to 1e-4·max(|θ_i|, 1) — the minimisers stop within
/// ≈ 1e-5 of an optimum, while mirror optima (±w) and a local optimum differ far more.
/// Each with the starts (by index: 0 the initial values, i the i-th of `starts`) that
/// reached it.
fn distinct_optima(outcomes: &[minimise::Outcome], names: &[&str]) -> Vec<Optimum> {
    let mut out: Vec<(Vec<f64>, Optimum)> = Vec::new();
    for (k, o) in outcomes.iter().enumerate() {
        let j = o.evaluation.j;
        let same = |(t, opt): &(Vec<f64>, Optimum)| {
            (opt.neg_log_likelihood - j).abs() <= 1e-9 * j.abs().max(1.0)
                && t.iter()
                    .zip(&o.theta)
                    .all(|(a, b)| (a - b).abs() <= 1e-4 * a.abs().max(1.0))
        };
        match out.iter_mut().find(|x| same(x)) {
            Some((_, opt)) => opt.starts.push(k),
            None => out.push((
                o.theta.clone(),
                Optimum {
                    params: names
                        .iter()
                        .zip(&o.theta)
                        .map(|(n, x)| (n.to_string(), *x))
                        .collect(),
                    neg_log_likelihood: o.evaluation.j,
                    converged: o.converged,
                    starts: vec![k],
                },
            )),
        }
    }
    let mut optima: Vec<Optimum> = out.into_iter().map(|(_, o)| o).collect();
    optima.sort_by(|a, b| a.neg_log_likelihood.total_cmp(&b.neg_log_likelihood));
    optima
}

fn rows(m: &[f64], p: usize) -> Vec<Vec<f64>> {
    m.chunks(p).map(<[f64]>::to_vec).collect()
}

/// The Hessian of J at θ: central differences of the exact gradient, h_i =
/// 1e-5·max(|θ_i|, 1e-3) (truncation O(h²) and the gradient's rounding over h are both
/// ≈ 1e-9 of the information on the references), symmetrised: 2p gradient passes.
/// None where a step leaves the model's domain.
fn observed_information(l: &Likelihoods, theta: &[f64]) -> Option<Vec<f64>> {
    let p = theta.len();
    let mut h = vec![0.0; p * p];
    for i in 0..p {
        let step = 1e-5 * theta[i].abs().max(1e-3);
        let mut a = theta.to_vec();
        let mut b = theta.to_vec();
        a[i] += step;
        b[i] -= step;
        let ga = l.at(&a, true, false).ok()?.gradient;
        let gb = l.at(&b, true, false).ok()?.gradient;
        for j in 0..p {
            h[j * p + i] = (ga[j] - gb[j]) / (a[i] - b[i]);
        }
    }
    for i in 0..p {
        for j in 0..i {
            let s = 0.5 * (h[i * p + j] + h[j * p + i]);
            h[i * p + j] = s;
            h[j * p + i] = s;
        }
    }
    Some(h)
}

/// The verdict from the eigen-decomposition of the information `m` (p × p).
fn identifiability(m: &[f64], names: &[&str], theta: &[f64]) -> Identifiability {
    let p = names.len();
    let eigen = nalgebra::DMatrix::from_row_slice(p, p, m).symmetric_eigen();
    let mut order: Vec<usize> = (0..p).collect();
    order.sort_by(|&a, &b| eigen.eigenvalues[a].total_cmp(&eigen.eigenvalues[b]));
    let eigenvalues: Vec<f64> = order.iter().map(|&k| eigen.eigenvalues[k]).collect();
    let (min, max) = (eigenvalues[0], eigenvalues[p - 1]);
    let weakest: Vec<f64> = (0..p).map(|i| eigen.eigenvectors[(i, order[0])]).collect();
    // The sign that makes the largest component positive, for a stable output.
    let big = weakest
        .iter()
        .copied()
        .fold(0.0f64, |a, x| if x.abs() > a.abs() { x } else { a });
    let weakest: Vec<f64> = weakest
        .iter()
        .map(|x| if big < 0.0 { -x } else { *x })
        .collect();
    let rank = eigenvalues
        .iter()
        .filter(|&&e| e > RANK_THRESHOLD * max)
        .count();
    let identifiable = max > 0.0 && min > RANK_THRESHOLD * max;
    let verdict = if identifiable {
        let kappa = max / min;
        let kappa = if kappa < 1e4 {
            format!("{kappa:.1}")
        } else {
            format!("{kappa:.2e}")
        };
        format!("identifiable: the information's condition number is {kappa}")
    } else {
        null_direction(names, theta, &weakest)
    };
    Identifiability {
        identifiable,
        eigenvalues,
        condition: (min > 0.0).then(|| max / min),
        weakest_direction: names
            .iter()
            .zip(&weakest)
            .map(|(n, x)| (n.to_string(), *x))
            .collect(),
        rank,
        verdict,
    }
}

/// What a null direction v of the information means, in words: the params it moves
/// (|v_i| > 0.1), and for two of them whether it keeps their product (relative
/// changes v_i/θ_i opposite) or their ratio (equal).
fn null_direction(names: &[&str], theta: &[f64], v: &[f64]) -> String {
    let moved: Vec<usize> = (0..v.len()).filter(|&i| v[i].abs() > 0.1).collect();
    let list = |idx: &[usize]| idx.iter().map(|&i| names[i]).collect::<Vec<_>>().join(", ");
    match moved.as_slice() {
        [i] => format!(
            "not identifiable: the data do not determine {} (J does not change with it at the optimum)",
            names[*i]
        ),
        [i, j] if theta[*i] != 0.0 && theta[*j] != 0.0 => {
            let (a, b) = (v[*i] / theta[*i], v[*j] / theta[*j]);
            let scale = a.abs().max(b.abs());
            let (ni, nj) = (names[*i], names[*j]);
            if (a + b).abs() < 0.05 * scale {
                format!("not identifiable: only {ni}·{nj} is determined, not {ni} and {nj} apart")
            } else if (a - b).abs() < 0.05 * scale {
                format!("not identifiable: only {ni}/{nj} is determined, not {ni} and {nj} apart")
            } else {
                format!(
                    "not identifiable: only a combination of {ni} and {nj} is determined (J does not change along the weakest direction)"
                )
            }
        }
        _ => format!(
            "not identifiable: only a combination of {} is determined (J does not change along the weakest direction)",
            list(&moved)
        ),
    }
}
