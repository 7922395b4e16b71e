//! The nonlinear procedure (METHOD §4): K = 6 filters of the seed-002 preset over D
//! steps (default 10⁶) of the reference scenario a's 2000 measurements repeated, on one
//! core — the run alone (the data already read), and per filter-step. Also the plain
//! EKF alone (K = 1), for the per-filter-step figure against filterpy
//! (`benches/nonlinear_peer.py`).
//!
//! `cargo bench -p kea-core --bench nonlinear` (`KEA_BENCH_STEPS` changes D), median
//! of 5 after a warm-up.

use kea_core::NoProgress;
use kea_core::exec::{Forgetful, Sequential};
use kea_core::registry::{self, Prepared};
use serde_json::json;
use std::time::Instant;

fn main() {
    let d: usize = std::env::var("KEA_BENCH_STEPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1_000_000);
    let csv = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/nonlinear/a_model_right.data.csv"
    );
    let mut reader = csv::Reader::from_path(csv).expect("scenario a's data");
    let y: Vec<f64> = reader
        .records()
        .filter_map(|r| r.expect("row")[4].parse().ok())
        .collect();
    // The record repeated with its trend: each repetition shifted by where the last
    // ended, so that the filters keep tracking (x1 stays far from 0).
    let span = y[y.len() - 1] - y[0];
    let rows: Vec<serde_json::Value> = (1..=d)
        .map(|n| {
            let (rep, k) = ((n - 1) / y.len(), (n - 1) % y.len());
            json!([n as f64 * 0.01, y[k] + rep as f64 * span])
        })
        .collect();
    let preset: serde_json::Value =
        serde_json::from_str(kea_core::nonlinear::request::preset("seed-002").unwrap()).unwrap();
    for (k, alpha) in [(6, json!([1, 0.8, 0.6, 0.5, 0.4, 0.3])), (1, json!([1]))] {
        let mut model = preset.clone();
        model["time"] = json!({"t0": 0, "t_end": d as f64 * 0.01, "steps": d});
        let request = json!({"model": model, "data": {"rows": rows},
                             "procedure": {"alpha": alpha}, "q_scale": [],
                             "trace_points": 1000});
        let prepared = registry::prepare_checked("nonlinear", request).expect("valid");
        let Prepared::Nonlinear(_) = &prepared else {
            unreachable!()
        };
        let mut times = Vec::new();
        for round in 0..6 {
            let start = Instant::now();
            let out = prepared
                .run(&Sequential, &mut NoProgress, &Forgetful)
                .expect("runs");
            let s = start.elapsed().as_secs_f64();
            std::hint::black_box(out.to_json().len());
            if round > 0 {
                times.push(s);
            }
        }
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        println!(
            "nonlinear K = {k}, D = {d}: {:.3} s ({:.0} ns per filter-step, median of {})",
            median,
            median / (k * d) as f64 * 1e9,
            times.len()
        );
    }
}
