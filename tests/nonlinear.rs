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
