//! The engine's performance workloads (BENCHMARKS.md): the seed's Table 1 (D = 10⁶,
//! P states, n = P measurements, time-varying a(t)), N = 30, the steady-state
//! shortcut, the Python peer's model (the whole analysis, and the filter's covariance
//! recursion alone), the error budget's cost per source, and the cost of expression
//! evaluation.
//!
//!     cargo bench -p kea-core --bench engine            # everything (~2 min)
//!     cargo bench -p kea-core --bench engine -- table1  # a filter on the names
//!
//! Each workload is timed `runs` times after one warm-up; the median is printed,
//! with the per-step figure. One core: the engine is single-threaded.
//!
//! `KEA_BENCH_STEPS=20000 KEA_BENCH_RUNS=1` shrink every workload, for counting
//! instructions under `valgrind --tool=callgrind` (load-independent figures).

use kea_core::{Model, NoProgress, analyze, covariance_recursion, model_from_value};
use serde_json::json;
use std::time::Instant;

/// A P-state chain: a_ii = −0.5 − 0.1 i (+ 0.2 sin(t) when time-varying), a_i,i+1 = 1,
/// b = I, every state measured (C = I), Γ = I.
fn chain(p: usize, steps: u64, varying: usize, shortcut: bool) -> Model {
    chain_measured(p, p, steps, varying, shortcut)
}

/// The chain with only the first `nm` states measured.
fn chain_measured(p: usize, nm: usize, steps: u64, varying: usize, shortcut: bool) -> Model {
    let a: Vec<Vec<serde_json::Value>> = (0..p)
        .map(|i| {
            (0..p)
                .map(|j| {
                    if i == j {
                        let base = -0.5 - 0.1 * i as f64;
                        if i < varying {
                            json!(format!("{base} + 0.2*sin(t + {i})"))
                        } else {
                            json!(base)
                        }
                    } else if j == i + 1 {
                        json!(1.0)
                    } else {
                        json!(0.0)
                    }
                })
                .collect()
        })
        .collect();
    let eye = |k: usize| -> Vec<Vec<f64>> {
        (0..k)
            .map(|i| (0..k).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
            .collect()
    };
    model_from_value(json!({
        "time": {"t0": 0.0, "t_end": 10.0, "steps": steps},
        "system": {
            "states": (0..p).map(|i| format!("x{i}")).collect::<Vec<_>>(),
            "a": a, "b": eye(p), "phi": vec![0.3; p],
            "y0": vec![1.0; p], "eta0": vec![0.1; p]
        },
        "measurement": {
            "names": (0..nm).map(|i| format!("z{i}")).collect::<Vec<_>>(),
            "c": eye(p)[..nm].to_vec(), "gamma": eye(nm), "psi": vec![1e-3; nm]
        },
        "options": {"steady_state_shortcut": shortcut}
    }))
    .expect("bench model is valid")
}

/// The analysis of `model`, timed.
fn time(name: &str, model: &Model, runs: usize) -> f64 {
    time_with(name, model, runs, || {
        let r = analyze(model, &Default::default(), &mut NoProgress).expect("bench runs");
        std::hint::black_box(&r);
    })
}

/// `run` (one pass over `model`'s steps), timed.
fn time_with(name: &str, model: &Model, runs: usize, run: impl Fn()) -> f64 {
    let steps = match model.time.steps {
        kea_core::model::Steps::Fixed(d) => d,
        _ => unreachable!(),
    };
    let once = || {
        let t = Instant::now();
        run();
        t.elapsed().as_secs_f64()
    };
    once();
    let mut v: Vec<f64> = (0..runs).map(|_| once()).collect();
    v.sort_by(f64::total_cmp);
    let med = v[v.len() / 2];
    println!(
        "{name:<40} median {:>9.3} s  ({:>7.1} ns/step; min {:.3} max {:.3}, {} runs)",
        med,
        med / steps as f64 * 1e9,
        v[0],
        v[v.len() - 1],
        runs
    );
    med
}

fn main() {
    let filter: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let want = |name: &str| filter.is_empty() || filter.iter().any(|f| name.contains(f.as_str()));
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<u64>().ok());
    // The builds compared as with `kea` (KEA_NO_SIMD, KEA_NO_AVX512; kea_core::cpu).
    let set = |k: &str| std::env::var_os(k).is_some();
    kea_core::cpu::set_limit(kea_core::cpu::Limit::from_switches(
        set("KEA_NO_SIMD"),
        set("KEA_NO_AVX512"),
    ));
    let d = env("KEA_BENCH_STEPS").unwrap_or(1_000_000);
    let runs = |r: usize| env("KEA_BENCH_RUNS").map_or(r, |v| v as usize);
    for p in [4, 6, 8, 9, 10] {
        let name = format!("table1 P={p} time-varying a(t)");
        if want(&name) {
            time(&name, &chain(p, d, p, true), runs(5));
        }
    }
    if want("peer N=10 n=5") {
        // The Python peer's model (benches/python_peer.py): time-invariant, no shortcut.
        time(
            "peer N=10 n=5 time-invariant, shortcut off",
            &chain_measured(10, 5, d / 5, 0, false),
            runs(5),
        );
    }
    if want("peer N=10 n=5 recursion only") {
        // The same model, the filter's covariance recursion and mean alone: what the
        // peer computes, so the like-for-like per-step comparison.
        let model = chain_measured(10, 5, d / 5, 0, false);
        time_with("peer N=10 n=5 recursion only", &model, runs(5), || {
            let r = covariance_recursion(&model, &Default::default(), &mut NoProgress)
                .expect("bench runs");
            std::hint::black_box(&r);
        });
    }
    if want("n30 time-varying a(t)") {
        time("n30 time-varying a(t)", &chain(30, d, 30, true), runs(1));
    }
    for (name, shortcut) in [
        ("shortcut P=10 time-invariant, shortcut on", true),
        ("shortcut P=10 time-invariant, shortcut off", false),
    ] {
        if want(name) {
            time(name, &chain(10, d, 0, shortcut), runs(5));
        }
    }
    if want("budget P=10") {
        // The error budget's pass (kea_core::analysis::budget) on the Table 1 chain: its
        // cost per source and step against the filter's covariance recursion alone.
        let steps = d / 10;
        let model = chain(10, steps, 10, false);
        let compiled = kea_core::model::compile(&model, &Default::default()).expect("compiles");
        let sources = kea_core::analysis::budget::source_count(&compiled);
        let alone = time_with("budget P=10: recursion only", &model, runs(5), || {
            let r = covariance_recursion(&model, &Default::default(), &mut NoProgress)
                .expect("bench runs");
            std::hint::black_box(&r);
        });
        let pass = time_with("budget P=10: the budget's pass", &model, runs(3), || {
            let b = kea_core::analysis::budget::run(&compiled, steps, None, &mut NoProgress)
                .expect("bench runs");
            std::hint::black_box(&b);
        });
        let per = (pass - alone) / sources as f64;
        println!(
            "budget per source: {:.1} ns/step, {:.2}× the covariance recursion alone ({sources} sources)",
            per / steps as f64 * 1e9,
            per / alone
        );
    }
    if want("expressions") {
        let with = time(
            "expressions P=10, 10 time-varying entries",
            &chain(10, d, 10, false),
            runs(5),
        );
        let without = time(
            "expressions P=10, constant a",
            &chain(10, d, 0, false),
            runs(5),
        );
        println!(
            "expression share: {:.1} % of the time-varying run",
            (with - without) / with * 100.0
        );
    }
}
