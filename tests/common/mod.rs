//! Helpers shared by the core's integration tests. (Each test binary compiles this
//! module and uses part of it.)
#![allow(dead_code)]

use kea_core::Error;

/// `e` has an error at `path` whose message contains `fragment` (panics listing the
/// errors otherwise).
pub fn assert_error_at(e: &Error, path: &str, fragment: &str) {
    let errors = e.field_errors();
    assert!(
        errors
            .iter()
            .any(|e| e.path == path && e.message.contains(fragment)),
        "expected an error at `{path}` containing \"{fragment}\", got {errors:#?}"
    );
}

/// The `a` of an N-state chain: `diagonal(i)` in row i's diagonal, `above` just right
/// of it, 0 elsewhere.
pub fn chain_a(
    n: usize,
    diagonal: impl Fn(usize) -> serde_json::Value,
    above: serde_json::Value,
) -> Vec<Vec<serde_json::Value>> {
    (0..n)
        .map(|i| {
            (0..n)
                .map(|j| match j {
                    _ if j == i => diagonal(i),
                    _ if j == i + 1 => above.clone(),
                    _ => serde_json::json!(0.0),
                })
                .collect()
        })
        .collect()
}

/// A preset's model as JSON, to modify before parsing.
pub fn preset_value(name: &str) -> serde_json::Value {
    serde_json::from_str(kea_core::presets::get_json(name).expect("a preset"))
        .expect("presets parse")
}

/// A JSON array of arrays of numbers (a reference's matrix).
pub fn matrix(v: &serde_json::Value) -> Vec<Vec<f64>> {
    let row = |r: &serde_json::Value| -> Vec<f64> {
        r.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    v.as_array().unwrap().iter().map(row).collect()
}

/// An analysis request (`{model, set?, budget?, truth?}`) through the registry, as every shell runs it.
pub fn run_analysis(request: serde_json::Value) -> kea_core::AnalysisResult {
    use kea_core::exec::{Forgetful, Sequential};
    let prepared = kea_core::registry::prepare("analysis", request).expect("a valid request");
    match prepared.run(&Sequential, &mut kea_core::NoProgress, &Forgetful) {
        Ok(kea_core::registry::Outcome::Analysis(r)) => r,
        Ok(_) => panic!("an analysis"),
        Err(e) => panic!("the analysis runs: {e:?}"),
    }
}
