//! Step-size selection (`time.steps: "auto"`, METHOD §1.2) against independent
//! references: the Euler solutions of a scalar model in closed form, and a plainly
//! written second implementation for a time-varying one.

use kea_core::{NoProgress, Overrides, analyze, model_from_value};
use serde_json::{Value, json};

fn scalar(a: Value, u: Value, auto: Value) -> Value {
    json!({
        "time": {"t0": 0.0, "t_end": 1.0, "steps": "auto", "auto": auto},
        "system": {
            "states": ["y"], "a": [[a]], "u": [u], "b": [[1]],
            "y0": [1.0], "eta0": [0.1], "phi": [0.2]
        },
        "measurement": {"names": ["z"], "c": [[1]], "gamma": [[1]], "psi": [0.05]}
    })
}

/// (steps, difference) of each trial, and the chosen D.
fn selection(model: Value) -> (Vec<(u64, Option<f64>)>, bool, u64) {
    let m = model_from_value(model).unwrap();
    let r = analyze(&m, &Overrides::new(), &mut NoProgress).unwrap();
    let s = r
        .step_selection
        .expect("a step selection for steps = \"auto\"");
    let trials = s.history.iter().map(|t| (t.steps, t.difference)).collect();
    (trials, s.converged, r.steps)
}

fn assert_close(got: f64, want: f64, rel: f64, what: &str) {
    assert!(
        (got - want).abs() <= rel * want.abs(),
        "{what}: got {got:e}, expected {want:e}"
    );
}

#[test]
fn constant_coefficient_differences_match_the_closed_form() {
    // ẏ = a y, y0 = 1, a < 0: the Euler solutions are y_k = (1 + a h)^k, so the
    // time-averaged difference of D and 2D steps (max|y| = y0 = 1) is
    // (1/D) Σ_k |(1 + a h)^k − (1 + a h/2)^(2k)|, h = 1/D.
    let a = -2.0f64;
    let diff = |d: u64| {
        let h = 1.0 / d as f64;
        (1..=d as i32)
            .map(|k| ((1.0 + a * h).powi(k) - (1.0 + a * h / 2.0).powi(2 * k)).abs())
            .sum::<f64>()
            / d as f64
    };
    let tol = 1e-4;
    let (trials, converged, chosen) = selection(scalar(
        json!(a),
        json!(0),
        json!({"tolerance": tol, "initial_steps": 10, "max_steps": 100000}),
    ));
    // The reference sequence: 10, 20, 40, … until the difference is ≤ tol.
    let mut d = 10;
    let mut want = Vec::new();
    loop {
        want.push(d);
        if diff(d) <= tol {
            break;
        }
        d *= 2;
    }
    assert!(
        want.len() >= 3,
        "the test should refine a few times: {want:?}"
    );
    assert!(converged);
    assert_eq!(chosen, *want.last().unwrap());
    assert_eq!(trials.iter().map(|t| t.0).collect::<Vec<_>>(), want);
    for (steps, got) in trials {
        assert_close(
            got.unwrap(),
            diff(steps),
            1e-9,
            &format!("difference at D = {steps}"),
        );
    }
}

#[test]
fn time_varying_model_matches_a_second_implementation_and_respects_the_cap() {
    // a(t) = −1 − 0.5 sin 3t, u(t) = cos t, Euler from t_{k−1} written plainly here.
    let a = |t: f64| -1.0 - 0.5 * (3.0 * t).sin();
    let u = |t: f64| t.cos();
    let euler = |d: u64| {
        let h = 1.0 / d as f64;
        let mut y = vec![1.0];
        for k in 1..=d {
            let t = (k - 1) as f64 * h;
            let last = y[y.len() - 1];
            y.push(last + (a(t) * last + u(t)) * h);
        }
        y
    };
    let diff = |d: u64| {
        let (c, f) = (euler(d), euler(2 * d));
        let ymax = c.iter().chain(&f).fold(0.0f64, |m, v| m.max(v.abs()));
        (1..=d as usize)
            .map(|k| (c[k] - f[2 * k]).abs())
            .sum::<f64>()
            / d as f64
            / ymax
    };
    // A tolerance the cap (800 steps) cannot reach: 100, 200, 400, then 800 unrefined.
    let (trials, converged, chosen) = selection(scalar(
        json!("-1-0.5*sin(3*t)"),
        json!("cos(t)"),
        json!({"tolerance": 1e-12, "initial_steps": 100, "max_steps": 800}),
    ));
    assert!(!converged);
    assert_eq!(chosen, 800);
    assert_eq!(
        trials.iter().map(|t| t.0).collect::<Vec<_>>(),
        [100, 200, 400, 800]
    );
    assert_eq!(trials[3].1, None);
    for &(steps, got) in &trials[..3] {
        assert_close(
            got.unwrap(),
            diff(steps),
            1e-9,
            &format!("difference at D = {steps}"),
        );
        assert!(got.unwrap() > 1e-12);
    }
}

/// A selection stopped by its cap says which D the tolerance would take (Euler: the
/// difference falls as 1/D) and what to change: max_steps where that D is within the
/// limit of 1e8 steps, the tolerance where it is not.
#[test]
fn a_capped_selection_says_what_would_reach_the_tolerance() {
    let warning = |tolerance: f64| {
        let m = model_from_value(scalar(
            json!("-1-0.5*sin(3*t)"),
            json!("cos(t)"),
            json!({"tolerance": tolerance, "initial_steps": 100, "max_steps": 800}),
        ))
        .unwrap();
        let r = analyze(&m, &Overrides::new(), &mut NoProgress).unwrap();
        let s = r.step_selection.unwrap();
        assert!(!s.converged);
        let (d, diff) = (s.history[2].steps, s.history[2].difference.unwrap());
        let w = r
            .warnings
            .into_iter()
            .find(|w| w.contains("did not reach its tolerance"))
            .expect("the warning");
        (w, d as f64 * diff / tolerance)
    };
    let (w, needed) = warning(1e-12);
    assert!(needed > 1e8, "{needed:e}");
    assert!(
        w.ends_with("beyond the limit of 1e8 steps: raise time.auto.tolerance"),
        "{w}"
    );
    let (w, needed) = warning(1e-5);
    assert!(needed < 1e8 && needed > 800.0, "{needed:e}");
    assert!(w.contains(&format!("about D = {needed:.1e}")), "{w}");
    assert!(
        w.ends_with("raise time.auto.max_steps or time.auto.tolerance"),
        "{w}"
    );
}

/// The covariance recursion alone (the benchmarks' like-for-like run) runs a fixed
/// number of steps; "auto" is refused with the field named.
#[test]
fn covariance_recursion_alone_refuses_auto_steps() {
    let m = model_from_value(scalar(json!(-1.0), json!(0.0), json!({"tolerance": 1e-3}))).unwrap();
    let err = kea_core::covariance_recursion(&m, &Overrides::new(), &mut NoProgress)
        .expect_err("auto steps are refused");
    let errors = err.field_errors();
    assert!(
        errors
            .iter()
            .any(|e| e.path == "time.steps" && e.message.contains("fixed number of steps")),
        "{errors:#?}"
    );
}

/// `time.auto` beside an integer `steps` has no effect: the result says so (it used to
/// be ignored without a word), and the run uses the integer.
#[test]
fn time_auto_with_integer_steps_is_reported_as_without_effect() {
    let mut m = scalar(json!(-1.0), json!(1.0), json!({"tolerance": 1e-3}));
    m["time"]["steps"] = json!(500);
    let r = analyze(
        &model_from_value(m).unwrap(),
        &Overrides::new(),
        &mut NoProgress,
    )
    .unwrap();
    assert_eq!(r.steps, 500);
    assert!(r.step_selection.is_none());
    assert_eq!(
        r.warnings[0],
        "time.auto has no effect: steps is 500, not \"auto\" (set steps to \"auto\" for the step-size selection, or leave time.auto out)"
    );
}

/// A stable but stiff model: Euler is unstable while |1 + aΔt| > 1, here for
/// D ≤ 5000 over [0, 10] with a = −1000, and its solutions overflow. Those trials are
/// not taken as converged (the overflowed differences are NaN, which `max` skips:
/// D = 1000 used to pass with a difference of 0 and the analysis then failed); the
/// selection refines to the first stable D and converges there.
#[test]
fn a_solution_that_overflows_is_refined_not_accepted() {
    let mut model = scalar(
        json!(-1000),
        json!(1000),
        json!({"tolerance": 1e-4, "initial_steps": 1000, "max_steps": 64000}),
    );
    model["time"]["t_end"] = json!(10.0);
    model["system"]["y0"] = json!([0.0]); // (y = 1 is the equilibrium)
    let (trials, converged, chosen) = selection(model);
    // D = 1000, 2000 (|1 + aΔt| = 9, 4) overflow; 4000 (|1 + aΔt| = 1.5) too, over
    // 4000 steps; 8000 (0.25) is stable.
    assert_eq!(
        trials[..3],
        [(1000, None), (2000, None), (4000, None)],
        "{trials:?}"
    );
    assert!(converged, "{trials:?}");
    assert!(chosen >= 8000, "chose D = {chosen}: {trials:?}");
    let (d, diff) = trials[trials.len() - 1];
    assert_eq!(d, chosen);
    assert!(diff.is_some_and(|x| x <= 1e-4), "{trials:?}");
}
