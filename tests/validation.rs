//! Every kind of bad model gets a precise error: the field path and what was expected.
//! No panic and no NaN for any of them.

mod common;

use kea_core::{Error, NoProgress, Overrides, analyze, model_from_value};
use serde_json::{Value, json};

fn good() -> Value {
    json!({
        "params": {"m": 100.0, "s": 37.17, "psi": 1e-5},
        "time": {"t0": 0.0, "t_end": 10.0, "steps": 1000},
        "system": {
            "states": ["x", "v"],
            "a": [[0, 1], ["-s/m", 0]],
            "u": [0, "0.3*sin(2*t)"],
            "b": [[0], [1]],
            "y0": [1, 0],
            "eta0": [0.1, 0.1],
            "phi": [0.5]
        },
        "measurement": {"names": ["zx"], "c": [[1, 0]], "gamma": [[1]], "psi": ["psi*1e4"]},
        "criteria": {"confidence": 0.95}
    })
}

/// Apply `edit` to the good model and expect an error at `path` containing `fragment`.
fn expect(edit: impl FnOnce(&mut Value), set: &[(&str, f64)], path: &str, fragment: &str) {
    let mut v = good();
    edit(&mut v);
    let set: Overrides = set.iter().map(|(k, x)| (k.to_string(), *x)).collect();
    let err = match model_from_value(v) {
        Err(e) => e,
        Ok(m) => match analyze(&m, &set, &mut NoProgress) {
            Err(e) => e,
            Ok(r) => panic!(
                "expected an error at {path}, got a result with F_YX = {:?}",
                r.criteria.covariance.weighted.yx
            ),
        },
    };
    common::assert_error_at(&err, path, fragment);
}

#[test]
fn the_good_model_runs() {
    let m = model_from_value(good()).unwrap();
    let r = analyze(&m, &Overrides::new(), &mut NoProgress).unwrap();
    assert!(r.criteria.covariance.weighted.yx.unwrap().is_finite());
}

#[test]
fn dimensions() {
    expect(
        |v| v["system"]["a"][1] = json!([0]),
        &[],
        "system.a[1]",
        "this row of `a` has 1 entry, expected 2 (N = 2)",
    );
    expect(
        |v| v["system"]["a"] = json!([[0, 1]]),
        &[],
        "system.a",
        "has 1 rows, expected 2",
    );
    expect(
        |v| v["system"]["u"] = json!([0]),
        &[],
        "system.u",
        "expected 2",
    );
    expect(
        |v| v["system"]["b"][1] = json!([1, 2]),
        &[],
        "system.b[1]",
        "has 2 entries, expected 1",
    );
    expect(
        |v| v["system"]["phi"] = json!([0.5, 0.5]),
        &[],
        "system.phi",
        "expected 1",
    );
    expect(
        |v| v["measurement"]["c"][0] = json!([1, 0, 0]),
        &[],
        "measurement.c[0]",
        "expected 2",
    );
    expect(
        |v| v["measurement"]["gamma"] = json!([[1], [1]]),
        &[],
        "measurement.gamma",
        "expected 1",
    );
    expect(
        |v| v["measurement"]["psi"] = json!([1, 2]),
        &[],
        "measurement.psi",
        "expected 1",
    );
    expect(
        |v| v["system"]["y0"] = json!([1]),
        &[],
        "system.y0",
        "expected 2",
    );
    expect(
        |v| v["measurement"]["names"] = json!(["a", "b", "c"]),
        &[],
        "measurement.names",
        "3 measurements but only 2 states",
    );
}

#[test]
fn expressions() {
    expect(
        |v| v["system"]["a"][1][0] = json!("-s/mass"),
        &[],
        "system.a[1][0]",
        "unknown parameter \"mass\"",
    );
    expect(
        |v| v["system"]["a"][1][0] = json!("-s/mass"),
        &[],
        "system.a[1][0]",
        "position 4",
    );
    expect(
        |v| v["system"]["a"][0][1] = json!("(1+t"),
        &[],
        "system.a[0][1]",
        "unbalanced '('",
    );
    expect(
        |v| v["system"]["a"][0][1] = json!("1+*t"),
        &[],
        "system.a[0][1]",
        "cannot parse",
    );
    expect(
        |v| v["measurement"]["c"][0][0] = json!("1+t"),
        &[],
        "measurement.c[0][0]",
        "must be constant",
    );
    expect(
        |v| v["system"]["phi"][0] = json!("sin(t)"),
        &[],
        "system.phi[0]",
        "must be constant",
    );
    expect(
        |v| v["system"]["a"][0][1] = json!("1/0"),
        &[],
        "system.a[0][1]",
        "finite",
    );
    expect(
        |v| v["system"]["a"][0][1] = json!(""),
        &[],
        "system.a[0][1]",
        "empty expression",
    );
    // finite at t0 but not later: reported at the step where it happens
    expect(
        |v| v["system"]["a"][0][1] = json!("1/(t-5)"),
        &[],
        "system.a[0][1]",
        "not finite",
    );
}

#[test]
fn numbers_and_ranges() {
    expect(
        |v| v["system"]["eta0"][0] = json!(-1),
        &[],
        "system.eta0[0]",
        "an SKO must be ≥ 0",
    );
    expect(
        |v| v["system"]["phi"][0] = json!(-0.5),
        &[],
        "system.phi[0]",
        "an SKO must be ≥ 0",
    );
    expect(
        |v| v["system"]["phi"][0] = json!(-1.35e154),
        &[],
        "system.phi[0]",
        "an SKO must be ≥ 0, got -1.35e154",
    );
    expect(
        |v| v["measurement"]["psi"][0] = json!("-psi"),
        &[],
        "measurement.psi[0]",
        "an SKO must be ≥ 0",
    );
    expect(
        |v| v["time"]["t_end"] = json!(0.0),
        &[],
        "time.t_end",
        "must be greater than t0",
    );
    expect(
        |v| v["time"]["steps"] = json!(0),
        &[],
        "time.steps",
        "at least 1",
    );
    expect(
        |v| v["time"]["steps"] = json!(1_000_000_000_000u64),
        &[],
        "time.steps",
        "more than the limit",
    );
    expect(
        |v| v["time"]["steps"] = json!(1e30),
        &[],
        "time.steps",
        "1e30 steps is more than the limit of 100000000",
    );
    expect(
        |v| {
            v["time"]["steps"] = json!("auto");
            v["time"]["auto"] = json!({"initial_steps": 1e9});
        },
        &[],
        "time.auto.initial_steps",
        "must not exceed the limit of 100000000",
    );
    expect(
        |v| v["time"]["steps"] = json!("many"),
        &[],
        "time.steps",
        "expected a positive integer or \"auto\"",
    );
    expect(|v| v["time"]["steps"] = json!(-3), &[], "time.steps", "");
    expect(
        |v| v["criteria"]["confidence"] = json!(1.5),
        &[],
        "criteria.confidence",
        "strictly between 0 and 1",
    );
    expect(
        |v| v["options"] = json!({"trace_points": 1}),
        &[],
        "options.trace_points",
        "or 2 to",
    );
    expect(
        |v| v["params"]["t"] = json!(1.0),
        &[],
        "params.t",
        "time variable",
    );
    expect(
        |v| v["params"]["sin"] = json!(1.0),
        &[],
        "params.sin",
        "function or constant",
    );
    // Constants too: a param `e` was once silently read as Euler's number.
    for name in ["e", "E", "PI", "TAU", "τ", "atan2", "min", "max"] {
        expect(
            |v| v["params"][name] = json!(1.0),
            &[],
            &format!("params.{name}"),
            "function or constant",
        );
    }
}

#[test]
fn weights() {
    expect(
        |v| v["criteria"]["weights"] = json!({"yx": [0.5, 0.4]}),
        &[],
        "criteria.weights.yx",
        "sum to 1",
    );
    expect(
        |v| v["criteria"]["weights"] = json!({"yx": [1.0]}),
        &[],
        "criteria.weights.yx",
        "one per state",
    );
    expect(
        |v| v["criteria"]["weights"] = json!({"yz": [0.5, 0.5]}),
        &[],
        "criteria.weights.yz[1]",
        "no paired measurement",
    );
    expect(
        |v| v["criteria"]["weights"] = json!({"yx": [-0.5, 1.5]}),
        &[],
        "criteria.weights.yx[0]",
        "≥ 0",
    );
}

#[test]
fn noise_covariances() {
    expect(
        |v| v["system"]["W"] = json!([[1.0]]),
        &[],
        "system.W",
        "not both",
    );
    expect(
        |v| {
            v["system"].as_object_mut().unwrap().remove("phi");
        },
        &[],
        "system.phi",
        "missing",
    );
    expect(
        |v| {
            v["measurement"].as_object_mut().unwrap().remove("psi");
            v["measurement"]["V"] = json!([[-1.0]]);
        },
        &[],
        "measurement.V",
        "positive semi-definite",
    );
    expect(
        |v| {
            v["system"]["b"] = json!([[1, 0], [0, 1]]);
            v["system"].as_object_mut().unwrap().remove("phi");
            v["system"]["W"] = json!([[1.0, 0.5], [0.4, 1.0]]);
        },
        &[],
        "system.W[1][0]",
        "symmetric: this entry is 0.4 but its mirror across the diagonal is 0.5",
    );
    // Extreme values in exponent form, not 155 zeros.
    expect(
        |v| {
            v["system"]["b"] = json!([[1, 0], [0, 1]]);
            v["system"].as_object_mut().unwrap().remove("phi");
            v["system"]["W"] = json!([[1.0, 1e-155], [0, 1.0]]);
        },
        &[],
        "system.W[1][0]",
        "this entry is 0 but its mirror across the diagonal is 1e-155",
    );
    expect(
        |v| {
            v["measurement"].as_object_mut().unwrap().remove("gamma");
        },
        &[],
        "measurement.gamma",
        "missing",
    );
}

#[test]
fn names_pairs_and_overrides() {
    expect(
        |v| v["system"]["states"] = json!(["x", "x"]),
        &[],
        "system.states[1]",
        "duplicate",
    );
    expect(
        |v| v["measurement"]["pairs"] = json!([{"state": "q", "measurement": "zx"}]),
        &[],
        "measurement.pairs[0].state",
        "no state named \"q\"",
    );
    // zx measures x (c = [[1, 0]]), not v: a pair of them would compare unrelated SKOs.
    expect(
        |v| v["measurement"]["pairs"] = json!([{"state": "v", "measurement": "zx"}]),
        &[],
        "measurement.pairs[0]",
        "does not measure state \"v\" (its entry of c is 0)",
    );
    expect(
        |_| {},
        &[("mass", 1.0)],
        "set.mass",
        "no parameter \"mass\"",
    );
    expect(|_| {}, &[("m", f64::NAN)], "set.m", "finite");
    // A name that is not an identifier is quoted in its path: `params.a.b` would
    // read as member b of a param a.
    expect(
        |v| v["params"]["a.b"] = json!(1.0),
        &[],
        "params[\"a.b\"]",
        "must be an identifier",
    );
    expect(
        |_| {},
        &[("x y", 1.0)],
        "set[\"x y\"]",
        "no parameter \"x y\"",
    );
}

#[test]
fn malformed_json_is_located() {
    expect(
        |v| v["system"]["a"][0][0] = json!(true),
        &[],
        "system.a[0][0]",
        "",
    );
    expect(
        |v| v["system"]["extra"] = json!(1),
        &[],
        "system.extra",
        "unknown member; expected one of: states, a, transition, prior_at, u, b",
    );
    // serde's path of a member whose key is not an identifier, quoted the same way.
    expect(
        |v| v["params"]["a[0]"] = json!("x"),
        &[],
        "params[\"a[0]\"]",
        "",
    );
    expect(
        |v| v["kea_model"] = json!(7),
        &[],
        "kea_model",
        "unsupported model format version 7",
    );
}

#[test]
fn singular_innovation_covariance_names_step_and_time() {
    let mut v = good();
    v["measurement"]["psi"] = json!([0.0]);
    v["system"]["eta0"] = json!([0.0, 0.0]);
    v["system"]["phi"] = json!([0.0]);
    let m = model_from_value(v).unwrap();
    let e = analyze(&m, &Overrides::new(), &mut NoProgress).unwrap_err();
    match &e {
        Error::Numerical {
            step,
            t,
            path,
            message,
        } => {
            assert_eq!(*step, 1);
            assert!((t - 0.01).abs() < 1e-12);
            assert_eq!(path, "measurement.c[0]");
            assert!(
                message.contains("innovation covariance")
                    && message.contains("measurement \"zx\" has no error"),
                "{message}"
            );
        }
        other => panic!("expected a numerical error, got {other:?}"),
    }
    assert!(e.to_string().contains("at step 1, t = 0.01"), "{e}");
}

#[test]
fn results_never_contain_nan() {
    // y ≡ 0: relative errors undefined -> null with a reason, not NaN
    let mut v = good();
    v["system"]["y0"] = json!([0, 0]);
    v["system"]["u"] = json!([0, 0]);
    let r = analyze(
        &model_from_value(v).unwrap(),
        &Overrides::new(),
        &mut NoProgress,
    )
    .unwrap();
    let text = serde_json::to_string(&r).unwrap();
    assert!(
        !text.contains("NaN") && !text.contains("inf"),
        "{text:.300}"
    );
    let s = &r.criteria.bound.per_state[0];
    assert!(s.yx.is_none());
    assert!(s.undefined["yx"].contains("y_B = 0"), "{:?}", s.undefined);
    assert!(r.criteria.bound.weighted.yx.is_none());
}

#[test]
fn cancellation_stops_the_run() {
    let mut v = good();
    v["time"]["steps"] = json!(1_000_000);
    let m = model_from_value(v).unwrap();
    let mut calls = 0;
    let mut cancel_second = |_f: f64| {
        calls += 1;
        if calls >= 2 {
            std::ops::ControlFlow::Break(())
        } else {
            std::ops::ControlFlow::Continue(())
        }
    };
    let e = analyze(&m, &Overrides::new(), &mut cancel_second).unwrap_err();
    assert_eq!(e, Error::Cancelled);
}

/// An N-state chain whose a entries are `text(i, j)`.
fn chain(n: usize, text: impl Fn(usize, usize) -> String) -> Value {
    let id = |i: usize, j: usize| if i == j { 1.0 } else { 0.0 };
    json!({
        "time": {"t0": 0.0, "t_end": 1.0, "steps": 50},
        "system": {
            "states": (0..n).map(|i| format!("s{i}")).collect::<Vec<_>>(),
            "a": (0..n).map(|i| (0..n).map(|j| text(i, j)).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "b": (0..n).map(|i| (0..n).map(|j| id(i, j)).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "y0": vec![1.0; n],
            "eta0": vec![0.5; n],
            "phi": vec![0.1; n]
        },
        "measurement": {
            "names": (0..n).map(|j| format!("m{j}")).collect::<Vec<_>>(),
            "c": (0..n).map(|i| (0..n).map(|j| id(i, j)).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "gamma": (0..n).map(|i| (0..n).map(|j| id(i, j)).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "psi": vec![0.01; n]
        }
    })
}

#[test]
fn distinct_time_expressions_are_limited_and_reported_once() {
    // 50 × 50 distinct time-dependent entries: entry 2000 (row-major) is the first
    // beyond the limit of 2000, and the limit is reported there only.
    let m = model_from_value(chain(50, |i, j| format!("-0.5*t*{}", i * 50 + j + 1))).unwrap();
    let err = analyze(&m, &Overrides::new(), &mut NoProgress).unwrap_err();
    let errors = err.field_errors();
    assert_eq!(errors.len(), 1, "{errors:#?}");
    assert_eq!(errors[0].path, "system.a[40][0]");
    assert!(
        errors[0]
            .message
            .contains("more than 2000 distinct time-dependent expressions")
    );
}

#[test]
fn work_estimates_count_every_step_not_only_n_cubed() {
    // steps × (N³ + 16N² + 200): a one-state step is not free.
    assert_eq!(kea_core::analysis::work::step_cost(1), 217.0);
    assert_eq!(kea_core::analysis::work::step_cost(10), 2800.0);
    let m = model_from_value(chain(
        10,
        |i, j| if i == j { "-1".into() } else { "0".into() },
    ))
    .unwrap();
    let w = kea_core::analysis::work::estimate_work(&m, &Overrides::new()).unwrap();
    assert_eq!((w.steps, w.states, w.work), (50, 10, 50.0 * 2800.0));
}

/// Where A and the measurements are sparse, the engine's part of the estimate counts
/// a's non-zeros and the measurements (2(N + nnz(a))N + nN²) in place of N³: an
/// N = 200 chain measured once was estimated 33 times its time. Where N³ is the
/// smaller (every state measured, or a dense a), it stays.
#[test]
fn work_estimates_count_a_sparse_a_and_few_measurements() {
    use kea_core::analysis::work::{AnalysisOnce, analysis_work};
    use kea_core::work::Work;
    // The steps' part (the once part: cost.rs's own test).
    let work = |m: &Value| {
        let m = model_from_value(m.clone()).unwrap();
        let compiled = kea_core::model::compile(&m, &Overrides::new()).unwrap();
        let w = analysis_work(&compiled, Some(&m));
        let once = AnalysisOnce::of(&compiled, Some(&m)).units();
        Work {
            units: w.units - once,
            ..w
        }
    };
    let n = 200;
    let bidiagonal = |i: usize, j: usize| match j.wrapping_sub(i) {
        0 => "-1".to_string(),
        1 => "1".to_string(),
        _ => "0".to_string(),
    };
    let mut one = chain(n, bidiagonal);
    one["measurement"] = json!({
        "names": ["m0"],
        "c": [(0..n).map(|j| if j == 0 { 1.0 } else { 0.0 }).collect::<Vec<_>>()],
        "gamma": [[1.0]],
        "psi": [0.01]
    });
    one["options"] = json!({"trace_points": 0});
    let w = work(&one);
    let nnz = 2 * n - 1;
    let engine = 2.0 * (n + nnz) as f64 * n as f64 + (n * n) as f64 + 16.0 * (n * n) as f64 + 200.0;
    assert_eq!(w.units, 50.0 * engine, "{}", w.explain);
    assert!(
        w.explain.contains("399 non-zeros in a, n = 1: below N³"),
        "{}",
        w.explain
    );
    // Every state measured: N³.
    let mut all = chain(n, bidiagonal);
    all["options"] = json!({"trace_points": 0});
    let all = work(&all);
    assert_eq!(
        all.units,
        50.0 * kea_core::analysis::work::step_cost(n),
        "{}",
        all.explain
    );
    // A dense a, measured once: N³ too (2(N + N²)N + N² is larger).
    one["system"]["a"] = json!(vec![vec![0.5; n]; n]);
    assert_eq!(
        work(&one).units,
        50.0 * kea_core::analysis::work::step_cost(n)
    );
}

#[test]
fn schedule_expressions_count_with_the_others() {
    // 100 measurements, each available `when` a distinct 600-character expression:
    // 84 × 600 characters is the first total beyond the limit of 50 000.
    let n = 100;
    let mut m = chain(n, |i, j| if i == j { "-1".into() } else { "0".into() });
    let when = |j: usize| format!("sin(t+{j:05}){}", "+0*t".repeat(147));
    assert_eq!(when(7).len(), 600);
    m["measurement"]["schedule"] = (0..n).map(|j| json!({"when": when(j)})).collect();
    let err = analyze(
        &model_from_value(m).unwrap(),
        &Overrides::new(),
        &mut NoProgress,
    )
    .unwrap_err();
    let errors = err.field_errors();
    assert_eq!(errors.len(), 1, "{errors:#?}");
    assert_eq!(errors[0].path, "measurement.schedule[83].when");
    assert!(
        errors[0].message.contains("exceed 50000 characters"),
        "{}",
        errors[0].message
    );
}

#[test]
fn repeated_expressions_are_shared_with_the_same_results() {
    // Every a entry of a 60-state model is time-dependent, with 3 distinct texts:
    // 3600 entries, over the limit if each counted. A 12-state copy whose entries
    // are written "(…)+0*k" parses 144 separate expressions; shared or separate,
    // the results must agree bit for bit.
    let text = |i: usize, j: usize| match (i == j, j == i + 1) {
        (true, _) => "-1-0.2*sin(t)".to_string(),
        (_, true) => "0.5+0.1*t".to_string(),
        _ => "0.001*cos(3*t)".to_string(),
    };
    let m = model_from_value(chain(60, text)).unwrap();
    let r = analyze(&m, &Overrides::new(), &mut NoProgress).unwrap();
    assert!(r.criteria.covariance.weighted.yx.unwrap().is_finite());

    let n = 12;
    let shared = model_from_value(chain(n, text)).unwrap();
    let separate =
        model_from_value(chain(n, |i, j| format!("({})+0*{}", text(i, j), i * n + j))).unwrap();
    let a = analyze(&shared, &Overrides::new(), &mut NoProgress).unwrap();
    let b = analyze(&separate, &Overrides::new(), &mut NoProgress).unwrap();
    let strip = |r: &kea_core::AnalysisResult| {
        let mut v = serde_json::to_value(r).unwrap();
        v["timing"] = Value::Null;
        v
    };
    assert_eq!(strip(&a), strip(&b));
}

#[test]
fn expression_length_is_limited() {
    // exmex parses some shapes in superlinear time: bounded before parsing.
    let long = format!("t{}", "*(-1)".repeat(400));
    expect(
        |v| v["system"]["u"][1] = json!(long),
        &[],
        "system.u[1]",
        "expression of 2001 characters; the limit is 1000",
    );
    // Distinct time-dependent texts of ≈ 999 characters: the total is limited too,
    // reported at the first entry beyond 50 000 characters.
    let text = |k: usize| {
        let head = format!("t*{k}");
        format!("{head}{}", "+0".repeat((999 - head.len()) / 2))
    };
    let n = 8;
    let mut total = 0;
    let first_over = (0..n * n)
        .find(|&k| {
            total += text(k).len();
            total > 50_000
        })
        .unwrap();
    let m = model_from_value(chain(n, |i, j| text(i * n + j))).unwrap();
    let err = analyze(&m, &Overrides::new(), &mut NoProgress).unwrap_err();
    let errors = err.field_errors();
    assert_eq!(errors.len(), 1, "{errors:#?}");
    assert_eq!(
        errors[0].path,
        format!("system.a[{}][{}]", first_over / n, first_over % n)
    );
    assert!(
        errors[0]
            .message
            .contains("exceed 50000 characters in total")
    );
}

/// The values a result's traces hold (t and every state's series), counted in its JSON.
fn trace_values(r: &kea_core::AnalysisResult) -> usize {
    let traces = serde_json::to_value(&r.traces).unwrap();
    let arrays = traces["states"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|s| s.as_object().unwrap().values())
        .filter_map(Value::as_array)
        .map(Vec::len);
    traces["t"].as_array().unwrap().len() + arrays.sum::<usize>()
}

/// The limit of 2 000 000 trace values counted 10 series a state, while a paired
/// state has 13 in the result: N = 100, all paired, passed 2000 rows, 2.6 M values.
/// Now the largest `trace_points` allowed is the largest whose result holds at most
/// 2 000 000 values, counted in the result itself (30 states, 20 of them paired).
#[test]
fn trace_size_is_limited_by_the_values_it_holds() {
    let with_points = |tp: usize, steps: usize| {
        let mut v = chain(30, |i, j| if i == j { "-1" } else { "0" }.to_string());
        for key in ["names", "c", "gamma", "psi"] {
            v["measurement"][key].as_array_mut().unwrap().truncate(20);
        }
        for row in v["measurement"]["gamma"].as_array_mut().unwrap() {
            row.as_array_mut().unwrap().truncate(20);
        }
        v["options"] = json!({"trace_points": tp});
        v["time"]["steps"] = json!(steps);
        model_from_value(v).unwrap()
    };
    let err = analyze(
        &with_points(100_000, 10),
        &Overrides::new(),
        &mut NoProgress,
    )
    .unwrap_err();
    let e = &err.field_errors()[0];
    assert_eq!(e.path, "options.trace_points");
    let most: usize = e.message["expected 0 (no traces) or 2 to ".len()..]
        .split(',')
        .next()
        .unwrap()
        .parse()
        .unwrap_or_else(|_| panic!("{}", e.message));
    assert!(
        e.message
            .contains("13 for each of the 20 paired states, 8 for each of the other 10"),
        "{}",
        e.message
    );
    // `most` rows fit, and one more row would not.
    let r = analyze(&with_points(most, most), &Overrides::new(), &mut NoProgress).unwrap();
    assert_eq!(r.traces.t.len(), most);
    let values = trace_values(&r);
    assert!(values <= 2_000_000, "{values} values in {most} rows");
    assert!(
        values + values / most > 2_000_000,
        "{values} values in {most} rows"
    );
    let err = analyze(
        &with_points(most + 1, 10),
        &Overrides::new(),
        &mut NoProgress,
    );
    assert_eq!(
        err.unwrap_err().field_errors()[0].path,
        "options.trace_points"
    );
}

#[test]
fn many_errors_are_listed_up_to_a_limit_and_name_lists_stay_short() {
    // 144 entries naming an unknown parameter, with 500 params defined: the response
    // lists 100 errors and says how many more; each lists 12 known names and a count.
    let mut v = chain(12, |_, _| "zz".to_string());
    v["params"] = (0..500).map(|i| (format!("p{i:03}"), json!(1.0))).collect();
    let err = model_from_value(v).and_then(|m| analyze(&m, &Overrides::new(), &mut NoProgress));
    let errors = err.unwrap_err().field_errors();
    assert_eq!(errors.len(), 101);
    assert_eq!(errors[0].path, "system.a[0][0]");
    assert!(
        errors[0].message.contains(
            "unknown parameter \"zz\" in \"zz\" (known: t, p000, p001, p002, p003, p004, p005, p006, p007, p008, p009, p010, … (501 names in all))"
        ),
        "{}",
        errors[0].message
    );
    assert_eq!(errors[100].path, "");
    assert_eq!(
        errors[100].message,
        "… and 44 more errors (only the first 100 are listed)"
    );
}

#[test]
fn noise_sources_are_limited_before_anything_is_sized_by_them() {
    // W is L × L: 300 000 columns of b asked for 720 GB and aborted the process.
    expect(
        |v| {
            v["system"]["b"] = json!([vec![0.0; 201], vec![1.0; 201]]);
            v["system"]["phi"] = json!(vec![0.5; 201]);
        },
        &[],
        "system.b[0]",
        "L (columns of b) = 201: more than the limit of 200 noise sources",
    );
    expect(
        |v| {
            v["measurement"]["gamma"] = json!([vec![1.0; 300_000]]);
            v["measurement"]["psi"] = json!(vec![0.1; 300_000]);
        },
        &[],
        "measurement.gamma[0]",
        "M (columns of gamma) = 300000: more than the limit of 200 noise sources",
    );
}

/// A measurement whose row of c is 0 measures nothing; with no noise either its
/// innovation variance is 0 at every step. It was found only at step 1 as a singular
/// innovation covariance (exit 1 in the CLI, after compiling and starting the run);
/// now the model is refused at the row. With noise it is legal (noise only, weight 0),
/// and a warning says so.
#[test]
fn a_measurement_of_nothing_is_named_at_its_row() {
    // The seed's form Z = c (y + gΦ): the noise is scaled by c, so it is 0 too.
    expect(
        |v| {
            v["measurement"]["gamma"] = Value::Null;
            v["measurement"]["g"] = json!([["t"], [1]]);
            v["measurement"]["c"] = json!([[0, "0*s"]]);
        },
        &[],
        "measurement.c[0]",
        "measurement \"zx\" measures nothing: its row of c is 0, and so is its noise",
    );
    // gamma: a constant 0 row, or a row whose sources have variance 0.
    let mut v = good();
    v["measurement"]["c"] = json!([[0, 0]]);
    v["measurement"]["gamma"] = json!([[0]]);
    let e = model_from_value(v).map(|m| kea_core::check(&m, &Overrides::new()));
    match e {
        Ok(Err(e)) => common::assert_error_at(&e, "measurement.c[0]", "it has no noise"),
        other => panic!("expected an error at measurement.c[0], got {other:?}"),
    }
    expect(
        |v| {
            v["measurement"]["c"] = json!([[0, 0]]);
            v["measurement"]["psi"] = json!([0]);
        },
        &[],
        "measurement.c[0]",
        "it has no noise",
    );
    // With a noise that varies in t the row is not known to be 0: the run decides.
    let mut v = good();
    v["measurement"]["c"] = json!([[0, 0]]);
    v["measurement"]["gamma"] = json!([["1 + t"]]);
    let m = model_from_value(v).unwrap();
    let r = analyze(&m, &Overrides::new(), &mut NoProgress).unwrap();
    let note = "measurement.c[0]: measurement \"zx\" measures no state (its row of c is 0): it is noise only, and the filter gives it no weight";
    assert!(r.warnings.iter().any(|w| w == note), "{:?}", r.warnings);
    // Its gain is 0: the filtered covariance is the open-loop one.
    assert!(
        r.final_.gain.iter().flatten().all(|&g| g == 0.0),
        "{:?}",
        r.final_.gain
    );
}

/// An a so large that one step multiplies the covariance beyond f64 was reported as
/// "the noise levels or the initial SKOs are too large to square", at `system`. Now
/// the entry is named, with A's entry and Δt, and every overflow names the states whose
/// variance overflowed. An unstable model's overflowing bound
/// was put down to "|A| grows where A does not", which is false for it.
#[test]
fn an_overflow_from_a_names_the_entry_or_the_instability() {
    expect(
        |v| v["system"]["a"][1][0] = json!("-s/m*1e300"),
        &[],
        "system.a[1][0]",
        "the filter's variance of \"v\" overflowed f64 (above 1.8e308): A = I + aΔt has an entry of -3.717e297 here (a = -3.717e299 there, Δt = 0.01)",
    );
    // v' = 50 v, not measured (zx sees x alone, and x does not see v): the filter's
    // variance of v grows by A_vv² = 1.5² a step and leaves f64 at step ≈ 875. The
    // message named the growing mode but not the state it grows in.
    expect(
        |v| v["system"]["a"] = json!([[-1, 0], [0, 50]]),
        &[],
        "system.a",
        "the filter's variance of \"v\" overflowed f64 (above 1.8e308): a mode of A = I + aΔt grows (by 1.5 a step, rate 40.55 per unit of t) and the measurements do not hold it",
    );
    // x' = 50 x, measured: the filter holds it, but the open-loop covariance grows
    // as e^{100 t} and overflows at t ≈ 7.1, and the a-priori bound as e^{50 t}, at
    // t ≈ 14.2.
    let mut v = good();
    v["time"]["t_end"] = json!(20.0);
    v["time"]["steps"] = json!(200_000);
    v["system"]["a"] = json!([[50, 0], [0, -1]]);
    v["system"]["u"] = json!([0, 0]);
    v["system"]["y0"] = json!([0, 1]);
    let m = model_from_value(v).unwrap();
    let r = analyze(&m, &Overrides::new(), &mut NoProgress).unwrap();
    let has = |what: &str| r.warnings.iter().any(|w| w.contains(what));
    assert!(
        has("the open-loop (a-priori) covariance overflowed at step ")
            && has(": the model is unstable on this interval (a mode of A grows)"),
        "{:?}",
        r.warnings
    );
    assert!(
        has("the bound (modulus procedure) overflowed at step ")
            && has(
                "the model is unstable on this interval (a mode of A grows, and the open-loop covariance overflowed too)"
            ),
        "{:?}",
        r.warnings
    );
    assert!(!has("grows where A does not"), "{:?}", r.warnings);
}

/// Numbers too large to square, and time grids f64 cannot step through, are named at
/// their field — not reported as a singular innovation covariance (an infinite one was)
/// nor run with Δt = 0.
#[test]
fn overflows_and_unresolvable_grids() {
    expect(
        |v| v["system"]["eta0"][0] = json!(1e200),
        &[],
        "system.eta0[0]",
        "its square, the variance",
    );
    expect(
        |v| v["measurement"]["psi"] = json!(["psi"]),
        &[("psi", 1e200)],
        "measurement.psi[0]",
        "below 1.34e154",
    );
    expect(
        |v| v["measurement"]["gamma"] = json!([["1e200*(1 + t)"]]),
        &[],
        "measurement.gamma[0][0]",
        "measurement-noise covariance Γ V Γᵀ overflowed f64 (a variance above 1.8e308); its largest term |Γ| ψ is 1.01e199 (measurement \"zx\": Γ = 1.01e200, ψ = 0.1)",
    );
    expect(
        |v| v["system"]["b"] = json!([[0], ["1e300*(1 + t)"]]),
        &[],
        "system.b[1][0]",
        "process-noise covariance B = bΔt W (bΔt)ᵀ overflowed f64 (a variance above 1.8e308); its largest term |bΔt| φ is 5e297 (state \"v\": b = 1e300, Δt = 0.01, φ = 0.5)",
    );
    expect(
        |v| v["time"]["t_end"] = json!(5e-324),
        &[],
        "time.steps",
        "below f64's resolution",
    );
    expect(
        |v| {
            v["time"]["t0"] = json!(1e17);
            v["time"]["t_end"] = json!(1.00000000000001e17);
        },
        &[],
        "time.steps",
        "below f64's resolution",
    );
    expect(
        |v| {
            v["time"]["t0"] = json!(-1e308);
            v["time"]["t_end"] = json!(1e308);
        },
        &[],
        "time.t_end",
        "overflows f64",
    );
}

/// Wrong JSON types are named with what is expected (serde's untagged enums said "data
/// did not match any variant"); a whole number written as a float is a step count.
#[test]
fn wrong_types_say_what_is_expected() {
    for bad in [json!(-5), json!(10.5), json!(true), json!([1000])] {
        expect(
            |v| v["time"]["steps"] = bad.clone(),
            &[],
            "time.steps",
            "expected a positive whole number of steps D, or \"auto\"",
        );
    }
    for bad in [json!(true), json!(null), json!({}), json!([1])] {
        expect(
            |v| v["system"]["a"][1][0] = bad.clone(),
            &[],
            "system.a[1][0]",
            "expected a number or an expression string",
        );
    }
    // serde's own messages in JSON's words, at the member's path.
    for (edit, path, message) in [
        (
            json!({"options": {"trace_points": -1}}),
            "options.trace_points",
            "expected a whole number ≥ 0, got -1",
        ),
        (
            json!({"options": {"steady_state_shortcut": 1}}),
            "options.steady_state_shortcut",
            "expected true or false, got 1",
        ),
        (
            json!({"system": {"y0": "abc"}}),
            "system.y0",
            "expected an array, got a string (\"abc\")",
        ),
        (
            json!({"criteria": {"confidence": [0.9]}}),
            "criteria.confidence",
            "expected a number, got an array",
        ),
    ] {
        let (part, inner) = edit.as_object().unwrap().iter().next().unwrap();
        let (field, value) = inner.as_object().unwrap().iter().next().unwrap();
        expect(|v| v[part][field] = value.clone(), &[], path, message);
    }
    // Every whole-number member reads a whole number written as a float, as steps do.
    let mut v = good();
    v["options"] = json!({"trace_points": 500.0});
    v["kea_model"] = json!(1.0);
    assert_eq!(model_from_value(v).unwrap().options.trace_points, 500);
    let mut v = good();
    v["time"]["steps"] = json!(1e3);
    let m = model_from_value(v).unwrap();
    assert_eq!(
        analyze(&m, &Overrides::new(), &mut NoProgress)
            .unwrap()
            .steps,
        1000
    );
}

/// A struct must be an object: serde's derived structs also read an array of the
/// fields in order, which took `"options": [0, false]` as no traces and no shortcut.
#[test]
fn an_array_is_not_an_object() {
    for (part, array) in [
        ("time", json!([0, 1, 100])),
        ("options", json!([0, false])),
        ("criteria", json!([])),
    ] {
        expect(
            |v| v[part] = array.clone(),
            &[],
            part,
            "expected an object, got an array",
        );
    }
    expect(
        |v| v["time"]["auto"] = json!([1e-3, 100, 800]),
        &[],
        "time.auto",
        "expected an object, got an array",
    );
    expect(
        |v| v["measurement"]["pairs"] = json!([["x", "z"]]),
        &[],
        "measurement.pairs[0]",
        "expected an object, got an array",
    );
    // Enums: a synthesis mode is an object holding one object.
    let mut request = json!({"model": good(), "target": {"criterion": "yx", "threshold": 2},
                             "mode": {"bisect": ["q", 0.01, 100]}});
    let e = kea_core::synthesis::request_from_value(request.clone()).unwrap_err();
    assert_eq!(
        e.field_errors(),
        [kea_core::FieldError::new(
            "mode.bisect",
            "expected an object, got an array"
        )]
    );
    request["mode"] = json!({"bisect": {"param": "q", "low": 0.01, "high": 100}});
    assert!(kea_core::synthesis::request_from_value(request).is_ok());
}

/// A model that is not an object, or lacks its parts, gets one error per part, each at
/// its path (serde read an array as the fields in order, and named one missing field
/// with an empty path).
#[test]
fn missing_parts_are_all_named() {
    let e = model_from_value(json!([1, 2])).unwrap_err().field_errors();
    assert_eq!(e.len(), 1);
    assert!(e[0].message.contains("a model is a JSON object"), "{e:?}");
    assert!(e[0].message.contains("got an array"), "{e:?}");
    let e = model_from_value(json!({"kea_model": 1}))
        .unwrap_err()
        .field_errors();
    let paths: Vec<&str> = e.iter().map(|f| f.path.as_str()).collect();
    assert_eq!(paths, ["time", "system", "measurement"]);
    expect(
        |v| {
            v["system"].as_object_mut().unwrap().remove("states");
        },
        &[],
        "system.states",
        "missing",
    );
}

/// An unknown `--set` name is listed with the model's own errors, not instead of them.
#[test]
fn an_unknown_override_does_not_hide_the_models_errors() {
    let mut v = good();
    v["system"]["a"][1][0] = json!("-s/mass");
    let m = model_from_value(v).unwrap();
    let set: Overrides = [("nope".to_string(), 1.0)].into_iter().collect();
    let e = analyze(&m, &set, &mut NoProgress)
        .unwrap_err()
        .field_errors();
    let paths: Vec<&str> = e.iter().map(|f| f.path.as_str()).collect();
    assert_eq!(paths, ["set.nope", "system.a[1][0]"], "{e:?}");
}

/// The same key twice in one object is refused with the key (serde_json keeps the last
/// one silently); numbers read as serde_json reads them.
#[test]
fn a_key_given_twice_is_refused() {
    let text = r#"{"kea_model": 1, "time": {"t0": 0, "t_end": 1, "steps": 10, "t0": 0.5}}"#;
    let e = kea_core::model_from_json(text).unwrap_err().field_errors();
    assert!(
        e[0].message
            .contains("the key \"t0\" appears twice in one object"),
        "{e:?}"
    );
    let good = good().to_string();
    let strict = kea_core::parse_json(good.as_bytes()).unwrap();
    assert_eq!(strict, serde_json::from_str::<Value>(&good).unwrap());
    let numbers = r#"[0.1, 1e-300, 18446744073709551615, -9223372036854775808, 2.5e300]"#;
    assert_eq!(
        kea_core::parse_json(numbers.as_bytes()).unwrap(),
        serde_json::from_str::<Value>(numbers).unwrap()
    );
}

/// A Γ (or the seed's g) with no columns gets one error, that it needs a column,
/// not a second, contradictory one at the same row ("0 entries, expected 1").
#[test]
fn a_noise_matrix_without_columns_is_one_error() {
    for (member, path) in [("gamma", "measurement.gamma[0]"), ("g", "measurement.g[0]")] {
        let mut v = good();
        let meas = v["measurement"].as_object_mut().unwrap();
        meas.remove("gamma");
        meas.insert(
            member.into(),
            if member == "g" {
                json!([[], []])
            } else {
                json!([[]])
            },
        );
        let err = match model_from_value(v) {
            Err(e) => e,
            Ok(m) => analyze(&m, &Overrides::new(), &mut NoProgress).unwrap_err(),
        };
        let Error::Invalid(errors) = err else {
            panic!("{member}: expected invalid, got {err}");
        };
        let here: Vec<_> = errors.iter().filter(|e| e.path == path).collect();
        assert_eq!(here.len(), 1, "{member}: {errors:?}");
        assert!(
            here[0]
                .message
                .contains("needs at least one column (M ≥ 1)"),
            "{here:?}"
        );
    }
}

/// An `unavailable` interval of three entries was read as its first two, the third
/// ignored (even a string); one of one entry was refused. Now both are refused.
#[test]
fn an_interval_has_exactly_two_ends() {
    for (interval, got) in [
        (json!([0, 0.5, 1]), "got 3"),
        (json!([0.5, 0.7, "x"]), "got 3"),
        (json!([0.5]), "got 1"),
    ] {
        let mut v = good();
        v["measurement"]["schedule"] = json!([{"unavailable": [interval]}]);
        let err = model_from_value(v).unwrap_err();
        let e = &err.field_errors()[0];
        assert_eq!(e.path, "measurement.schedule[0].unavailable[0]", "{e:?}");
        assert!(e.message.contains(got), "{}", e.message);
    }
}

/// A misspelt section (`sytem`) was reported only as `system` missing, and a model
/// wrapped as `{"model": …}` as three sections missing. Now the unknown member is
/// named too, first, with the members a model has.
#[test]
fn a_missing_section_comes_with_the_unknown_member_that_was_meant() {
    let mut v = good();
    let system = v.as_object_mut().unwrap().remove("system").unwrap();
    v["sytem"] = system;
    let err = model_from_value(v).unwrap_err();
    let errors = err.field_errors();
    assert_eq!(errors[0].path, "sytem");
    assert_eq!(
        errors[0].message,
        "unknown member; expected one of: kea_model, name, description, params, time, system, measurement, criteria, options"
    );
    assert_eq!(errors[1].path, "system");
    assert!(
        errors[1].message.starts_with("missing"),
        "{}",
        errors[1].message
    );
    assert_eq!(errors.len(), 2);

    let err = model_from_value(json!({"model": good()})).unwrap_err();
    let errors = err.field_errors();
    assert_eq!(errors[0].path, "model");
    assert!(
        errors[0].message.contains("not inside \"model\""),
        "{}",
        errors[0].message
    );
    assert_eq!(errors.len(), 4, "{errors:?}");

    // The list is the model's: serde names the same members for an unknown one.
    let mut v = good();
    v["colour"] = json!(1);
    let err = model_from_value(v).unwrap_err();
    assert_eq!(err.field_errors()[0].path, "colour");
    assert_eq!(
        err.field_errors()[0].message,
        "unknown member; expected one of: kea_model, name, description, params, time, system, measurement, criteria, options"
    );
}

/// The web editor renames a parameter's uses in expressions, but not to or from a name
/// the language reads as a function or constant (`s/m` renamed `s/e` would mean
/// Euler's number): its list (web/editor.js, `RESERVED`) is the core's, and `t`.
#[test]
fn the_web_editors_reserved_names_are_the_cores() {
    let js =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/web/editor.js")).unwrap();
    let start = js
        .find("const RESERVED = new Set(")
        .expect("RESERVED in editor.js");
    let end = start + js[start..].find(".split(' ')").unwrap();
    let words: String = js[start..end].split('\'').skip(1).step_by(2).collect();
    let mut web: Vec<&str> = words.split(' ').filter(|w| !w.is_empty()).collect();
    let mut core = kea_core::expr::reserved_names();
    core.push("t");
    web.sort_unstable();
    core.sort_unstable();
    core.dedup();
    assert_eq!(web, core);
}

/// A singular innovation covariance was one message for any measurement, at
/// `measurement` ("a measurement has no error … and what it measures is already known
/// exactly"), even where one measurement did it (the web form's new measurement of a
/// state with η₀ = 0 and no noise). Now it names the measurement, at its row of c.
#[test]
fn a_singular_innovation_covariance_names_the_measurement() {
    let model = |measurement: Value| {
        json!({
            "time": {"t0": 0.0, "t_end": 1.0, "steps": 100},
            "system": {
                "states": ["x", "v"], "a": [[0, 1], [0, 0]], "b": [[1], [0]],
                "phi": [0.1], "y0": [0, 1], "eta0": [1, 0]
            },
            "measurement": measurement
        })
    };
    // z2 measures v, whose variance stays 0 (η₀ = 0, no noise reaches it), with no
    // noise of its own.
    expect_error(
        model(json!({
            "names": ["z1", "z2"], "c": [[1, 0], [0, 1]],
            "gamma": [[1, 0], [0, 0]], "psi": [0.1, 0.1]
        })),
        "measurement.c[1]",
        "measurement \"z2\" has no error (its Γ V Γᵀ is 0) and what it measures is known exactly",
    );
    // z2 is z1 again, with the same noise source: it adds nothing.
    expect_error(
        model(json!({
            "names": ["z1", "z2"], "c": [[1, 0], [1, 0]],
            "gamma": [[1], [1]], "psi": [0.1]
        })),
        "measurement.c[1]",
        "measurement \"z2\" adds nothing to \"z1\"",
    );
    // The same where the cancellation is not exact in floating point: z2 = 3·z1 with
    // coefficients 0.1 and 0.3 left a whitened row of 1.4e-17, taken as a noise-free
    // measurement (a gain of 7.2e16, χ 1.4e16, exit 0).
    expect_error(
        model(json!({
            "names": ["z1", "z2"], "c": [[0.1, 0], [0.3, 0]],
            "gamma": [[0.1, 0], [0.3, 0]], "psi": [1, 1]
        })),
        "measurement.c[1]",
        "measurement \"z2\" adds nothing to \"z1\"",
    );
    // z3 = 0.673 z1 − 0.047 z2, noise and all, with noises of unequal size (Rv less
    // well conditioned: the residue was ≈ 1e-15 of the terms).
    expect_error(
        json!({
            "time": {"t0": 0.0, "t_end": 1.0, "steps": 2},
            "system": {
                "states": ["x1", "x2", "x3"], "a": [[0, 0, 0], [0, 0, 0], [0, 0, 0]],
                "b": [[1], [0], [0]], "phi": [1], "y0": [1, 1, 1], "eta0": [1, 1, 1]
            },
            "measurement": {
                "names": ["z1", "z2", "z3"],
                "c": [[-0.481, -0.531, 0], [0.991, -0.059, 0], [-0.37029, -0.35459, 0]],
                "gamma": [[1, 0], [0, 1], [0.673, -0.047]], "psi": [0.36, 0.004]
            }
        }),
        "measurement.c[2]",
        "adds nothing to",
    );
}

/// Run `v` and expect an error at `path` containing `fragment`.
fn expect_error(v: Value, path: &str, fragment: &str) {
    let m = model_from_value(v).unwrap();
    let err = analyze(&m, &Overrides::new(), &mut NoProgress).unwrap_err();
    let e = &err.field_errors()[0];
    assert_eq!(e.path, path, "{e:?}");
    assert!(e.message.contains(fragment), "{}", e.message);
}

/// A state or measurement name with a line break (or NUL) was accepted, and split the
/// command line's table row in two.
#[test]
fn names_have_no_control_characters() {
    expect(
        |v| v["system"]["states"] = json!(["x", "a\nb"]),
        &[],
        "system.states[1]",
        "must not contain control characters (a line break, a tab, NUL), got \"a\\nb\"",
    );
    expect(
        |v| v["measurement"]["names"] = json!(["z\u{0}"]),
        &[],
        "measurement.names[0]",
        "control characters",
    );
}

/// Names that only look alike were distinct states: "x" and "x ", or a name with a
/// zero-width space (which shows as nothing, in the table and the CSV header).
#[test]
fn names_that_look_like_others_are_refused() {
    expect(
        |v| v["system"]["states"] = json!(["x", "x "]),
        &[],
        "system.states[1]",
        "a name must not begin or end with a space, got \"x \"",
    );
    expect(
        |v| v["system"]["states"] = json!(["x", "\u{200B}"]),
        &[],
        "system.states[1]",
        "a name must not be empty",
    );
    expect(
        |v| v["measurement"]["names"] = json!(["z\u{200B}"]),
        &[],
        "measurement.names[0]",
        "a name must not contain an invisible character (U+200B)",
    );
}

/// `every` named no range for a wrong type ("a whole number ≥ 0") and another for 0
/// ("must be at least 1"): now one range, from 1, in both.
#[test]
fn a_schedules_every_names_its_range() {
    for (every, got) in [
        (json!("2"), "got a string (\"2\")"),
        (json!(2.5), "got 2.5"),
    ] {
        expect(
            |v| v["measurement"]["schedule"] = json!([{ "every": every }]),
            &[],
            "measurement.schedule[0].every",
            &format!("expected a whole number from 1, {got}"),
        );
    }
    expect(
        |v| v["measurement"]["schedule"] = json!([{"every": 0}]),
        &[],
        "measurement.schedule[0].every",
        "expected a whole number of steps from 1, got 0",
    );
}
