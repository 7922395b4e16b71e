//! The nonlinear procedure against the independent references in
//! `tests/data/nonlinear/` (README there): from each scenario's spec and CSV, the
//! EKF and every iterate — states and P at the checkpoints, RMS, δ on the predictions
//! and the posteriors, i*, the γ table, the α variants and the Q-scale grid — to 1e-9
//! relative; the indices exactly.

use kea_core::exec::{Forgetful, Sequential};
use kea_core::nonlinear::NonlinearResult;
use kea_core::nonlinear::result::Summary;
use kea_core::registry::{self, Outcome};
use kea_core::{Error, NoProgress};
use serde_json::{Value, json};

const TOLERANCE: f64 = 1e-9;

fn data_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/nonlinear")
}

fn json_file(name: &str) -> Value {
    let text = std::fs::read_to_string(data_dir().join(name)).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn run(request: Value) -> Result<NonlinearResult, Error> {
    let prepared = registry::prepare_checked("nonlinear", request)?;
    match prepared.run(&Sequential, &mut NoProgress, &Forgetful)? {
        Outcome::Nonlinear(r) => Ok(r),
        _ => unreachable!("a nonlinear request gives a nonlinear outcome"),
    }
}

/// The filter's model of a scenario's spec, in kea's format (the seed-002 preset
/// with the spec's numbers).
fn model(spec: &Value) -> Value {
    let f = |v: &Value| v.as_f64().unwrap();
    let dt = f(&spec["discretisation"]["dt"]);
    let steps = spec["discretisation"]["n_steps"].as_u64().unwrap();
    json!({
        "kea_nonlinear": 1,
        "params": {"b": spec["filter_model"]["b"], "sigma": spec["measurement"]["sigma"]},
        "time": {"t0": 0, "t_end": dt * steps as f64, "steps": steps},
        "system": {
            "states": ["x1", "x2"],
            "f": ["x2", "-b*abs(x2)*x2/abs(x1)"],
            "y0": spec["init"]["x0"],
            "P0": spec["init"]["P0"],
            "W": spec["procedure"]["Q_eta"],
        },
        "measurement": {"names": ["y"], "h": ["x1"], "psi": ["sigma"]},
        "procedure": {"alpha": spec["procedure"]["alpha"]},
    })
}

fn close(got: f64, want: f64, what: &str) {
    let scale = want.abs().max(1e-300);
    assert!(
        (got - want).abs() <= TOLERANCE * scale,
        "{what}: {got} against {want} (relative {:e})",
        (got - want).abs() / scale
    );
}

fn close_all(got: &[f64], want: &Value, what: &str) {
    let want: Vec<f64> = want
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert_eq!(got.len(), want.len(), "{what}");
    for (i, (g, w)) in got.iter().zip(&want).enumerate() {
        close(*g, *w, &format!("{what}[{i}]"));
    }
}

/// An EKF's or iterate's summary against the reference's.
fn summary(got: &Summary, want: &Value, what: &str) {
    let rms = got.rms.as_ref().unwrap();
    close(
        rms[0].unwrap(),
        want["rms_pos"].as_f64().unwrap(),
        &format!("{what} rms_pos"),
    );
    close(
        rms[1].unwrap(),
        want["rms_vel"].as_f64().unwrap(),
        &format!("{what} rms_vel"),
    );
    if let Some(p) = want.get("rms_pos_prior") {
        let prior = got.rms_prior.as_ref().unwrap();
        close(
            prior[0].unwrap(),
            p.as_f64().unwrap(),
            &format!("{what} rms_pos_prior"),
        );
    }
    close(
        got.delta,
        want["delta_prior"].as_f64().unwrap(),
        &format!("{what} delta"),
    );
    if let Some(p) = want.get("delta_post") {
        close(
            got.delta_posterior,
            p.as_f64().unwrap(),
            &format!("{what} delta_post"),
        );
    }
}

fn scenario(name: &str) {
    let spec = json_file(&format!("{name}.spec.json"));
    let expected = json_file(&format!("{name}.expected.json"));
    let out = &expected["outputs"];
    let csv = std::fs::read_to_string(data_dir().join(format!("{name}.data.csv"))).unwrap();
    let checkpoints: Vec<u64> = out["checkpoints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["n"].as_u64().unwrap())
        .collect();
    let scales: Vec<f64> = out["ekf_q_grid"]["grid"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["scale"].as_f64().unwrap())
        .collect();
    let request = json!({
        "model": model(&spec),
        "data": {"csv_text": csv},
        "q_scale": scales,
        "checkpoints": checkpoints,
        "trace_points": 100,
    });
    let r = run(request.clone()).unwrap();
    assert_eq!(r.ignored_columns, vec!["n"]);
    assert_eq!(r.measured, vec![2000]);

    // The weights.
    let p = &out["procedure"];
    for (k, row) in r.gamma.iter().enumerate() {
        close_all(
            row,
            &json!(p["gamma"][k].as_array().unwrap()[..=k]),
            &format!("gamma[{k}]"),
        );
        close_all(
            &r.weights[k],
            &json!(p["innovation_weights"][k].as_array().unwrap()[..=k]),
            &format!("weights[{k}]"),
        );
        close(
            r.r[k][0],
            p["R_eff"][k].as_f64().unwrap(),
            &format!("R[{k}]"),
        );
    }
    // The EKF, the iterates, the choice.
    summary(&r.ekf, &out["ekf"], "ekf");
    for (i, it) in r.iterates.iter().enumerate() {
        summary(it, &p["iterates"][i], &format!("iterate {}", i + 1));
    }
    assert_eq!(r.i_star as u64, p["i_star"].as_u64().unwrap());
    assert_eq!(
        r.i_star_posterior as u64,
        p["i_star_delta_post"].as_u64().unwrap()
    );
    assert_eq!(
        r.i_stop_first_increase as u64,
        p["i_stop_first_increase"].as_u64().unwrap()
    );
    let best = r.best_rms.as_ref().unwrap();
    assert_eq!(
        best[0].unwrap() as u64,
        p["oracle_best_i_pos"].as_u64().unwrap()
    );
    assert_eq!(
        best[1].unwrap() as u64,
        p["oracle_best_i_vel"].as_u64().unwrap()
    );
    // The checkpoints.
    for (c, want) in r
        .checkpoints
        .iter()
        .zip(out["checkpoints"].as_array().unwrap())
    {
        assert_eq!(c.n as u64, want["n"].as_u64().unwrap());
        let snapshot = |s: &kea_core::nonlinear::result::Snapshot, w: &Value, what: String| {
            close_all(&s.prior, &w["prior"], &format!("{what} prior"));
            close_all(&s.posterior, &w["post"], &format!("{what} post"));
            for (i, row) in s.p_posterior.iter().enumerate() {
                close_all(row, &w["P_post"][i], &format!("{what} P_post[{i}]"));
            }
        };
        snapshot(&c.ekf, &want["ekf"], format!("n = {} ekf", c.n));
        for (s, w) in c.iterates.iter().zip(want["iterates"].as_array().unwrap()) {
            snapshot(s, w, format!("n = {} iterate {}", c.n, s.i.unwrap()));
        }
    }
    // The Q-scale grid.
    let q = &out["ekf_q_grid"];
    for (got, want) in r.q_scale.grid.iter().zip(q["grid"].as_array().unwrap()) {
        summary(&got.summary, want, &format!("Q × {}", got.scale));
    }
    let chosen = &r.q_scale.grid[r.q_scale.chosen.unwrap()];
    close(
        chosen.scale,
        q["delta_tuned"]["scale"].as_f64().unwrap(),
        "delta-tuned scale",
    );
    let best = r.q_scale.best_rms.as_ref().unwrap();
    close(
        r.q_scale.grid[best[0].unwrap()].scale,
        q["oracle_pos"]["scale"].as_f64().unwrap(),
        "oracle_pos scale",
    );
    close(
        r.q_scale.grid[best[1].unwrap()].scale,
        q["oracle_vel"]["scale"].as_f64().unwrap(),
        "oracle_vel scale",
    );

    // The variants: other α schedules, the prior residuals.
    for v in out["variants"].as_array().unwrap() {
        let mut req = request.clone();
        req["procedure"] = v["procedure_overrides"].clone();
        req["q_scale"] = json!([]);
        let rv = run(req).unwrap();
        let what = v["procedure_overrides"].to_string();
        for (k, row) in rv.gamma.iter().enumerate() {
            close_all(
                row,
                &json!(v["gamma"][k].as_array().unwrap()[..=k]),
                &format!("{what} gamma[{k}]"),
            );
        }
        assert_eq!(rv.i_star as u64, v["i_star"].as_u64().unwrap(), "{what}");
        for (i, it) in rv.iterates.iter().enumerate() {
            summary(it, &v["iterates"][i], &format!("{what} iterate {}", i + 1));
        }
        assert!(rv.q_scale.grid.is_empty() && rv.q_scale.chosen.is_none());
    }
}

#[test]
fn scenario_a_model_right_equals_the_reference() {
    scenario("a_model_right");
}

#[test]
fn scenario_b_wrong_model_manoeuvre_equals_the_reference() {
    scenario("b_wrong_model_manoeuvre");
}

/// The seed-002 preset as a model object, to edit.
fn preset() -> Value {
    let text = kea_core::nonlinear::request::preset("seed-002").unwrap();
    serde_json::from_str(text).unwrap()
}

/// F = ∂f/∂x and H = ∂h/∂x from the expressions equal central differences on random
/// points (the dual numbers against a second way).
#[test]
fn jacobians_equal_central_differences() {
    use kea_core::expr::{StateFn, Value as Entry};
    let states = vec!["x1".to_string(), "x2".to_string(), "x3".to_string()];
    let params = std::collections::BTreeMap::from([("b".to_string(), 0.7)]);
    let texts = [
        "-b*abs(x2)*x2/abs(x1)",
        "sin(x1)*exp(-x2/10) + x1^3 - x3",
        "atan2(x2, x1) + cos(t*x3)",
        "sqrt(x1^2 + x2^2 + x3^2)",
        "log(x1)*x2 + tanh(x1*x3)",
        "x1/(1 + x2^2) - b*x3^2",
        "min(x1, x2) + max(x2, x3)^2",
    ];
    // A fixed linear congruential stream: points in [0.5, 3] (log and the drag law's
    // domain), the same on every run.
    let mut seed: u64 = 20261203;
    let mut uniform = || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        0.5 + 2.5 * ((seed >> 11) as f64 / (1u64 << 53) as f64)
    };
    for text in texts {
        let mut f = StateFn::compile(&Entry::Expr(text.into()), &states, &params, "f").unwrap();
        for _ in 0..50 {
            let x = [uniform(), uniform(), uniform()];
            let t = uniform();
            let mut grad = [0.0; 3];
            let v = f.eval_with_gradient(&x, t, &mut grad);
            assert_eq!(v.to_bits(), f.value(&x, t).to_bits(), "{text}");
            for j in 0..3 {
                let h = 1e-6 * x[j].abs().max(1.0);
                let (mut up, mut down) = (x, x);
                up[j] += h;
                down[j] -= h;
                let numeric = (f.value(&up, t) - f.value(&down, t)) / (2.0 * h);
                let scale = grad[j].abs().max(1.0);
                assert!(
                    (grad[j] - numeric).abs() <= 1e-6 * scale,
                    "∂({text})/∂x{} at {x:?}: {} against {numeric}",
                    j + 1,
                    grad[j]
                );
            }
        }
    }
}

/// A state leaving f's domain stops the run with the step, the time, the filter, the
/// expression and the state — never a NaN in a result.
#[test]
fn a_state_leaving_the_domain_is_a_clear_error() {
    let mut model = preset();
    model["system"]["y0"] = json!([0, 45]);
    let rows: Vec<Value> = (1..=2000).map(|n| json!([n as f64 * 0.01, 1.0])).collect();
    let e = run(json!({"model": model, "data": {"rows": rows}})).unwrap_err();
    let Error::Numerical {
        step,
        t,
        path,
        message,
    } = &e
    else {
        panic!("{e:?}")
    };
    assert_eq!((*step, *t), (0, 0.0));
    assert_eq!(path, "model.system.f[1]");
    assert!(
        message.contains("iterate 1")
            && message.contains("\"-b*abs(x2)*x2/abs(x1)\"")
            && message.contains("x1 = 0, x2 = 45")
            && message.contains("left the expression's domain"),
        "{message}"
    );
}

/// The truth, simulated: the same seed gives the same bits; without noise a constant
/// velocity is integrated exactly and an input is an acceleration; with noise the
/// increments and the measurement errors have the variances asked for.
#[test]
fn the_truth_is_simulated_as_specified() {
    let prepare = |truth: Value, steps: u64| {
        let mut model = preset();
        model["time"] = json!({"t0": 0, "t_end": steps as f64 * 0.01, "steps": steps});
        let request = json!({"model": model, "data": {"truth": truth}});
        match registry::prepare_checked("nonlinear", request).unwrap() {
            registry::Prepared::Nonlinear(r) => r,
            _ => unreachable!(),
        }
    };
    let data = |truth: Value, steps: u64| {
        let r = prepare(truth, steps);
        let csv = kea_core::nonlinear::data_csv(&r).unwrap();
        let mut rows = csv.lines();
        assert_eq!(rows.next(), Some("t,y,x1_true,x2_true"));
        rows.map(|l| {
            l.split(',')
                .map(|c| c.parse::<f64>().unwrap_or(f64::NAN))
                .collect::<Vec<f64>>()
        })
        .collect::<Vec<_>>()
    };
    // Reproducible.
    let noisy = json!({"seed": 7, "y0": [1000, 50], "phi": [0, 1]});
    let a = data(noisy.clone(), 300);
    let b = data(noisy, 300);
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
    let c = data(json!({"seed": 8, "y0": [1000, 50], "phi": [0, 1]}), 300);
    assert_ne!(format!("{a:?}"), format!("{c:?}"));

    // No process noise, constant velocity; then a constant input of 2 m/s².
    let still = data(
        json!({"seed": 1, "y0": [1000, 50], "phi": [0, 0], "f": ["x2", "0"]}),
        500,
    );
    for row in &still {
        let t = row[0];
        assert!((row[2] - (1000.0 + 50.0 * t)).abs() < 1e-9, "{row:?}");
        assert_eq!(row[3], 50.0);
    }
    let pushed = data(
        json!({"seed": 1, "y0": [1000, 50], "phi": [0, 0], "f": ["x2", "0"], "input": ["0", "2"]}),
        500,
    );
    for row in &pushed {
        assert!((row[3] - (50.0 + 2.0 * row[0])).abs() < 1e-9, "{row:?}");
    }

    // Random walk of intensity q = 4 in x1 (f = 0): increments N(0, q Δt); the
    // measurement errors N(0, σ² = 4). 4σ bands of the sample variances, D = 20000.
    let d = 20000;
    let walk = data(
        json!({"seed": 3, "y0": [1000, 0], "phi": [2, 0], "f": ["0", "0"]}),
        d,
    );
    let increments: Vec<f64> = walk.windows(2).map(|w| w[1][2] - w[0][2]).collect();
    let errors: Vec<f64> = walk[1..].iter().map(|r| r[1] - r[2]).collect();
    let var = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64;
    let band = 4.0 * (2.0 / d as f64).sqrt();
    let q_dt = 4.0 * 0.01;
    assert!(
        (var(&increments) / q_dt - 1.0).abs() < band,
        "{}",
        var(&increments) / q_dt
    );
    assert!(
        (var(&errors) / 4.0 - 1.0).abs() < band,
        "{}",
        var(&errors) / 4.0
    );
}

/// Bad requests: every problem at its path, saying what was expected.
#[test]
fn bad_requests_name_the_field() {
    let rows = json!([[0.01, 1000.0]]);
    let cases = [
        (
            json!({"model": "preset:seed-003", "data": {"rows": rows}}),
            "model",
            "no nonlinear preset",
        ),
        (
            json!({"model": "preset:seed-002", "data": {"rows": rows}, "procedure": {"alpha": [1, 1.2]}}),
            "procedure.alpha[1]",
            "0 < α_j < 1",
        ),
        (
            json!({"model": "preset:seed-002", "data": {"rows": rows}, "checkpoints": [0]}),
            "checkpoints[0]",
            "from 1 to D = 2000",
        ),
        (
            json!({"model": "preset:seed-002", "data": {"csv": "d.csv"}}),
            "data.csv",
            "read by the command line",
        ),
        (
            json!({"model": "preset:seed-002", "data": {}}),
            "data",
            "exactly one of",
        ),
        (
            json!({"model": "preset:seed-002", "data": {"truth": {"sed": 1}}}),
            "data.truth.sed",
            "unknown member",
        ),
        (
            json!({"model": "preset:seed-002", "data": {"truth": {"seed": 1, "f": ["x2", "x3"]}}}),
            "data.truth.f[1]",
            "unknown parameter \"x3\"",
        ),
        (
            json!({"model": "preset:seed-002", "data": {"rows": [[0.015, 1.0]]}}),
            "data.rows[0][0]",
            "not on the model's grid",
        ),
        (
            json!({"model": "preset:seed-002", "data": {"rows": rows}, "q_scale": [0]}),
            "q_scale[0]",
            "scale > 0",
        ),
        (
            json!({"model": "preset:seed-002", "data": {"rows": rows}, "set": {"c": 1}}),
            "set.c",
            "c",
        ),
        (
            json!({"model": "preset:seed-002", "data": {"rows": rows}, "runs": 3}),
            "runs",
            "unknown member",
        ),
    ];
    for (request, path, words) in cases {
        let e = run(request.clone()).unwrap_err().field_errors();
        assert!(
            e.iter()
                .any(|e| e.path == path && e.message.contains(words)),
            "{request}: {e:?}"
        );
    }
    let mut model = preset();
    model["system"]["states"] = json!(["x1", "b"]);
    model["measurement"]["h"] = json!(["x1", "b"]);
    model["measurement"]["psi"] = json!([0]);
    let e = run(json!({"model": model, "data": {"rows": rows}}))
        .unwrap_err()
        .field_errors();
    let paths: Vec<&str> = e.iter().map(|e| e.path.as_str()).collect();
    assert!(paths.contains(&"model.system.states[1]"), "{e:?}");
    let e = {
        let mut model = preset();
        model["measurement"]["h"] = json!(["x1", "x2"]);
        model["measurement"]["psi"] = json!([0]);
        run(json!({"model": model, "data": {"rows": rows}}))
            .unwrap_err()
            .field_errors()
    };
    assert!(e.iter().any(|e| e.path == "model.measurement.h"), "{e:?}");
}

/// Missing measurements are left out of their step's update: a record with every other
/// measurement missing gives the filter of the thinned data, and δ counts only what
/// was measured.
#[test]
fn missing_measurements_are_skipped() {
    let csv = std::fs::read_to_string(data_dir().join("a_model_right.data.csv")).unwrap();
    let thinned: String = csv
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i >= 2 && i % 2 == 0 {
                // (Row n = i − 1 odd kept; even steps lose y, the last column.)
                let cut = l.rfind(',').unwrap();
                format!("{},\n", &l[..cut])
            } else {
                format!("{l}\n")
            }
        })
        .collect();
    let r = run(json!({"model": "preset:seed-002", "data": {"csv_text": thinned}, "q_scale": []}))
        .unwrap();
    assert_eq!(r.measured, vec![1000]);
    assert!(
        r.iterates
            .iter()
            .all(|s| s.delta.is_finite() && s.rms.is_some())
    );
    // The same data with the missing rows left out entirely: the same filters, bit for
    // bit (the RMS differ: the truth is then known at half the steps).
    let dropped: String = thinned
        .lines()
        .filter(|l| !l.ends_with(','))
        .map(|l| format!("{l}\n"))
        .collect();
    let s = run(json!({"model": "preset:seed-002", "data": {"csv_text": dropped}, "q_scale": []}))
        .unwrap();
    for (a, b) in r.iterates.iter().zip(&s.iterates) {
        assert_eq!(a.delta.to_bits(), b.delta.to_bits());
        assert_eq!(a.delta_posterior.to_bits(), b.delta_posterior.to_bits());
    }
    assert_eq!(r.traces.iterates.len(), s.traces.iterates.len());
}
