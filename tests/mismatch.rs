//! The mismatched filter (`"truth"`, `kea_core::analysis::mismatch`) against
//! independent plain-matrix recursions (nalgebra): the Joseph form with the design's
//! gains and the truth's noises, and the joint recursion of the true state and the
//! estimate [x; x̂] for another a, C, u and y0; with truth = design it is the filter.

mod common;
use common::{assert_error_at, preset_value};
use kea_core::AnalysisResult;
use kea_core::registry;
use nalgebra::{DMatrix, DVector};
use serde_json::{Value, json};

fn analyse(request: Value) -> AnalysisResult {
    common::run_analysis(request)
}

fn rel(a: f64, b: f64) -> f64 {
    ((a - b) / b).abs()
}

/// A 2-state model whose every part is a param: a = [[0, 1], [−k, −c]], b = [0; 1],
/// u = [0; g], C = [1, m] (one measurement), φ = q, ψ = r, y0, η0.
fn model() -> Value {
    json!({
        "kea_model": 1,
        "params": { "k": 2.0, "c": 0.6, "g": 0.3, "m": 0.0, "q": 0.5, "r": 0.2,
                    "y1": 1.0, "s1": 0.7, "s2": 0.4 },
        "time": { "t0": 0, "t_end": 4, "steps": 400 },
        "system": {
            "states": ["x", "v"],
            "a": [[0, 1], ["-k", "-c"]],
            "b": [[0], [1]],
            "u": [0, "g"],
            "y0": ["y1", 0],
            "eta0": ["s1", "s2"],
            "phi": ["q"]
        },
        "measurement": { "names": ["z"], "c": [[1, "m"]], "gamma": [[1]], "psi": ["r"],
                         "schedule": [{ "every": 2 }] },
        "options": { "trace_points": 0 }
    })
}

struct Params {
    k: f64,
    c: f64,
    g: f64,
    m: f64,
    q: f64,
    r: f64,
    y1: f64,
    s1: f64,
    s2: f64,
}

impl Params {
    fn with(set: &[(&str, f64)]) -> Params {
        let mut p = Params {
            k: 2.0,
            c: 0.6,
            g: 0.3,
            m: 0.0,
            q: 0.5,
            r: 0.2,
            y1: 1.0,
            s1: 0.7,
            s2: 0.4,
        };
        for &(name, v) in set {
            match name {
                "k" => p.k = v,
                "c" => p.c = v,
                "g" => p.g = v,
                "m" => p.m = v,
                "q" => p.q = v,
                "r" => p.r = v,
                "y1" => p.y1 = v,
                "s1" => p.s1 = v,
                "s2" => p.s2 = v,
                _ => panic!("{name}"),
            }
        }
        p
    }
    /// A = I + aΔt, B = (bΔt) q² (bΔt)ᵀ, uΔt, C, Rv = r².
    fn discrete(&self, dt: f64) -> (DMatrix<f64>, DMatrix<f64>, DVector<f64>, DMatrix<f64>, f64) {
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -self.k, -self.c]);
        let big_a = DMatrix::identity(2, 2) + a * dt;
        let bd = DMatrix::from_row_slice(2, 1, &[0.0, dt]);
        let big_b = &bd * bd.transpose() * (self.q * self.q);
        let u = DVector::from_row_slice(&[0.0, self.g * dt]);
        let c = DMatrix::from_row_slice(1, 2, &[1.0, self.m]);
        (big_a, big_b, u, c, self.r * self.r)
    }
}

/// The independent reference: the design's Riccati recursion (block form) for the
/// gains; the joint mean and covariance of [x; x̂] under the truth; and the Joseph form
/// with the design's gains and the truth's noises, P = h (A P Aᵀ + B^t) hᵀ + K Rv^t Kᵀ
/// (right only where A, C, u and y0 agree). Returns, at t_D, the error's covariance
/// diagonal and mean from the joint recursion, the Joseph form's diagonal, and the
/// design's filtered variances.
#[allow(clippy::type_complexity)] // four diagonals
fn reference(design: &Params, truth: &Params) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let (steps, dt) = (400u64, 0.01);
    let (ad, bdes, ud, cd, rvd) = design.discrete(dt);
    let (at, bt, ut, ct, rvt) = truth.discrete(dt);
    let mut r = DMatrix::from_diagonal(&DVector::from_row_slice(&[
        design.s1.powi(2),
        design.s2.powi(2),
    ]));
    // z = [x; x̂]: x_0 ~ (y0^t, P0^t), x̂_0 = y0^d.
    let mut mu = DVector::from_row_slice(&[truth.y1, 0.0, design.y1, 0.0]);
    let mut s = DMatrix::zeros(4, 4);
    s[(0, 0)] = truth.s1.powi(2);
    s[(1, 1)] = truth.s2.powi(2);
    let mut joseph = s.view((0, 0), (2, 2)).clone_owned();
    for k in 1..=steps {
        let rp = &ad * &r * ad.transpose() + &bdes;
        let (gain, h) = if k % 2 == 0 {
            let q = (&cd * &rp * cd.transpose())[(0, 0)] + rvd;
            let gain = &rp * cd.transpose() / q;
            let h = DMatrix::identity(2, 2) - &gain * &cd;
            r = &h * &rp * h.transpose() + &gain * gain.transpose() * rvd;
            (gain, h)
        } else {
            r = rp;
            (DMatrix::zeros(2, 1), DMatrix::identity(2, 2))
        };
        // x_k = A^t x + u^t + w;  x̂_k = h (A^d x̂ + u^d) + K (C^t x_k + v)
        let mut f = DMatrix::zeros(4, 4);
        f.view_mut((0, 0), (2, 2)).copy_from(&at);
        f.view_mut((2, 0), (2, 2)).copy_from(&(&gain * &ct * &at));
        f.view_mut((2, 2), (2, 2)).copy_from(&(&h * &ad));
        let mut gw = DMatrix::zeros(4, 2);
        gw.view_mut((0, 0), (2, 2))
            .copy_from(&DMatrix::identity(2, 2));
        gw.view_mut((2, 0), (2, 2)).copy_from(&(&gain * &ct));
        let mut gv = DMatrix::zeros(4, 1);
        gv.view_mut((2, 0), (2, 1)).copy_from(&gain);
        let mut c = DVector::zeros(4);
        c.rows_mut(0, 2).copy_from(&ut);
        c.rows_mut(2, 2).copy_from(&(&h * &ud + &gain * &ct * &ut));
        mu = &f * &mu + c;
        joseph = &h * (&at * &joseph * at.transpose() + &bt) * h.transpose()
            + &gain * gain.transpose() * rvt;
        s = &f * &s * f.transpose() + &gw * &bt * gw.transpose() + &gv * gv.transpose() * rvt;
    }
    let d = DMatrix::from_row_slice(2, 4, &[1.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, -1.0]);
    let cov = &d * &s * d.transpose();
    let mean = &d * &mu;
    (
        vec![cov[(0, 0)], cov[(1, 1)]],
        vec![mean[0], mean[1]],
        vec![joseph[(0, 0)], joseph[(1, 1)]],
        vec![r[(0, 0)], r[(1, 1)]],
    )
}

fn mismatch(truth_set: &[(&str, f64)]) -> AnalysisResult {
    let set: serde_json::Map<String, Value> = truth_set
        .iter()
        .map(|(k, v)| (k.to_string(), json!(v)))
        .collect();
    analyse(json!({ "model": model(), "truth": { "set": set } }))
}

/// Noise levels and the initial SKOs mismatched: the Joseph form with the design's
/// gains and the truth's noises, against the reference; the loss is ≥ 1 (the filter
/// designed on the truth is the best there is) and the believed SKO the design's.
#[test]
fn noise_mismatch_equals_the_plain_recursion() {
    for truth in [
        vec![("r", 0.5)],
        vec![("q", 0.1), ("s1", 2.0)],
        vec![("r", 0.05), ("q", 1.5), ("s2", 0.0)],
    ] {
        let r = mismatch(&truth);
        let m = r.mismatch.as_ref().unwrap();
        assert_eq!(m.differs_in, "noise", "{truth:?}");
        let (_, mean, var, believed) = reference(&Params::with(&[]), &Params::with(&truth));
        for (i, s) in m.states.iter().enumerate() {
            assert!(
                rel(s.actual_sko.powi(2), var[i]) <= 1e-12,
                "{truth:?} {}: {} against {}",
                s.state,
                s.actual_sko.powi(2),
                var[i]
            );
            assert_eq!(s.bias, 0.0);
            assert!(
                mean[i].abs() <= 1e-12,
                "the reference's x − x̂ by difference"
            );
            assert!(rel(s.believed_sko.powi(2), believed[i]) <= 1e-12);
            assert!(
                s.loss.unwrap() >= 1.0 - 1e-12,
                "{truth:?} {}: loss {:?}",
                s.state,
                s.loss
            );
        }
        assert!(r.criteria.actual.is_some());
    }
}

/// The traces end at the values at t_D, with a schedule (every second step) too: the
/// optimal filter's trace is the truth's own analysis, on the model's availability.
#[test]
fn traces_end_at_the_final_values() {
    let mut m = model();
    m["options"]["trace_points"] = json!(50);
    for truth in [json!({"r": 0.5}), json!({"k": 3.0, "q": 0.1})] {
        let r = analyse(json!({ "model": m, "truth": { "set": truth } }));
        let mm = r.mismatch.as_ref().unwrap();
        assert_eq!(mm.traces.t.len(), 50);
        assert_eq!(*mm.traces.t.last().unwrap(), 4.0);
        for (s, tr) in mm.states.iter().zip(&mm.traces.states) {
            assert_eq!(*tr.actual_sko.last().unwrap(), s.actual_sko);
            assert!(
                rel(*tr.optimal_sko.last().unwrap(), s.optimal_sko) <= 1e-12,
                "{truth} {}: {} against {}",
                s.state,
                tr.optimal_sko.last().unwrap(),
                s.optimal_sko
            );
            assert!(
                rel(*tr.believed_sko.last().unwrap(), s.believed_sko) <= 1e-12,
                "{truth} {}",
                s.state
            );
        }
    }
    // No trace points, no traces.
    let r = mismatch(&[("r", 0.5)]);
    assert!(r.mismatch.unwrap().traces.t.is_empty());
}

/// Another a, C, u and y0: the error's covariance and mean against the joint [x; x̂]
/// recursion (which forms e = x − x̂ by difference: the tolerance is its cancellation's).
#[test]
fn structural_mismatch_equals_the_joint_recursion() {
    for truth in [
        vec![("k", 3.0)],
        vec![("c", 0.2), ("g", 1.0), ("y1", 2.0)],
        vec![("m", 0.3), ("r", 0.4)],
    ] {
        let r = mismatch(&truth);
        let m = r.mismatch.as_ref().unwrap();
        assert_eq!(m.differs_in, "structure", "{truth:?}");
        let (var, mean, _, _) = reference(&Params::with(&[]), &Params::with(&truth));
        for (i, s) in m.states.iter().enumerate() {
            assert!(
                rel(s.actual_sko.powi(2), var[i]) <= 1e-9,
                "{truth:?} {}: {} against {}",
                s.state,
                s.actual_sko.powi(2),
                var[i]
            );
            // (The reference's mean is of e = x − x̂; the bias is of x̂ − x.)
            let scale = mean[i].abs().max(1e-3 * s.actual_sko);
            assert!(
                (s.bias + mean[i]).abs() <= 1e-9 * scale,
                "{truth:?} {}: bias {} against {}",
                s.state,
                s.bias,
                mean[i]
            );
        }
    }
}

/// With truth = design the actual SKOs are the potential ones bit for bit (the
/// filter's own R), no bias, loss 1, and the actual criteria the covariance set's (to
/// rounding: the truth's open-loop SKO is the pass's).
#[test]
fn truth_equal_to_design_is_the_filter() {
    for name in ["cv-tracker", "helicopter-range", "helicopter-angle"] {
        let r = analyse(json!({ "model": preset_value(name), "truth": { "set": {} } }));
        let m = r.mismatch.as_ref().unwrap();
        assert_eq!(m.differs_in, "noise");
        for (i, s) in m.states.iter().enumerate() {
            assert_eq!(
                s.actual_sko, r.final_.potential_sko[i],
                "{name} {}",
                s.state
            );
            assert_eq!(s.optimal_sko, s.actual_sko, "{name} {}", s.state);
            assert_eq!(s.bias, 0.0);
        }
        let (a, c) = (
            &r.criteria.actual.as_ref().unwrap().weighted,
            &r.criteria.covariance.weighted,
        );
        for (x, y) in [(a.yz, c.yz), (a.zx, c.zx), (a.yx, c.yx)] {
            assert!(
                rel(x.unwrap(), y.unwrap()) <= 1e-10,
                "{name}: {x:?} against {y:?}"
            );
        }
        assert_eq!(m.optimal, r.criteria.covariance);
        for t in &m.traces.states {
            assert_eq!(
                t.optimal_sko, t.believed_sko,
                "{name}: the same filter, the same bits"
            );
            assert_eq!(t.actual_sko, t.believed_sko, "{name}: the filter's own R");
        }
    }
}

#[test]
fn bad_truths_are_refused_at_their_paths() {
    let refused = |truth: Value| {
        registry::prepare("analysis", json!({ "model": model(), "truth": truth }))
            .err()
            .expect("refused")
    };
    assert_error_at(&refused(json!(5)), "truth", "expected an object");
    assert_error_at(&refused(json!({})), "truth", "give `set`");
    assert_error_at(&refused(json!({"sett": {}})), "truth.sett", "");
    assert_error_at(&refused(json!({"set": {"nope": 1}})), "truth.set.nope", "");
    assert_error_at(
        &refused(json!({"set": {"r": -1}})),
        "truth.set",
        "with truth.set, measurement.psi[0]",
    );
    let mut other = preset_value("helicopter-range");
    other["time"] = json!({ "t0": 0, "t_end": 4, "steps": 400 });
    let e = refused(json!({"model": other}));
    assert_error_at(
        &e,
        "truth.model.system.states",
        "the truth has 6 states, the model 2",
    );
    assert_error_at(&e, "truth.model.measurement.names", "4 measurements");
    let mut broken = model();
    broken["system"]["a"][0][1] = json!("1 +");
    assert_error_at(
        &refused(json!({"model": broken})),
        "truth.model.system.a[0][1]",
        "",
    );
}

/// The Monte Carlo of the mismatched filter (`"truth"` in a Monte Carlo request): the
/// runs imitate the truth, the filter is the model's.
fn monte_carlo(truth: Value, runs: u64) -> kea_core::monte_carlo::MonteCarloResult {
    use kea_core::exec::{Forgetful, Sequential};
    let request = json!({ "model": model(), "runs": runs, "seed": 11, "truth": truth });
    let prepared = registry::prepare("monte_carlo", request).expect("a valid request");
    match prepared.run(&Sequential, &mut kea_core::NoProgress, &Forgetful) {
        Ok(registry::Outcome::MonteCarlo(o)) => o.result,
        Ok(_) => panic!("a Monte Carlo"),
        Err(e) => panic!("the Monte Carlo runs: {e:?}"),
    }
}

/// A sensor 16 times noisier and a model error 4 times larger than designed: the
/// sample variances lie in their χ² bands around the actual covariance and outside
/// them around what the filter believes — at the last step and step by step.
#[test]
fn monte_carlo_agrees_with_the_actual_covariance_not_the_believed_one() {
    let runs = 2000;
    let truth = json!({ "set": { "r": 3.2, "q": 2.0 } });
    let mc = monte_carlo(truth.clone(), runs);
    let an = analyse(json!({ "model": model(), "truth": truth }));
    let m = an.mismatch.as_ref().unwrap();
    let actual = mc.final_.actual_sko.as_ref().expect("actual SKOs");
    let bias = mc.final_.actual_bias.as_ref().unwrap();
    // The noise-only mismatch has no bias: Σe²/R ~ σ² χ²_R / R.
    let band = kea_core::monte_carlo::chi2_band(runs as f64, runs as f64);
    for i in 0..2 {
        assert_eq!(
            actual[i], m.states[i].actual_sko,
            "the analysis's recursion"
        );
        assert_eq!(bias[i], 0.0);
        let sample = mc.final_.filtered_sko[i].powi(2);
        let (to_actual, to_believed) = (
            sample / actual[i].powi(2),
            sample / mc.final_.potential_sko[i].powi(2),
        );
        assert!(
            (band[0]..=band[1]).contains(&to_actual),
            "state {i}: {to_actual} outside {band:?}"
        );
        assert!(
            to_believed > band[1],
            "state {i}: {to_believed} inside {band:?}"
        );
    }
    let verdicts = mc.consistency.per_state_actual.as_ref().unwrap();
    for (v, b) in verdicts.iter().zip(&mc.consistency.per_state) {
        assert_eq!(
            v.verdict,
            kea_core::monte_carlo::Verdict::Consistent,
            "{v:?}"
        );
        assert!(v.fraction_in_band.unwrap() >= 0.85, "{v:?}");
        assert_eq!(
            b.verdict,
            kea_core::monte_carlo::Verdict::Optimistic,
            "{b:?}"
        );
        assert!(b.fraction_in_band.unwrap() <= 0.05, "{b:?}");
    }
    let traces = &mc.traces.states[0];
    assert_eq!(traces.actual_sko.as_ref().unwrap().len(), mc.traces.t.len());
}

/// Another a, u and y0 (a biased filter): the sample variance about the sample mean in
/// its band around the actual variance, the sample mean at the actual bias.
#[test]
fn monte_carlo_of_a_structural_mismatch_finds_the_actual_bias() {
    let mc = monte_carlo(json!({ "set": { "k": 3.0, "g": 1.0, "y1": 2.0 } }), 2000);
    let bias = mc.final_.actual_bias.as_ref().unwrap();
    assert!(bias.iter().any(|b| b.abs() > 0.05), "{bias:?}");
    for v in mc.consistency.per_state_actual.as_ref().unwrap() {
        assert_eq!(
            v.verdict,
            kea_core::monte_carlo::Verdict::Consistent,
            "{v:?}"
        );
        assert!(v.fraction_in_band.unwrap() >= 0.8, "{v:?}");
        assert!(v.normalised_bias.unwrap().abs() <= 0.1, "{v:?}");
    }
}

/// A truth equal to the model imitates the same world with the same draws: the
/// sample filtered SKOs are the plain Monte Carlo's, bit for bit.
#[test]
fn monte_carlo_with_the_model_as_truth_is_the_plain_one() {
    let plain = monte_carlo(json!("process"), 200);
    let same = monte_carlo(json!({ "set": {} }), 200);
    assert_eq!(plain.final_.filtered_sko, same.final_.filtered_sko);
    for (p, s) in plain.traces.states.iter().zip(&same.traces.states) {
        assert_eq!(p.filtered_sko, s.filtered_sko);
        for (a, b) in p.a_priori_sko.iter().zip(&s.a_priori_sko) {
            assert!(rel(*b, *a) <= 1e-12, "{a} {b}");
        }
    }
    assert!(plain.consistency.per_state_actual.is_none());
}

#[test]
fn bad_monte_carlo_truths_are_refused_at_their_paths() {
    let refused = |truth: Value| {
        registry::prepare(
            "monte_carlo",
            json!({ "model": model(), "runs": 10, "truth": truth }),
        )
        .err()
        .expect("refused")
    };
    assert_error_at(&refused(json!({"set": {"nope": 1}})), "truth.set.nope", "");
    assert_error_at(&refused(json!("banana")), "truth", "process");
    assert_error_at(&refused(json!({})), "truth", "give `set`");
}
