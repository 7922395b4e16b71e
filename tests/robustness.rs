//! Robustness: inputs found by fuzzing the core (parse → validate → analyze, simulate)
//! that broke the rule "bad input gets a clear error naming the field path, never a
//! panic, a NaN/inf in a result, or a hang" — each reduced to a small model — and one
//! seeded randomized test that mutates the presets and checks the rule on a few hundred
//! models.
//!
//! Randomness: the dev-dependencies' `rand` + `rand_chacha` (a seeded ChaCha8 stream,
//! so the test is the same on every run and platform). `proptest` would add shrinking,
//! but its value is in exploring; this test is a fixed regression net (the exploring was
//! done with a fuzzer), and a failing case is printed whole, small enough to read.

mod common;

use kea_core::analysis::result::AnalysisResult;
use kea_core::{Error, NoProgress, Overrides, analyze, model_from_value};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{Value, json};

/// One state, one measurement: the smallest model, to edit.
fn scalar() -> Value {
    json!({
        "time": {"t0": 0, "t_end": 1, "steps": 100},
        "system": {"states": ["x"], "a": [[-1]], "b": [[1]], "y0": [1], "eta0": [1], "phi": [1]},
        "measurement": {"names": ["z"], "c": [[1]], "gamma": [[1]], "psi": [1]},
        "options": {"trace_points": 10}
    })
}

fn run(v: Value) -> Result<AnalysisResult, Error> {
    let m = model_from_value(v)?;
    analyze(&m, &Overrides::new(), &mut NoProgress)
}

/// The error of `v`, which must be one error at `path` containing `fragment`.
fn error_at(v: Value, path: &str, fragment: &str) -> Error {
    let e = match run(v) {
        Err(e) => e,
        Ok(r) => panic!(
            "expected an error at {path}, got a result (final.measured_sko = {:?}, final.gain = {:?})",
            r.final_.measured_sko, r.final_.gain
        ),
    };
    common::assert_error_at(&e, path, fragment);
    e
}

/// Γ V Γᵀ overflowing f64 for a measurement that is never available: the filter never
/// used it, so nothing failed, and the result carried an infinite measured SKO
/// (`final.measured_sko = [inf]`, null in JSON) and ζ. Now the step's inputs are
/// checked where they are computed: an error at step 1, t_1.
#[test]
fn an_overflowing_noise_covariance_is_an_error_even_when_never_used() {
    let mut v = scalar();
    v["measurement"]["gamma"] = json!([["1e200*(1 + t)"]]);
    v["measurement"]["schedule"] = json!([{"when": "-1 - t"}]);
    let e = error_at(
        v,
        "measurement.gamma[0][0]",
        "the measurement-noise covariance Γ V Γᵀ overflowed f64",
    );
    match e {
        Error::Numerical { step, t, .. } => {
            assert_eq!(step, 1);
            assert_eq!(t, 0.01);
        }
        other => panic!("expected a numerical error, got {other:?}"),
    }
    // The same in the seed's form Γ = C g, the measurement never available.
    let mut v = scalar();
    v["measurement"]["gamma"] = Value::Null;
    v["measurement"]["g"] = json!([["max(t - 0.025, 0)*1e300"]]);
    v["measurement"]["schedule"] = json!([{"when": -1}]);
    let e = error_at(v, "measurement.c[0]", "Γ V Γᵀ overflowed f64");
    assert!(e.to_string().contains("(at step 3, t = 0.03)"), "{e}");
}

/// An SKO whose square is below f64's normal range (psi = 1e-160: V = 1e-320, with
/// three significant digits) was run: with phi = 0 the gain was NaN (`final.gain =
/// [[NaN]]`, null in JSON), here the measured SKO came out as 9.99994e-161. eta0 and phi
/// alike, and such a variance given directly in V or W. Now each is refused at its
/// field, as a square above f64's range already was.
#[test]
fn variances_below_the_normal_range_are_refused_at_their_field() {
    for (edit, path) in [
        (
            ("measurement", "psi", json!([1e-160])),
            "measurement.psi[0]",
        ),
        (("system", "eta0", json!([1e-160])), "system.eta0[0]"),
        (("system", "phi", json!([1e-155])), "system.phi[0]"),
    ] {
        let mut v = scalar();
        v[edit.0][edit.1] = edit.2;
        error_at(v, path, "an SKO must be 0 or at least 1.5e-154");
    }
    let mut v = scalar();
    v["measurement"]["psi"] = Value::Null;
    v["measurement"]["V"] = json!([[1e-320]]);
    error_at(
        v,
        "measurement.V[0][0]",
        "a variance must be 0 or at least 2.2e-308",
    );
    let mut v = scalar();
    v["system"]["phi"] = Value::Null;
    v["system"]["W"] = json!([[5e-324]]);
    error_at(
        v,
        "system.W[0][0]",
        "a variance must be 0 or at least 2.2e-308",
    );
    // The smallest accepted SKO, and 0, still run.
    for psi in [1.5e-154, 0.0] {
        let mut v = scalar();
        v["measurement"]["psi"] = json!([psi]);
        let r = run(v).unwrap();
        assert!(r.final_.gain[0][0].is_finite(), "psi = {psi:e}");
    }
}

/// Maxima, criteria and trace values that overflowed f64 became null without a word
/// (ẏ_B with y0 = 1e308, z_B with c = 1e154, relative errors with y_B = 1e-300). Now
/// each null carries a reason or a warning.
#[test]
fn overflowed_maxima_and_trace_values_are_named() {
    let warning = |r: &AnalysisResult, fragment: &str| {
        r.warnings
            .iter()
            .find(|w| w.contains(fragment))
            .unwrap_or_else(|| panic!("no warning with \"{fragment}\" in {:#?}", r.warnings))
            .clone()
    };
    // ẏ = a y = −2e308
    let mut v = scalar();
    v["system"]["y0"] = json!([1e308]);
    v["system"]["a"] = json!([[-2]]);
    let r = run(v).unwrap();
    assert!(r.ydot_max[0].is_infinite());
    warning(
        &r,
        "ẏ_B of \"x\" overflowed f64 (above 1.8e308) and is null",
    );
    // z_B = 1e154 · 1e200
    let mut v = scalar();
    v["system"]["y0"] = json!([1e200]);
    v["system"]["a"] = json!([[0]]);
    v["measurement"]["c"] = json!([[1e154]]);
    let r = run(v).unwrap();
    warning(&r, "z_B of \"z\" overflowed f64");
    let yz = &r.criteria.covariance.per_state[0];
    assert_eq!(yz.yz, None);
    assert!(
        yz.undefined["yz"].starts_with("z_B = Σ|C_ji| y_B,i (1.5) overflowed f64"),
        "{:?}",
        yz.undefined
    );
    // λη / y_B = 1e10 / 1e-300
    let mut v = scalar();
    v["system"]["y0"] = json!([1e-300]);
    v["system"]["a"] = json!([[0]]);
    v["system"]["eta0"] = json!([1e10]);
    v["measurement"]["psi"] = json!([1e10]);
    let r = run(v).unwrap();
    let w = warning(&r, "trace values of \"x\"");
    assert!(w.contains("overflowed f64 and are null"), "{w}");
    assert!(r.traces.states[0].rel_y.iter().all(Option::is_none));
}

/// A measurement-noise variance Γ V Γᵀ below f64's normal range, reached through an
/// expression for Γ (1e-160² = 1e-320) that validation cannot see: the gain came out
/// NaN. Now an error at the step.
#[test]
fn a_subnormal_measurement_noise_variance_is_an_error_at_its_step() {
    let mut v = scalar();
    v["measurement"]["gamma"] = json!([["1e-160*(1 + t)"]]);
    let e = error_at(v, "measurement", "below f64's normal range (2.2e-308)");
    assert!(
        e.to_string()
            .contains("variance of \"z\", a diagonal entry of Γ V Γᵀ, is 1."),
        "{e}"
    );
    assert!(e.to_string().contains("(at step 1, t = 0.01)"), "{e}");
}

/// Further down the same variance is 0 outright (1e-200² underflows), and a constant
/// Γ of 1e-200 ran as a noise-free measurement: the covariance set all null and the
/// bound's F_YZ 1.5e200, while the same variance through an expression was refused.
/// Now both are the same error.
#[test]
fn a_measurement_noise_variance_that_underflows_to_zero_is_an_error() {
    for gamma in [json!(1e-200), json!("1e-200*(1 + t)")] {
        let mut v = scalar();
        v["measurement"]["gamma"] = json!([[gamma]]);
        let e = error_at(v, "measurement", "below f64's normal range (2.2e-308)");
        assert!(
            e.to_string()
                .contains("of \"z\", a diagonal entry of Γ V Γᵀ, underflows to 0 (its terms |γ|ψ are below 1.5e-154)"),
            "{gamma}: {e}"
        );
    }
    // A variance that is 0 because the noise cancels (γ in V's null space) is not
    // an underflow: V = [[1, 1], [1, 1]], γ = [1, −1].
    let mut v = scalar();
    v["measurement"]["gamma"] = json!([[1, -1]]);
    v["measurement"].as_object_mut().unwrap().remove("psi");
    v["measurement"]["V"] = json!([[1, 1], [1, 1]]);
    let r = run(v).expect("a cancelling noise is not an underflow");
    assert_eq!(r.final_.measured_sko[0], 0.0);
    // Without a steady state for the reason it has, not for a suspected model.
    assert!(
        r.warnings.iter().any(|w| w.starts_with(
            "the stationary Riccati solution is not computed where the measurement-noise covariance Γ V Γᵀ is singular"
        )),
        "{:?}",
        r.warnings
    );
}

/// A Monte Carlo of a diverging model (ẏ = 10 v) went on until the simulated process
/// was 1e65: X − Y, the filter's error, was then rounding, and the sample SKO came out
/// exactly 0 — reported as the filter's real accuracy. Now the run stops with the state,
/// the step and the size; the traces CSV has empty cells, never NaN or inf.
#[test]
fn a_simulated_process_that_outgrows_double_precision_stops_the_run() {
    use kea_core::exec::Sequential;
    use kea_core::monte_carlo::{MonteCarloRequest, simulate, traces_csv};
    let mut v = common::preset_value("cv-tracker");
    v["system"]["a"] = json!([[0, 1], [0, 10]]);
    v["time"] = json!({"t0": 0, "t_end": 100, "steps": 1000});
    let m = model_from_value(v).unwrap();
    let req = MonteCarloRequest::new(10, 1);
    let e = simulate(&m, &Overrides::new(), &req, &Sequential, &mut NoProgress).unwrap_err();
    let text = e.to_string();
    assert!(
        text.starts_with("system: the simulated process of \"position\" reached "),
        "{text}"
    );
    assert!(text.contains("times the filter's error SKO"), "{text}");
    // A model whose bound overflows (χ null in the result) writes empty cells.
    let mut v = common::preset_value("cv-tracker");
    v["time"] = json!({"t0": 0, "t_end": 1000, "steps": 10000});
    v["options"]["trace_points"] = json!(4);
    let m = model_from_value(v).unwrap();
    let r = simulate(&m, &Overrides::new(), &req, &Sequential, &mut NoProgress).unwrap();
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("the bound (modulus procedure) overflowed")),
        "{:?}",
        r.warnings
    );
    let csv = traces_csv(&r);
    assert!(!csv.contains("NaN") && !csv.contains("inf"), "{csv}");
    assert!(
        csv.contains(",,"),
        "the overflowed χ is an empty cell: {csv}"
    );
}

/// A Monte Carlo in which no measurement is ever available: the NIS band was null
/// without a word; a warning says why.
#[test]
fn a_simulation_without_measurements_says_why_nis_is_undefined() {
    use kea_core::exec::Sequential;
    use kea_core::monte_carlo::{MonteCarloRequest, simulate};
    let mut v = scalar();
    v["measurement"]["schedule"] = json!([{"when": -1}]);
    let m = model_from_value(v).unwrap();
    let r = simulate(
        &m,
        &Overrides::new(),
        &MonteCarloRequest::new(4, 1),
        &Sequential,
        &mut NoProgress,
    )
    .unwrap();
    assert!(r.consistency.nis.time_average.is_none());
    assert!(
        r.warnings
            .iter()
            .any(|w| w.starts_with("no measurement is available at any step")),
        "{:?}",
        r.warnings
    );
}

/// A bisection over [1e-300, 1e15]: high/low overflowed f64, and the planned number of
/// halvings (u32::MAX) + 1 overflowed too — a panic in a debug build, 0 halvings
/// planned in a release build. Now ln(high) − ln(low): 2 probes + 18 halvings + 2.
#[test]
fn a_bisection_over_an_extreme_bracket_is_planned_and_runs() {
    use kea_core::exec::Sequential;
    use kea_core::synthesis::{planned_analyses, request_from_value, synthesize};
    let mut model = scalar();
    model["params"] = json!({"p": 1});
    model["system"]["y0"] = json!(["p"]);
    let req = request_from_value(json!({
        "model": model,
        "target": {"criterion": "yx", "threshold": 1.0},
        "mode": {"bisect": {"param": "p", "low": 1e-300, "high": 1e15, "rel_tol": 0.009, "probes": 2}}
    }))
    .unwrap();
    // ⌈log2((ln 1e15 − ln 1e-300) / ln 1.009)⌉ + 1 = ⌈16.3⌉ + 1 = 18
    assert_eq!(planned_analyses(&req), 2 + 18 + 2);
    synthesize(&req, &Sequential, &mut NoProgress).unwrap();
}

/// A grid where the criterion is undefined in every cell (y0 = 0: y_B = 0) said "the
/// best is -inf" and advised widening the ranges; now it says there is no value.
#[test]
fn a_grid_with_no_value_anywhere_says_so() {
    use kea_core::exec::Sequential;
    use kea_core::synthesis::{request_from_value, synthesize};
    let mut model = scalar();
    model["params"] = json!({"q": 1});
    model["system"]["phi"] = json!(["q"]);
    model["system"]["y0"] = json!([0]);
    let req = request_from_value(json!({
        "model": model,
        "target": {"criterion": "yz", "criteria": "bound", "threshold": 1},
        "mode": {"grid": {"params": [{"name": "q", "values": [1, 2]}]}}
    }))
    .unwrap();
    let r = synthesize(&req, &Sequential, &mut NoProgress).unwrap();
    assert!(!r.message.contains("inf"), "{}", r.message);
    assert!(
        r.message.starts_with(
            "No cell of 2 meets F_YZ (bound) ≥ 1: the criterion has no value at any point"
        ),
        "{}",
        r.message
    );
}

// ------------------------------------------------------------ randomized regression

/// Numbers, expressions and odd JSON values the mutations put into a model.
const NUMBERS: &[f64] = &[
    0.0,
    -0.0,
    1.0,
    -1.0,
    0.5,
    2.0,
    3.0,
    100.0,
    1e308,
    -1e308,
    1e154,
    1.35e154,
    1e-160,
    1e15,
    1e16,
    1e9,
    0.9999999999,
    1e-9,
    1e8,
];
const EXPRESSIONS: &[&str] = &[
    "1/0",
    "0/0",
    "sqrt(-1)",
    "t^1e9",
    "ln(t)",
    "1/t",
    "exp(t*1000)",
    "1e308*(1 + t)",
    "tan(t)",
    "asin(2)",
    "(-1)^0.5",
    "signum(t - 5)",
    "floor(t)",
    "min(t, 1)",
    "atan2(t, 0)",
    "2^1024",
    "sin(t)",
    "1/(t - 0.5)",
    "-t",
    "0*t",
    "",
    "(",
    "2t",
    "a^b^c",
    "--t",
    "1e400",
    "nan",
    "q",
    "1/q",
    "e",
    "atan2(1)",
];

fn pick<'a, T>(rng: &mut ChaCha8Rng, items: &'a [T]) -> &'a T {
    &items[rng.random_range(0..items.len())]
}

fn random_entry(rng: &mut ChaCha8Rng) -> Value {
    match rng.random_range(0..10) {
        0..=3 => json!(*pick(rng, NUMBERS)),
        4..=6 => json!(*pick(rng, EXPRESSIONS)),
        7 => {
            // deep nesting or a long text (the length limit is 1000 characters)
            let d = rng.random_range(1..600);
            match rng.random_range(0..3) {
                0 => json!(format!("{}t{}", "(".repeat(d), ")".repeat(d))),
                1 => json!(vec!["t"; d].join("+")),
                _ => json!(format!("{}t", "-".repeat(d))),
            }
        }
        8 => Value::Null,
        _ => [json!(true), json!([]), json!({}), json!("auto")][rng.random_range(0..4)].clone(),
    }
}

/// Every JSON pointer of a value.
fn pointers(v: &Value, prefix: String, out: &mut Vec<String>) {
    match v {
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                pointers(x, format!("{prefix}/{i}"), out);
            }
        }
        Value::Object(o) => {
            for (k, x) in o {
                pointers(x, format!("{prefix}/{k}"), out);
            }
        }
        _ => {}
    }
    out.push(prefix);
}

/// One mutation, chosen to reach the validation's and the engine's edges.
fn mutate(v: &mut Value, rng: &mut ChaCha8Rng) {
    let n = v["system"]["states"].as_array().map_or(1, |s| s.len());
    let op = rng.random_range(0..12);
    // (The targeted edits index into objects: not after an edit made a part something
    // else.)
    let objects = ["time", "system", "measurement", "criteria", "options"]
        .iter()
        .all(|k| v.get(k).is_none_or(Value::is_object))
        && v["criteria"].get("weights").is_none_or(Value::is_object);
    if op >= 5 && !objects {
        return;
    }
    match op {
        0..=3 => {
            // any entry, anywhere
            let mut ps = Vec::new();
            pointers(v, String::new(), &mut ps);
            let p = pick(rng, &ps).clone();
            if let Some(x) = v.pointer_mut(&p)
                && !p.is_empty()
            {
                *x = random_entry(rng);
            }
        }
        4 => {
            // a row or an entry removed or repeated: dimension mismatches
            let mut ps = Vec::new();
            pointers(v, String::new(), &mut ps);
            let p = pick(rng, &ps).clone();
            if let Some(Value::Array(a)) = v.pointer_mut(&p)
                && !a.is_empty()
            {
                let i = rng.random_range(0..a.len());
                if rng.random() {
                    a.remove(i);
                } else {
                    let x = a[i].clone();
                    a.push(x);
                }
            }
        }
        5 => {
            let f = *pick(rng, &["t0", "t_end"]);
            v["time"][f] = json!(*pick(rng, &[0.0, -1.0, 1e308, -1e308, 5e-324, 1e17, -0.0]));
        }
        6 => {
            v["time"]["steps"] = json!("auto");
            v["time"]["auto"] = json!({
                "tolerance": *pick(rng, &[1e-300, 1e300, 1.0, 1e-3, 0.0, -1.0]),
                "initial_steps": *pick(rng, &[0u64, 1, 3, 50]),
                "max_steps": *pick(rng, &[0u64, 1, 100, 400])
            });
        }
        7 => {
            v["criteria"]["confidence"] = json!(*pick(
                rng,
                &[0.0, 1.0, 0.9999999999, 0.9999999999999999, 1e-300]
            ));
        }
        8 => {
            let f = *pick(rng, &["yz", "zx", "yx"]);
            let len = *pick(rng, &[n, n, n + 1, n.saturating_sub(1)]);
            let w: Vec<f64> = (0..len)
                .map(|_| *pick(rng, &[0.0, 1.0, 1.0 / n as f64, -0.0, 1e308, -1.0]))
                .collect();
            v["criteria"]["weights"][f] = json!(w);
        }
        9 => {
            v["options"]["trace_points"] = json!(*pick(rng, &[0u64, 1, 2, 3, 7, 100_001]));
        }
        10 => {
            let states = v["system"]["states"].clone();
            let names = v["measurement"]["names"].clone();
            let s = states.get(rng.random_range(0..n)).cloned();
            let m = names.get(0).cloned();
            v["measurement"]["pairs"] = match rng.random_range(0..3) {
                0 => json!([]),
                1 => json!([{"state": s, "measurement": m}, {"state": s, "measurement": m}]),
                _ => json!([{"state": "nope", "measurement": m}]),
            };
        }
        _ => {
            let nm = v["measurement"]["names"].as_array().map_or(1, |a| a.len());
            let s: Vec<Value> = (0..nm)
                .map(|_| match rng.random_range(0..5) {
                    0 => Value::Null,
                    1 => json!({"every": *pick(rng, &[0u64, 1, 3]), "offset": *pick(rng, &[0u64, 2])}),
                    2 => json!({"when": *pick(rng, EXPRESSIONS)}),
                    3 => json!({"unavailable": [[*pick(rng, NUMBERS), *pick(rng, NUMBERS)]]}),
                    _ => json!({"when": "-1"}),
                })
                .collect();
            v["measurement"]["schedule"] = json!(s);
        }
    }
}

/// Every number of a result is finite, except where the result documents a null:
/// criteria and trace values are `Option`s (None is null), and the final bound and
/// open-loop SKOs are NaN (null) after an overflow.
fn assert_finite_or_documented_null(r: &AnalysisResult, model: &str) {
    let fin = |x: f64, what: &str| assert!(x.is_finite(), "{what} = {x} for {model}");
    let all = |v: &[f64], what: &str| v.iter().for_each(|&x| fin(x, what));
    let opt = |v: Option<f64>, what: &str| v.into_iter().for_each(|x| fin(x, what));
    let opts = |v: &[Option<f64>], what: &str| v.iter().for_each(|&x| opt(x, what));
    let rows = |m: &[Vec<f64>], what: &str| m.iter().for_each(|r| all(r, what));
    for x in [r.dt, r.t0, r.t_end, r.confidence, r.lambda] {
        fin(x, "dt, t0, t_end, confidence or lambda");
    }
    all(&r.y_max, "y_max");
    all(&r.ydot_max, "ydot_max");
    all(&r.z_max, "z_max");
    for set in [&r.criteria.bound, &r.criteria.covariance] {
        for s in &set.per_state {
            for x in [s.yz, s.zx, s.yx] {
                opt(x, "a per-state criterion");
            }
        }
        let w = &set.weighted;
        for x in [w.yz, w.zx, w.yx] {
            opt(x, "a weighted criterion");
        }
        for ws in [&w.weights.yz, &w.weights.zx, &w.weights.yx] {
            all(ws, "a weight");
        }
    }
    let f = &r.final_;
    rows(&f.covariance, "final.covariance");
    rows(&f.gain, "final.gain");
    rows(&f.predicted_covariance, "final.predicted_covariance");
    for (v, what) in [
        (&f.zeta, "final.zeta"),
        (&f.potential_sko, "final.potential_sko"),
        (&f.measured_sko, "final.measured_sko"),
        (&f.delta_z, "final.delta_z"),
    ] {
        all(v, what);
    }
    for (v, what) in [
        (&f.eta, "final.eta"),
        (&f.chi, "final.chi"),
        (&f.open_loop_sko, "final.open_loop_sko"),
        (&f.delta_y, "final.delta_y"),
        (&f.delta_x, "final.delta_x"),
    ] {
        // null (NaN) after an overflow, never infinite
        v.iter()
            .for_each(|x| assert!(!x.is_infinite(), "{what} = {x} for {model}"));
    }
    if let Some(s) = &r.steady_state {
        fin(s.t, "steady_state.t");
        rows(&s.covariance, "steady_state.covariance");
        rows(&s.gain, "steady_state.gain");
    }
    if let Some(s) = &r.step_selection {
        fin(s.tolerance, "step_selection.tolerance");
        for t in &s.history {
            opt(t.difference, "step_selection.history.difference");
        }
    }
    all(&r.traces.t, "traces.t");
    for s in &r.traces.states {
        all(&s.y, "traces.y");
        for (v, what) in [
            (&s.eta, "eta"),
            (&s.chi, "chi"),
            (&s.potential_sko, "potential_sko"),
            (&s.open_loop_sko, "open_loop_sko"),
            (&s.rel_y, "rel_y"),
            (&s.rel_x, "rel_x"),
            (&s.local_yx, "local_yx"),
        ] {
            opts(v, what);
        }
        for (v, what) in [
            (&s.zeta, "zeta"),
            (&s.measured_sko, "measured_sko"),
            (&s.rel_z, "rel_z"),
            (&s.local_yz, "local_yz"),
            (&s.local_zx, "local_zx"),
        ] {
            if let Some(v) = v {
                opts(v, what);
            }
        }
    }
}

/// A few hundred mutated presets through parse → validate → analyze: no panic, an
/// error that names a field (or a step and time), or a result whose numbers are finite
/// or a documented null. Steps are capped at 200 so the test stays fast in debug.
#[test]
fn mutated_presets_give_errors_or_finite_results() {
    let mut seeds: Vec<Value> = kea_core::presets::names()
        .into_iter()
        .map(common::preset_value)
        .collect();
    seeds.push(scalar());
    let mut rng = ChaCha8Rng::seed_from_u64(20_240_611);
    let (mut errors, mut results) = (0, 0);
    for case in 0..400 {
        let mut v = pick(&mut rng, &seeds).clone();
        for _ in 0..rng.random_range(1..4) {
            mutate(&mut v, &mut rng);
        }
        // keep each run cheap (the engine's cost is not what is tested here)
        if let Some(d) = v["time"]["steps"].as_u64()
            && (201..=100_000_000).contains(&d)
        {
            v["time"]["steps"] = json!(200);
        }
        let text = v.to_string();
        match run(v) {
            Ok(r) => {
                results += 1;
                assert!(r.steps <= 400, "case {case}: {} steps", r.steps);
                assert_finite_or_documented_null(&r, &text);
            }
            Err(e) => {
                errors += 1;
                match &e {
                    Error::Invalid(list) => {
                        assert!(!list.is_empty(), "case {case}: an empty error list");
                        for f in list {
                            assert!(!f.message.is_empty(), "case {case}: {text}");
                        }
                    }
                    Error::Numerical { t, path, .. } => {
                        assert!(t.is_finite(), "case {case}: t = {t} in {e} for {text}");
                        assert!(!path.is_empty(), "case {case}: no path in {e} for {text}");
                    }
                    Error::Cancelled => panic!("case {case}: cancelled"),
                }
            }
        }
    }
    // Both kinds of outcome are exercised.
    assert!(
        errors > 50 && results > 50,
        "{errors} errors, {results} results"
    );
}

/// An initial SKO 150 orders of magnitude above the measurement's (cv-tracker with
/// eta0 = 1e150, inside the SKOs' range): the position's update is exact, but the
/// velocity's variance, known only through two positions, cancels to rounding level
/// at step 2, and at step 3 q comes out ≤ 0. That was reported as a singular
/// innovation covariance ("a measurement has no error…"), naming the measurement;
/// now as the precision it is, from the step it began.
#[test]
fn an_innovation_covariance_lost_to_rounding_says_so() {
    let mut v = common::preset_value("cv-tracker");
    v["system"]["eta0"] = json!([1e150, 1e150]);
    let e = error_at(
        v,
        "system",
        "the filter's covariance lost its precision: from step 2 (t = 0.2) the update cancelled the variance of \"velocity\"",
    );
    assert!(
        e.to_string()
            .contains("bring them nearer, or rescale the units"),
        "{e}"
    );
}

/// The analysis's traces CSV wrote f64's plain form: 1e200 as a 201-digit number,
/// 1e-150 with 150 zeros. Values outside [1e-4, 1e15) are now in exponent form, and
/// every cell still reads back to the result's value.
#[test]
fn the_traces_csv_writes_extreme_values_in_exponent_form() {
    let mut v = scalar();
    v["system"]["a"] = json!([[0]]);
    v["system"]["y0"] = json!([1e200]);
    v["system"]["eta0"] = json!([1e-150]);
    let r = run(v).unwrap();
    let csv = kea_core::analysis::report::traces_csv(&r);
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let y = header
        .iter()
        .position(|h| *h == "y:x")
        .expect("a y:x column");
    let mut rows = 0;
    for (k, line) in lines.enumerate() {
        let cells: Vec<&str> = line.split(',').collect();
        assert!(cells.iter().all(|c| c.len() <= 24), "row {k}: {line}");
        let want = r.traces.states[0].y[k];
        assert_eq!(cells[y].parse::<f64>().unwrap(), want, "row {k}");
        rows += 1;
    }
    assert!(rows > 2);
    assert!(csv.contains(",1e200,"), "{csv}");
}

/// A stable but stiff model whose Euler step is unstable (a = −1e6, Δt = 0.01:
/// |1 + aΔt| ≈ 1e4) overflowed as "the model diverges faster than f64 can follow",
/// blaming the model. Now the error says the model is stable, the step is not, and
/// how many steps would do; a model that truly diverges keeps its message.
#[test]
fn an_unstable_euler_step_of_a_stable_model_says_how_many_steps_would_do() {
    let mut v = scalar();
    v["system"]["a"] = json!([[-1e6]]);
    let e = error_at(
        v,
        "system.a",
        "the mean state overflowed, though the model is stable here",
    );
    assert!(
        e.to_string().contains(
            "(Euler is stable for it only with Δt < 2e-6); give time.steps ≥ 500001 (now 100)"
        ),
        "{e}"
    );
    let mut v = scalar();
    v["system"]["a"] = json!([[1e6]]);
    error_at(
        v,
        "system.a",
        "the model diverges faster than f64 can follow",
    );
}

/// With a tiny confidence (P = 1e-7, λ = 1.3e-7) a scalar a = 0 model was warned that
/// its bound "grew far beyond the covariance's confidence interval … oscillatory or
/// feedback dynamics": χ was 2.1e7 times λσ because λσ was tiny, not the bound large
/// (χ = 0.925, σ = 0.347). Below λ = 1 the bound is compared with σ.
#[test]
fn a_tiny_confidence_does_not_make_the_bound_look_grown() {
    let model = |confidence: f64| {
        model_from_value(json!({
            "time": {"t0": 0, "t_end": 1, "steps": 10},
            "system": {"states": ["x"], "a": [[0]], "b": [[1]], "phi": [1], "y0": [1], "eta0": [1]},
            "measurement": {"names": ["z"], "c": [[1]], "gamma": [[1]], "psi": [1]},
            "criteria": {"confidence": confidence}
        }))
        .unwrap()
    };
    for confidence in [1e-7, 0.5, 0.95] {
        let r = analyze(&model(confidence), &Overrides::new(), &mut NoProgress).unwrap();
        assert!(
            !r.warnings.iter().any(|w| w.contains("grew far beyond")),
            "P = {confidence}: {:?}",
            r.warnings
        );
    }
}

/// C r Cᵀ overflowing f64 (c = 1e20 against an initial SKO of 1e140) was reported as
/// a singular innovation covariance, "measurement \"z\" adds nothing to  (…)", with
/// an empty list of other measurements. It is an overflow, named at the row of c.
#[test]
fn an_overflowing_innovation_variance_is_not_called_singular() {
    let mut v = scalar();
    v["system"]["eta0"] = json!([1e140]);
    v["measurement"]["c"] = json!([[1e20]]);
    let e = error_at(
        v,
        "measurement.c[0]",
        "the innovation variance of measurement \"z\" (C r Cᵀ + Γ V Γᵀ) overflowed f64",
    );
    assert!(!e.to_string().contains("singular"), "{e}");
}

/// A mean overflowing with a = 0 was blamed on `system.a` ("the model diverges"):
/// the cause is the input u (or y0), too large for f64 over the interval.
#[test]
fn a_mean_overflowing_without_growth_names_u_or_y0() {
    let mut v = scalar();
    v["system"]["a"] = json!([[0]]);
    v["system"]["u"] = json!([-1e308]);
    v["time"] = json!({"t0": 0, "t_end": 2, "steps": 20});
    error_at(
        v,
        "system.u[0]",
        "where A does not grow: its input u is too large",
    );
    let mut v = scalar();
    v["system"]["a"] = json!([[0]]);
    v["system"]["y0"] = json!([1.7e308]);
    v["system"]["u"] = json!([1e307]);
    v["time"] = json!({"t0": 0, "t_end": 1, "steps": 10});
    error_at(v, "system.y0[0]", "its initial mean y0 is too large");
    // A growing A stays the cause it was.
    let mut v = scalar();
    v["system"]["a"] = json!([[800]]);
    v["system"]["y0"] = json!([1e300]);
    error_at(
        v,
        "system.a",
        "the model diverges faster than f64 can follow",
    );
}

/// Nearly dependent measurement noises (Γ V Γᵀ of condition ≈ 1e10 here) cost the
/// whitening about 10 digits without a word: an audit found χ 2× off at 7.6e18. A
/// warning now names the first step and the digits; Rv of condition 1e6 gives none.
#[test]
fn an_ill_conditioned_measurement_noise_covariance_is_warned_of() {
    let model = |tiny: f64| {
        json!({
            "time": {"t0": 0.0, "t_end": 1.0, "steps": 10},
            "system": {
                "states": ["x1", "x2"], "a": [[0, 1], [0, 0]], "b": [[0], [1]],
                "phi": [1], "y0": [1, 1], "eta0": [1, 1]
            },
            "measurement": {
                "names": ["z1", "z2"], "c": [[1, 0], [0, 1]],
                "gamma": [[1, 0], [1, tiny]], "psi": [1, 1]
            }
        })
    };
    let r = run(model(1e-5)).unwrap();
    let w = r
        .warnings
        .iter()
        .find(|w| w.contains("ill-conditioned"))
        .unwrap_or_else(|| panic!("no warning in {:#?}", r.warnings));
    assert!(
        w.starts_with("the measurement noise covariance Γ V Γᵀ is ill-conditioned from step 1 (t = 0.1): the pivots of its factorisation span up to 1.0e10")
            && w.contains("loses about 10 of f64's 16 digits"),
        "{w}"
    );
    let r = run(model(1e-3)).unwrap();
    assert!(
        !r.warnings.iter().any(|w| w.contains("ill-conditioned")),
        "{:#?}",
        r.warnings
    );
}
