//! The identification's SRIF (METHOD §3): J alone, J with its gradient over three
//! parameters, and both with the sample information, and the expected information's
//! pass (`identification::expected`), on the damped oscillator of
//! `tests/data/identification/case_b` (N = 2, one measurement), its 1000 measurements
//! repeated to D steps.
//!
//! `cargo bench -p kea-core --bench identification` (D = 10⁵; `KEA_BENCH_STEPS`
//! changes it), median of 5 after a warm-up.

use kea_core::identification::{
    Data, Discrete, Partial, Prior, PriorAt, expected_information, likelihood,
    likelihood_and_gradient, likelihood_gradient_information,
};
use std::time::Instant;

fn main() {
    let d: usize = std::env::var("KEA_BENCH_STEPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(100_000);
    let csv = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/identification/case_b.csv"
    );
    let mut reader = csv::Reader::from_path(csv).expect("case b data");
    let z1: Vec<f64> = reader
        .records()
        .map(|r| r.expect("row")[1].parse().expect("number"))
        .collect();
    let z: Vec<f64> = (0..d).map(|k| z1[k % z1.len()]).collect();
    let data = Data {
        m: 1,
        t: (1..=d).map(|k| k as f64).collect(),
        z,
    };
    let (r, w, sv, sw) = (0.95f64, 0.3f64, 0.5f64, 0.3f64);
    let (c, s) = (w.cos(), w.sin());
    let model = Discrete {
        n: 2,
        l: 2,
        m: 1,
        phi: vec![r * c, r * s, -r * s, r * c],
        u: vec![0.0; 2],
        g: vec![1.0, 0.0, 0.0, 1.0],
        q: vec![sw * sw, 0.0, 0.0, sw * sw],
        h: vec![1.0, 0.0],
        r: vec![sv * sv],
    };
    let prior = Prior {
        x0: vec![0.0; 2],
        p0: vec![1.0, 0.0, 0.0, 1.0],
        at: PriorAt::FirstMeasurement,
    };
    let zero = Partial::zero(&model);
    let partials = [
        Partial {
            phi: vec![c, s, -s, c],
            ..zero.clone()
        },
        Partial {
            phi: vec![-r * s, r * c, -r * c, -r * s],
            ..zero.clone()
        },
        Partial {
            r: vec![2.0 * sv],
            ..zero.clone()
        },
    ];
    let median = |f: &dyn Fn()| {
        f();
        let mut v: Vec<f64> = (0..5)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect();
        v.sort_by(f64::total_cmp);
        v[2]
    };
    let j = median(&|| {
        std::hint::black_box(likelihood(&model, &prior, &data).expect("runs"));
    });
    let g = median(&|| {
        std::hint::black_box(
            likelihood_and_gradient(&model, &partials, &prior, &data).expect("runs"),
        );
    });
    let gi = median(&|| {
        std::hint::black_box(
            likelihood_gradient_information(&model, &partials, &prior, &data).expect("runs"),
        );
    });
    let ei = median(&|| {
        std::hint::black_box(expected_information(&model, &partials, &prior, &data).expect("runs"));
    });
    println!(
        "identification J, N = 2, D = {d}:              median {j:.4} s ({:.0} ns/step)",
        j / d as f64 * 1e9
    );
    println!(
        "identification J + gradient (3 params), D = {d}: median {g:.4} s ({:.0} ns/step)",
        g / d as f64 * 1e9
    );
    println!(
        "identification J + gradient + information, D = {d}: median {gi:.4} s ({:.0} ns/step)",
        gi / d as f64 * 1e9
    );
    println!(
        "identification expected information (3 params), D = {d}: median {ei:.4} s ({:.0} ns/step)",
        ei / d as f64 * 1e9
    );
}
