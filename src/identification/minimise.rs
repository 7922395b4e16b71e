//! The seed's three minimisers of J(θ) (METHOD §3, "Minimisers", seed 003 (1.3),
//! (2.1.9)), over an [`Objective`] that gives J, ∂J/∂θ = g and, when asked, the Fisher
//! information M — so that they are tested on closed forms, apart from the SRIF.
//!
//! - [`Method::Scoring`] (the default; the seed's "Newton"): θ ← θ − α M⁻¹g, α from 1
//!   halved until the Armijo test holds. If M (on the free parameters) is not positive
//!   definite — Cholesky fails — M + λ·μ·I is tried with μ = max diag M and
//!   λ = 10⁻⁸, 10⁻⁶, …, 1; if that fails too (or μ ≤ 0, or M is missing), the
//!   iteration takes the gradient direction, started as [`Method::Gradient`]'s first.
//!   Once the gradient test holds, up to 20 full scoring steps polish θ̂ past what J's
//!   rounding lets a line search judge, while each lowers the decrement (`polish`).
//!   (A singular sample information is harmless: its null directions change no ν_k
//!   and no S_k, hence not J, so g has no part there and the damped step is ≈ −M⁺g.)
//! - [`Method::Gradient`]: θ ← θ − α g, α halved until J decreases (Armijo). The first
//!   trial moves θ by max(‖θ‖∞, 1) in ∞-norm; after that α is carried over, and
//!   doubled when the step was accepted without halving.
//! - [`Method::Conjugate`]: d₀ = −g₀, d_k = −g_k + β_k d_{k−1} (the seed's p_k) with
//!   Polak–Ribière+ β_k = max(0, g_kᵀ(g_k − g_{k−1}) / g_{k−1}ᵀg_{k−1}); β = 0 (a
//!   restart) every p iterations (p = dim θ), when the free set changes and when d_k
//!   is not a descent direction. Line search: the first trial α = α_{k−1}·g_{k−1}ᵀ
//!   d_{k−1} / g_kᵀd_k (at k = 0 as gradient descent's), halved until Armijo holds,
//!   then up to 3 secant steps on the directional derivative (exact on a quadratic)
//!   while |gᵀd_k| > 0.1·|g_kᵀd_k| (the strong-Wolfe curvature test), each kept only
//!   if it passes Armijo with a lower J.
//!
//! Every trial point is θ(α) = P(θ + α d), P the projection onto the [`Bounds`]; a
//! parameter at a bound whose gradient pushes outward is held for that iteration (the
//! projected gradient is 0 there), as is a held direction component pointing out. A
//! trial is accepted when J(θ(α)) < J(θ) and J(θ(α)) ≤ J(θ) + 10⁻⁴·gᵀ(θ(α) − θ), so J
//! falls strictly from one recorded iteration to the next. When a bound cuts the
//! accepted trial, the step stopping at 0.9 of the way to the bound is tried too and
//! the lower J kept: a bound may sit on a stationary point (J even in a param bounded
//! at 0), where a projected step would stay for good. A trial where θ is outside
//! the domain ([`Failure::Domain`]) or J or g is not finite counts as J = +∞.
//!
//! Stopping rules, checked at every recorded point, in this order ([`Stop`]):
//! 1. the gradient test: for scoring the Newton decrement ½ g_Fᵀ M_FF⁻¹ g_F (F the free
//!    parameters; the fall of J a Newton step promises, in log-likelihood units)
//!    ≤ `tolerance`; for the others, and scoring without a usable M, the scaled
//!    projected gradient max_i |g_i|·max(|θ_i|, 1) / max(|J|, 1) ≤ `gradient_tolerance`
//!    (it cannot go much below √ε ≈ 10⁻⁸: there J no longer resolves the steps);
//! 2. the step test: after a step, |ΔJ| ≤ `step_tolerance`·max(|J|, 1) and
//!    max_i |Δθ_i| / max(|θ_i|, 1) ≤ `step_tolerance`;
//! 3. `max_iterations` accepted steps taken;
//! 4. the line search fails: 60 halvings, or θ(α) = θ in floating point.
//!
//! Only 1 and 2 count as converged. Defaults ([`Options::default`]): 100 iterations,
//! `tolerance` 10⁻⁸, `gradient_tolerance` 10⁻⁶, `step_tolerance` 10⁻¹² (about the
//! rounding of J summed over a long record). A line-search stop with a small measure
//! is usually J's rounding, not a failure: the records show it.

use crate::numerics::linalg::{cholesky, cholesky_solve};
use serde::{Deserialize, Serialize};

const ARMIJO: f64 = 1e-4;
const CURVATURE: f64 = 0.1;
const HALVINGS: usize = 60;
const REFINEMENTS: usize = 3;
/// Scoring's polishing steps at most, and the rise of J (relative) they may make.
const POLISH: usize = 20;
const ROUNDING: f64 = 1e-13;
const FLOOR: f64 = 1e-20;
const DAMPING: [f64; 6] = [0.0, 1e-8, 1e-6, 1e-4, 1e-2, 1.0];

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Fisher scoring, θ ← θ − α M⁻¹g (asks the objective for the information).
    #[default]
    Scoring,
    /// Gradient descent with a step halved until J decreases.
    Gradient,
    /// Polak–Ribière+ nonlinear conjugate gradients.
    Conjugate,
}

/// J, g and (when asked for) M at one θ.
#[derive(Clone, Debug, PartialEq)]
pub struct Evaluation {
    pub j: f64,
    pub gradient: Vec<f64>,
    /// p×p row-major, positive semidefinite; `None` when not asked for.
    pub information: Option<Vec<f64>>,
}

/// Why an [`Objective`] gave no value.
#[derive(Clone, Debug, PartialEq)]
pub enum Failure<E> {
    /// θ is outside the model's domain: J = +∞ at a trial point, the error at θ₀.
    Domain(E),
    /// Stop now (a cancel): returned at once.
    Abort(E),
}

/// J(θ) to minimise: for identification the SRIF's likelihood; in the tests closed forms.
pub trait Objective {
    type Error;
    /// J(θ), its gradient and, if `information`, the Fisher information.
    fn evaluate(
        &mut self,
        theta: &[f64],
        information: bool,
    ) -> Result<Evaluation, Failure<Self::Error>>;
}

/// A box min ≤ θ ≤ max (±∞ allowed); θ₀ must be inside (the caller checks).
#[derive(Clone, Debug, PartialEq)]
pub struct Bounds {
    pub min: Vec<f64>,
    pub max: Vec<f64>,
}

impl Bounds {
    /// No bounds on p parameters.
    pub fn none(p: usize) -> Self {
        Bounds {
            min: vec![f64::NEG_INFINITY; p],
            max: vec![f64::INFINITY; p],
        }
    }
}

/// The iteration limit and the stopping thresholds (see the module doc).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Options {
    /// Accepted steps at most (default 100).
    pub max_iterations: usize,
    /// Scoring's threshold on the Newton decrement, in J's units (default 10⁻⁸).
    pub tolerance: f64,
    /// The threshold on the scaled projected gradient (default 10⁻⁶).
    pub gradient_tolerance: f64,
    /// The step test's threshold on relative changes of J and θ (default 10⁻¹²).
    pub step_tolerance: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            max_iterations: 100,
            tolerance: 1e-8,
            gradient_tolerance: 1e-6,
            step_tolerance: 1e-12,
        }
    }
}

/// Why the minimiser stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stop {
    /// Converged: the Newton decrement ≤ `tolerance` (scoring with a usable M) or the
    /// scaled projected gradient ≤ `gradient_tolerance`.
    Gradient,
    /// Converged: the last step changed J and each θ_i by at most `step_tolerance`
    /// relatively (to max(|·|, 1)).
    Step,
    /// Not converged: `max_iterations` steps were taken.
    MaxIterations,
    /// Not converged: no trial passed the Armijo test in 60 halvings, or the step
    /// vanished in floating point (θ(α) = θ).
    LineSearch,
    /// Not converged: J or g at θ₀ is not finite; no step was tried.
    NotFinite,
}

impl Stop {
    /// The stop in words, for a report.
    pub fn describe(self) -> &'static str {
        match self {
            Stop::Gradient => {
                "the gradient test holds (for scoring: the fall of J a Newton step promises is below the tolerance)"
            }
            Stop::Step => "the last step changed J and every param by less than the step tolerance",
            Stop::MaxIterations => {
                "the iteration limit was reached (raise max_iterations, or start nearer)"
            }
            Stop::LineSearch => {
                "no step along the search direction lowers J (near the optimum, J's rounding; see the iterations)"
            }
            Stop::NotFinite => "J or its gradient is not finite at the initial values",
        }
    }
}

/// The initial point and each accepted step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Iteration {
    pub theta: Vec<f64>,
    pub j: f64,
    /// ‖projected gradient‖∞.
    pub gradient_norm: f64,
    /// The gradient test's value here: the Newton decrement (scoring with a usable M)
    /// or the scaled projected gradient.
    pub measure: f64,
    /// max_i |Δθ_i| of the step to here (0 at θ₀).
    pub step: f64,
    /// Objective evaluations spent on this point (1 at θ₀); those of a failed line
    /// search are in no record.
    pub evaluations: usize,
}

/// The result: θ̂ (the last recorded θ), the records, and why it stopped.
#[derive(Clone, Debug, PartialEq)]
pub struct Outcome {
    pub theta: Vec<f64>,
    /// At θ̂, with the information when the method asked for it.
    pub evaluation: Evaluation,
    pub iterations: Vec<Iteration>,
    /// The stop is [`Stop::Gradient`] or [`Stop::Step`].
    pub converged: bool,
    pub stop: Stop,
}

/// Minimises J from θ₀ inside `bounds` (see the module doc). A [`Failure::Domain`] at
/// θ₀ and an [`Failure::Abort`] anywhere return their error.
pub fn minimise<O: Objective>(
    objective: &mut O,
    theta0: &[f64],
    bounds: &Bounds,
    method: Method,
    options: &Options,
) -> Result<Outcome, O::Error> {
    let p = theta0.len();
    debug_assert!(bounds.min.len() == p && bounds.max.len() == p);
    debug_assert!((0..p).all(|i| bounds.min[i] <= theta0[i] && theta0[i] <= bounds.max[i]));
    let info = method == Method::Scoring;
    let e = objective.evaluate(theta0, info);
    let e = e.map_err(|(Failure::Domain(x) | Failure::Abort(x))| x)?;
    let mut at = Point {
        theta: theta0.to_vec(),
        e,
    };
    let mut iterations = vec![record(&at, 0.0, 1)];
    if !finite(&at.e) {
        return Ok(finish(at, iterations, Stop::NotFinite));
    }
    let mut line = Line {
        objective,
        bounds,
        info,
    };
    let mut carried = f64::NAN; // gradient descent: the next first trial's α
    let mut previous: Option<Previous> = None;
    let (mut since_restart, mut small_step) = (0, false);
    loop {
        let (theta, g) = (&at.theta, &at.e.gradient);
        let outward = |i: usize, v: f64| {
            theta[i] <= bounds.min[i] && v < 0.0 || theta[i] >= bounds.max[i] && v > 0.0
        };
        let free = held_free(&at.theta, &at.e.gradient, bounds);
        let pg: Vec<f64> = (0..p).map(|i| if free[i] { g[i] } else { 0.0 }).collect();
        let newton = if info { newton(&at.e, &free) } else { None };
        let scale = at.e.j.abs().max(1.0);
        let scaled = (0..p).fold(0.0, |m: f64, i| {
            m.max(pg[i].abs() * theta[i].abs().max(1.0))
        });
        let (measure, threshold) = match &newton {
            Some((_, decrement)) => (*decrement, options.tolerance),
            None => (scaled / scale, options.gradient_tolerance),
        };
        let here = iterations.last_mut().expect("θ₀ recorded");
        here.measure = measure;
        here.gradient_norm = pg.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
        let stop = if measure <= threshold {
            Some(Stop::Gradient)
        } else if small_step {
            Some(Stop::Step)
        } else {
            (iterations.len() > options.max_iterations).then_some(Stop::MaxIterations)
        };
        if let Some(stop) = stop {
            if stop == Stop::Gradient && newton.is_some() {
                at = polish(line.objective, bounds, at, &mut iterations)?;
            }
            return Ok(finish(at, iterations, stop));
        }
        let steepest: Vec<f64> = pg.iter().map(|x| -x).collect();
        let restart = (previous.as_ref()).is_none_or(|l| since_restart == p || l.free != free);
        let (mut d, mut alpha0) = match (method, newton, &previous) {
            (Method::Scoring, Some((d, _)), _) => (d, 1.0),
            (Method::Conjugate, _, Some(l)) if !restart => {
                let beta = ((dot(&pg, &pg) - dot(&pg, &l.g)) / dot(&l.g, &l.g)).max(0.0);
                let d = (0..p).map(|i| if free[i] { beta * l.d[i] - pg[i] } else { 0.0 });
                (d.collect(), f64::NAN)
            }
            (Method::Gradient, _, _) => (steepest.clone(), carried),
            _ => (steepest.clone(), f64::NAN),
        };
        for i in 0..p {
            if outward(i, d[i]) {
                d[i] = 0.0; // the projection would hold it for every α
            }
        }
        let mut slope = dot(g, &d);
        if restart || !(slope < 0.0) {
            since_restart = 0;
        }
        if !(slope < 0.0) {
            (d, slope, alpha0) = (steepest, -dot(&pg, &pg), f64::NAN);
        }
        if !(slope < 0.0) {
            return Ok(finish(at, iterations, Stop::LineSearch));
        }
        if method == Method::Conjugate {
            alpha0 = previous
                .as_ref()
                .map_or(f64::NAN, |l| l.alpha * l.slope / slope);
        }
        if !(alpha0 > 0.0 && alpha0.is_finite()) {
            let largest = d.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
            alpha0 = theta.iter().fold(1.0, |m: f64, x| m.max(x.abs())) / largest;
        }
        let Some(found) = line.search(&at, &d, alpha0, method == Method::Conjugate)? else {
            return Ok(finish(at, iterations, Stop::LineSearch));
        };
        let (t, theta) = (&found.point.theta, &at.theta);
        let step = (0..p).fold(0.0, |m: f64, i| m.max((t[i] - theta[i]).abs()));
        let relative = (0..p).fold(0.0, |m: f64, i| {
            m.max((t[i] - theta[i]).abs() / t[i].abs().max(1.0))
        });
        let j = found.point.e.j;
        small_step = (at.e.j - j).abs() <= options.step_tolerance * j.abs().max(1.0)
            && relative <= options.step_tolerance;
        carried = found.alpha * if found.first { 2.0 } else { 1.0 };
        since_restart += 1;
        iterations.push(record(&found.point, step, found.evaluations));
        previous = Some(Previous {
            g: pg,
            d,
            slope,
            alpha: found.alpha,
            free,
        });
        at = found.point;
    }
}

/// Scoring's last steps, past what J can tell: at the gradient test's threshold the
/// fall of J a Newton step promises (the decrement) is near J's own rounding (≈ 10⁻¹³
/// of J summed over a long record), so the Armijo test can no longer judge a step,
/// while θ is still ~√(2·decrement/M) from the optimum — more so where scoring
/// converges only linearly (at an optimum where the data misfit the model, M is not
/// the Hessian: case a2's local optimum cuts the decrement ≈ 3× a step). Up to
/// [`POLISH`] full scoring steps are taken while each lowers the decrement (it comes
/// from g and M, which stay accurate where J's differences do not) and J rises by no
/// more than its rounding ([`ROUNDING`]·max(|J|, 1)); each is recorded.
fn polish<O: Objective>(
    objective: &mut O,
    bounds: &Bounds,
    mut at: Point,
    iterations: &mut Vec<Iteration>,
) -> Result<Point, O::Error> {
    let p = at.theta.len();
    for _ in 0..POLISH {
        let free = held_free(&at.theta, &at.e.gradient, bounds);
        let Some((d, decrement)) = newton(&at.e, &free) else {
            break;
        };
        // (Below this the step is beyond θ's own digits: nothing to polish.)
        if !(decrement > FLOOR * at.e.j.abs().max(1.0)) {
            break;
        }
        let theta: Vec<f64> = (0..p)
            .map(|i| (at.theta[i] + d[i]).clamp(bounds.min[i], bounds.max[i]))
            .collect();
        let e = match objective.evaluate(&theta, true) {
            Ok(e) if finite(&e) => e,
            Ok(_) | Err(Failure::Domain(_)) => break,
            Err(Failure::Abort(x)) => return Err(x),
        };
        let free = held_free(&theta, &e.gradient, bounds);
        let Some((_, next)) = newton(&e, &free) else {
            break;
        };
        if !(next < decrement && e.j <= at.e.j + ROUNDING * at.e.j.abs().max(1.0)) {
            break;
        }
        let step = (0..p).fold(0.0, |m: f64, i| m.max((theta[i] - at.theta[i]).abs()));
        at = Point { theta, e };
        let mut r = record(&at, step, 1);
        r.measure = next;
        r.gradient_norm = at.e.gradient.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
        iterations.push(r);
    }
    Ok(at)
}

/// The parameters not held at a bound by a gradient that pushes outward.
fn held_free(theta: &[f64], g: &[f64], bounds: &Bounds) -> Vec<bool> {
    (0..theta.len())
        .map(|i| {
            !(theta[i] <= bounds.min[i] && g[i] > 0.0 || theta[i] >= bounds.max[i] && g[i] < 0.0)
        })
        .collect()
}

/// A θ and the objective there./// A θ and the objective there.
struct Point {
    theta: Vec<f64>,
    e: Evaluation,
}

/// The last step, for CG's β and first trial: the projected gradient, the direction,
/// gᵀd, the accepted α and the free set.
struct Previous {
    g: Vec<f64>,
    d: Vec<f64>,
    slope: f64,
    alpha: f64,
    free: Vec<bool>,
}

fn finish(at: Point, iterations: Vec<Iteration>, stop: Stop) -> Outcome {
    let converged = matches!(stop, Stop::Gradient | Stop::Step);
    let (theta, evaluation) = (at.theta, at.e);
    Outcome {
        theta,
        evaluation,
        iterations,
        converged,
        stop,
    }
}

fn record(at: &Point, step: f64, evaluations: usize) -> Iteration {
    let (theta, j, nan) = (at.theta.clone(), at.e.j, f64::NAN); // NaNs set at the loop's top
    Iteration {
        theta,
        j,
        gradient_norm: nan,
        measure: nan,
        step,
        evaluations,
    }
}

fn finite(e: &Evaluation) -> bool {
    e.j.is_finite() && e.gradient.iter().all(|g| g.is_finite())
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The scoring direction −M_FF⁻¹g_F (0 off F), damped if need be, and the Newton
/// decrement ½ g_Fᵀ M_FF⁻¹ g_F; `None` without a usable M.
fn newton(e: &Evaluation, free: &[bool]) -> Option<(Vec<f64>, f64)> {
    let p = free.len();
    let m = e.information.as_ref().filter(|m| m.len() == p * p)?;
    let idx: Vec<usize> = (0..p).filter(|&i| free[i]).collect();
    let nf = idx.len();
    let mu = idx.iter().fold(0.0, |a: f64, &i| a.max(m[i * p + i]));
    for lambda in DAMPING {
        if lambda > 0.0 && !(mu > 0.0 && mu.is_finite()) {
            break;
        }
        let mut l: Vec<f64> = idx
            .iter()
            .flat_map(|&i| idx.iter().map(move |&j| m[i * p + j]))
            .collect();
        for k in 0..nf {
            l[k * nf + k] += lambda * mu;
        }
        if cholesky(&mut l, nf) {
            let mut x: Vec<f64> = idx.iter().map(|&i| e.gradient[i]).collect();
            cholesky_solve(&l, &mut x, nf, 1);
            let mut d = vec![0.0; p];
            for (k, &i) in idx.iter().enumerate() {
                d[i] = -x[k];
            }
            let decrement = -0.5 * dot(&e.gradient, &d);
            return Some((d, decrement));
        }
    }
    None
}

/// The line search's context: the objective, the box, whether M is asked for.
struct Line<'a, O> {
    objective: &'a mut O,
    bounds: &'a Bounds,
    info: bool,
}

/// A trial point P(θ + αd), its evaluation (`None`: outside the domain or not
/// finite), and whether the projection moved it.
struct Trial {
    theta: Vec<f64>,
    e: Option<Evaluation>,
    clipped: bool,
}

struct Found {
    point: Point,
    alpha: f64,
    evaluations: usize,
    /// Accepted at the first trial.
    first: bool,
}

impl<O: Objective> Line<'_, O> {
    /// `None` when θ(α) = θ in floating point.
    /// Whether every param of `t` on a bound has a gradient pushing outward (J falls
    /// beyond the bound): the bound holds it for a reason.
    fn active(&self, t: &Trial) -> bool {
        let (b, e) = (self.bounds, t.e.as_ref().expect("evaluated"));
        (0..t.theta.len()).all(|i| {
            let g = e.gradient[i];
            (t.theta[i] > b.min[i] || g > 0.0) && (t.theta[i] < b.max[i] || g < 0.0)
        })
    }

    /// The largest α with θ + αd inside the box (∞ when no bound is in the way).
    fn to_boundary(&self, at: &Point, d: &[f64]) -> f64 {
        let b = self.bounds;
        (0..d.len()).fold(f64::INFINITY, |a: f64, i| {
            let room = if d[i] > 0.0 {
                (b.max[i] - at.theta[i]) / d[i]
            } else if d[i] < 0.0 {
                (b.min[i] - at.theta[i]) / d[i]
            } else {
                f64::INFINITY
            };
            a.min(room)
        })
    }

    fn trial(&mut self, at: &Point, d: &[f64], alpha: f64) -> Result<Option<Trial>, O::Error> {
        let (b, mut clipped) = (self.bounds, false);
        let theta: Vec<f64> = (at.theta.iter().zip(d).enumerate())
            .map(|(i, (x, d))| {
                let y = (x + alpha * d).max(b.min[i]).min(b.max[i]);
                clipped |= y != x + alpha * d;
                y
            })
            .collect();
        if theta == at.theta {
            return Ok(None);
        }
        let e = match self.objective.evaluate(&theta, self.info) {
            Ok(e) => Some(e).filter(finite),
            Err(Failure::Domain(_)) => None,
            Err(Failure::Abort(x)) => return Err(x),
        };
        Ok(Some(Trial { theta, e, clipped }))
    }

    /// Backtracking from α₀; then, if `refine` (CG), up to [`REFINEMENTS`] secant
    /// steps on the directional derivative while the curvature test fails, each kept
    /// only if it passes Armijo with a lower J.
    fn search(
        &mut self,
        at: &Point,
        d: &[f64],
        alpha0: f64,
        refine: bool,
    ) -> Result<Option<Found>, O::Error> {
        let slope0 = dot(&at.e.gradient, d);
        let mut alpha = alpha0;
        for halving in 0..HALVINGS {
            let Some(t) = self.trial(at, d, alpha)? else {
                break;
            };
            let Some(mut j) = armijo(&t, at) else {
                alpha *= 0.5;
                continue;
            };
            let (mut t, mut evaluations) = (t, halving + 1);
            // A step cut by a bound may land on a stationary point that the bound makes
            // (J even in a param bounded at 0: case b's w, where ∂J/∂w = 0): the step
            // that stops short of the bound, at 0.9 of the way, is tried too, and kept
            // unless the cut step is lower and its bounds are active — the gradient
            // there pushes outward, so the optimum may well be on them.
            if t.clipped {
                let short = 0.9 * self.to_boundary(at, d);
                if short > 0.0 && short < alpha {
                    evaluations += 1;
                    if let Some(inner) = self.trial(at, d, short)?
                        && let Some(j2) = armijo(&inner, at)
                        && !(j < j2 && self.active(&t))
                    {
                        (t, j, alpha) = (inner, j2, short);
                    }
                }
            }
            let (mut best, mut a0, mut s0) = (t, 0.0, slope0);
            for _ in 0..REFINEMENTS {
                let s1 = best.e.as_ref().map_or(0.0, |e| dot(&e.gradient, d));
                if !refine || best.clipped || s1.abs() <= CURVATURE * slope0.abs() {
                    break;
                }
                let secant = if s1 > s0 {
                    alpha - s1 * (alpha - a0) / (s1 - s0)
                } else {
                    4.0 * alpha
                };
                let next = secant.max(alpha / 10.0).min(4.0 * alpha);
                let Some(t) = self.trial(at, d, next)? else {
                    break;
                };
                evaluations += 1;
                match armijo(&t, at) {
                    Some(j2) if j2 < j => (a0, s0, alpha, j, best) = (alpha, s1, next, j2, t),
                    _ => break,
                }
            }
            let point = Point {
                theta: best.theta,
                e: best.e.expect("accepted"),
            };
            return Ok(Some(Found {
                point,
                alpha,
                evaluations,
                first: halving == 0,
            }));
        }
        Ok(None)
    }
}

/// J at the trial if it passes the Armijo test J < J₀, J ≤ J₀ + c·g₀ᵀ(θ − θ₀).
fn armijo(t: &Trial, at: &Point) -> Option<f64> {
    let predicted: f64 = (0..t.theta.len())
        .map(|i| at.e.gradient[i] * (t.theta[i] - at.theta[i]))
        .sum();
    let j = t.e.as_ref()?.j;
    (j < at.e.j && j <= at.e.j + ARMIJO * predicted).then_some(j)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// (J, g, M) at θ, or `None` outside the domain.
    type Closed = fn(&[f64]) -> Option<(f64, Vec<f64>, Vec<f64>)>;

    struct F {
        f: Closed,
        calls: usize,
        domain: usize,
        abort_at: Option<usize>,
    }

    impl Objective for F {
        type Error = &'static str;
        fn evaluate(
            &mut self,
            theta: &[f64],
            info: bool,
        ) -> Result<Evaluation, Failure<&'static str>> {
            self.calls += 1;
            if self.abort_at == Some(self.calls) {
                return Err(Failure::Abort("cancelled"));
            }
            let Some((j, gradient, m)) = (self.f)(theta) else {
                self.domain += 1;
                return Err(Failure::Domain("outside"));
            };
            Ok(Evaluation {
                j,
                gradient,
                information: info.then_some(m),
            })
        }
    }

    fn f(f: Closed) -> F {
        F {
            f,
            calls: 0,
            domain: 0,
            abort_at: None,
        }
    }

    /// Runs and checks what holds for every run: θ₀ first, J strictly falling, the
    /// outcome at the last record, `converged` as the stop says.
    fn run(obj: &mut F, theta0: &[f64], bounds: &Bounds, method: Method, max: usize) -> Outcome {
        let options = Options {
            max_iterations: max,
            ..Options::default()
        };
        run_with(obj, theta0, bounds, method, &options)
    }

    fn run_with(obj: &mut F, theta0: &[f64], b: &Bounds, method: Method, o: &Options) -> Outcome {
        let out = minimise(obj, theta0, b, method, o).expect("no failure");
        assert_eq!(out.iterations[0].theta, theta0);
        // (Strictly down, but for scoring's polish, which may rise by J's rounding.)
        for w in out.iterations.windows(2) {
            assert!(
                w[1].j < w[0].j || w[1].j <= w[0].j + ROUNDING * w[0].j.abs().max(1.0),
                "{method:?}: J rose {} → {}",
                w[0].j,
                w[1].j
            );
        }
        let last = out.iterations.last().unwrap();
        assert_eq!((&last.theta, last.j), (&out.theta, out.evaluation.j));
        assert!(out.iterations.iter().all(|i| i.measure.is_finite()));
        assert_eq!(
            out.converged,
            matches!(out.stop, Stop::Gradient | Stop::Step)
        );
        assert!(out.iterations.len() <= o.max_iterations + 1);
        assert_eq!(
            out.evaluation.information.is_some(),
            method == Method::Scoring
        );
        out
    }

    fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    const A: [f64; 9] = [4.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 2.0];
    const C: [f64; 3] = [1.0, -2.0, 3.0];

    /// ½ (θ − c)ᵀA(θ − c), M = A (the Hessian); A's eigenvalues > 1.
    fn quadratic(t: &[f64]) -> Option<(f64, Vec<f64>, Vec<f64>)> {
        let r: Vec<f64> = (0..3).map(|i| t[i] - C[i]).collect();
        let g: Vec<f64> = (0..3).map(|i| dot(&A[3 * i..3 * i + 3], &r)).collect();
        Some((0.5 * dot(&r, &g), g, A.to_vec()))
    }

    /// Rosenbrock as least squares r₁ = 10(y − x²), r₂ = 1 − x, J = r₁² + r₂², with
    /// the Gauss–Newton M = 2 JᵣᵀJᵣ.
    fn rosenbrock(t: &[f64]) -> Option<(f64, Vec<f64>, Vec<f64>)> {
        let (x, y) = (t[0], t[1]);
        let (r1, r2) = (10.0 * (y - x * x), 1.0 - x);
        let g = vec![2.0 * (-20.0 * x * r1 - r2), 20.0 * r1];
        let m = vec![2.0 * (400.0 * x * x + 1.0), -400.0 * x, -400.0 * x, 200.0];
        Some((r1 * r1 + r2 * r2, g, m))
    }

    /// θ − ln θ, minimum 1 at θ = 1, undefined for θ ≤ 0; M = 1/θ² (the Hessian).
    fn log_barrier(t: &[f64]) -> Option<(f64, Vec<f64>, Vec<f64>)> {
        let x = t[0];
        (x > 0.0).then(|| (x - libm::log(x), vec![1.0 - 1.0 / x], vec![1.0 / (x * x)]))
    }

    const METHODS: [Method; 3] = [Method::Scoring, Method::Gradient, Method::Conjugate];

    #[test]
    fn quadratic_minimum_in_one_scoring_step_and_to_1e_8_by_the_others() {
        let b = Bounds::none(3);
        let out = run(&mut f(quadratic), &[0.0; 3], &b, Method::Scoring, 100);
        assert_eq!((out.iterations.len(), out.stop), (2, Stop::Gradient));
        assert!(close(&out.theta, &C, 1e-12) && out.iterations[1].evaluations == 1);
        // J* = 0 resolves small steps: |θ − c| ≤ |g| / λ_min < the scaled gradient.
        let tight = Options {
            gradient_tolerance: 1e-9,
            ..Options::default()
        };
        for method in [Method::Gradient, Method::Conjugate] {
            let out = run_with(&mut f(quadratic), &[0.0; 3], &b, method, &tight);
            assert!(
                out.converged && close(&out.theta, &C, 1e-8),
                "{method:?} {out:?}"
            );
        }
        // With the secant steps CG is (nearly) exact-line-search CG: about p steps.
        let out = run_with(&mut f(quadratic), &[0.0; 3], &b, Method::Conjugate, &tight);
        assert!(out.iterations.len() <= 5, "{}", out.iterations.len());
    }

    #[test]
    fn rosenbrock_from_the_classic_start() {
        let b = Bounds::none(2);
        // Gauss–Newton with backtracking: a few tens of steps; CG a few hundred;
        // gradient descent crawls along the valley and needs thousands.
        for (method, max, tol) in [
            (Method::Scoring, 100, 1e-8),
            (Method::Conjugate, 1000, 1e-6),
            (Method::Gradient, 20_000, 1e-4),
        ] {
            let out = run(&mut f(rosenbrock), &[-1.2, 1.0], &b, method, max);
            assert!(
                out.converged && close(&out.theta, &[1.0, 1.0], tol),
                "{method:?} {out:?}"
            );
        }
    }

    #[test]
    fn a_bound_active_at_the_solution() {
        // ½ (θ − c)ᵀA(θ − c), A = [2 1; 1 2], c = (3, 0), x ≤ 1: at x = 1, ∂J/∂y = 0
        // gives y = 1, and ∂J/∂x = −3 < 0 pushes outward, so (1, 1) is the minimiser.
        fn bowl(t: &[f64]) -> Option<(f64, Vec<f64>, Vec<f64>)> {
            let (u, v) = (t[0] - 3.0, t[1]);
            let g = vec![2.0 * u + v, u + 2.0 * v];
            Some((0.5 * (u * g[0] + v * g[1]), g, vec![2.0, 1.0, 1.0, 2.0]))
        }
        let b = Bounds {
            min: vec![-5.0, f64::NEG_INFINITY],
            max: vec![1.0, f64::INFINITY],
        };
        for method in METHODS {
            let out = run(&mut f(bowl), &[0.0, 0.0], &b, method, 100);
            assert!(
                out.converged && close(&out.theta, &[1.0, 1.0], 1e-5),
                "{method:?} {out:?}"
            );
            assert_eq!(out.theta[0], 1.0);
        }
    }

    #[test]
    fn a_domain_error_at_a_trial_shrinks_the_step() {
        let b = Bounds::none(1);
        // Scoring's first step from 5 is to −15; the others' first trial is to 0.
        for method in METHODS {
            let mut obj = f(log_barrier);
            let out = run(&mut obj, &[5.0], &b, method, 100);
            assert!(
                out.converged && close(&out.theta, &[1.0], 1e-5),
                "{method:?} {out:?}"
            );
            assert!(obj.domain > 0, "{method:?} never left the domain");
        }
        // At θ₀ it is the error.
        let err = minimise(
            &mut f(log_barrier),
            &[-1.0],
            &b,
            Method::Scoring,
            &Options::default(),
        );
        assert_eq!(err, Err("outside"));
    }

    #[test]
    fn an_abort_propagates() {
        for method in METHODS {
            let mut obj = F {
                abort_at: Some(3),
                ..f(rosenbrock)
            };
            let r = minimise(
                &mut obj,
                &[-1.2, 1.0],
                &Bounds::none(2),
                method,
                &Options::default(),
            );
            assert_eq!((r, obj.calls), (Err("cancelled"), 3));
        }
    }

    #[test]
    fn stops_that_are_not_convergence() {
        let (b1, b2) = (Bounds::none(1), Bounds::none(2));
        let out = run(&mut f(rosenbrock), &[-1.2, 1.0], &b2, Method::Gradient, 5);
        let stop = (out.stop, out.converged, out.iterations.len());
        assert_eq!(stop, (Stop::MaxIterations, false, 6));
        // J = θ² with the gradient's sign wrong: every trial raises J.
        fn liar(t: &[f64]) -> Option<(f64, Vec<f64>, Vec<f64>)> {
            Some((t[0] * t[0], vec![-2.0 * t[0]], vec![2.0]))
        }
        fn nan(_: &[f64]) -> Option<(f64, Vec<f64>, Vec<f64>)> {
            Some((f64::NAN, vec![0.0], vec![1.0]))
        }
        for method in METHODS {
            let out = run(&mut f(liar), &[1.0], &b1, method, 100);
            let stop = (out.stop, out.converged, out.iterations.len());
            assert_eq!(stop, (Stop::LineSearch, false, 1), "{method:?}");
            let out = minimise(&mut f(nan), &[1.0], &b1, method, &Options::default()).unwrap();
            assert_eq!((out.stop, out.converged), (Stop::NotFinite, false));
        }
    }

    #[test]
    fn scoring_without_a_positive_definite_information() {
        // J = ½(θ₁ + θ₂ − 1)² with its singular Hessian: M + 10⁻⁸·I, the ridge step
        // from 0, lands on the minimum-norm minimiser (½, ½).
        fn ridge(t: &[f64]) -> Option<(f64, Vec<f64>, Vec<f64>)> {
            let s = t[0] + t[1] - 1.0;
            Some((0.5 * s * s, vec![s, s], vec![1.0; 4]))
        }
        let out = run(
            &mut f(ridge),
            &[0.0; 2],
            &Bounds::none(2),
            Method::Scoring,
            100,
        );
        assert!(
            out.converged && close(&out.theta, &[0.5, 0.5], 1e-8),
            "{out:?}"
        );
        // (One damped step there; the polish may add one more, as small as the damping.)
        assert!(
            close(&out.iterations[1].theta, &[0.5, 0.5], 1e-7),
            "{out:?}"
        );
        assert!(out.iterations.len() <= 3, "{out:?}");
        // M = diag(1, −1, 1): neither M nor M + λ·I (λ ≤ 1) factors; gradient steps.
        fn indefinite(t: &[f64]) -> Option<(f64, Vec<f64>, Vec<f64>)> {
            let m = vec![1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 1.0];
            quadratic(t).map(|(j, g, _)| (j, g, m))
        }
        let out = run(
            &mut f(indefinite),
            &[0.0; 3],
            &Bounds::none(3),
            Method::Scoring,
            100,
        );
        assert!(out.converged && close(&out.theta, &C, 1e-6), "{out:?}");
    }

    #[test]
    fn serde_names() {
        assert_eq!(Method::default(), Method::Scoring);
        let names =
            serde_json::to_string(&(Method::Conjugate, Stop::MaxIterations, Stop::LineSearch));
        assert_eq!(
            names.unwrap(),
            r#"["conjugate","max_iterations","line_search"]"#
        );
        assert_eq!(
            serde_json::from_str::<Method>(r#""gradient""#).unwrap(),
            Method::Gradient
        );
        assert_eq!(
            serde_json::from_str::<Options>("{}").unwrap(),
            Options::default()
        );
    }
}
