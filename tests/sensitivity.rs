//! The sensitivity kind (`kea_core::sensitivity`) against separate analyses, under
//! threads, and against Euler's theorem for criteria that are ratios of SKOs.

mod common;
use common::{assert_error_at, preset_value};
use kea_core::exec::{Executor, Forgetful, Sequential};
use kea_core::registry::{self, Outcome};
use kea_core::sensitivity::SensitivityResult;
use kea_core::{NoProgress, analysis::analyze, model_from_value};
use serde_json::{Value, json};

fn run_with<E: Executor>(request: Value, exec: &E) -> SensitivityResult {
    let prepared = registry::prepare("sensitivity", request).expect("a valid request");
    match prepared.run(exec, &mut NoProgress, &Forgetful) {
        Ok(Outcome::Sensitivity(r)) => r,
        Ok(_) => panic!("a sensitivity"),
        Err(e) => panic!("it runs: {e:?}"),
    }
}

fn run(request: Value) -> SensitivityResult {
    run_with(request, &Sequential)
}

/// Runs a batch on scoped threads, each item on its own: the order of the results is
/// the items', whatever order the threads finish in.
struct Threads;

impl Executor for Threads {
    fn map<T: Send, R: Send, F: Fn(T) -> R + Sync>(&self, items: Vec<T>, f: F) -> Vec<R> {
        std::thread::scope(|s| {
            let handles: Vec<_> = items.into_iter().map(|x| s.spawn(|| f(x))).collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        })
    }
    fn threads(&self) -> usize {
        3
    }
}

/// The weighted criteria of an analysis at `set`, as the sensitivity lists them.
fn criteria(model: &Value, set: &[(&str, f64)]) -> [Option<f64>; 6] {
    let m = model_from_value(model.clone()).unwrap();
    let set = set.iter().map(|(k, v)| (k.to_string(), *v)).collect();
    let r = analyze(&m, &set, &mut NoProgress).unwrap();
    let (c, b) = (&r.criteria.covariance.weighted, &r.criteria.bound.weighted);
    [c.yx, c.zx, c.yz, b.yx, b.zx, b.yz]
}

/// Each S is the central difference of two separate analyses, bit for bit; the
/// params are ranked by |S| of covariance.yx; the same bits on three threads.
#[test]
fn equals_separate_analyses_and_does_not_depend_on_threads() {
    let model = preset_value("cv-tracker");
    let request = json!({ "model": model, "set": { "q": 2.0 }, "relative_step": 0.01 });
    let r = run(request.clone());
    assert_eq!(r.analyses, 1 + 2 * r.params.len() as u64);
    let h = 0.01f64;
    for p in &r.params {
        let v = p.value;
        let other: Vec<(&str, f64)> = if p.name == "q" {
            vec![]
        } else {
            vec![("q", 2.0)]
        };
        let at = |x: f64| {
            let mut set = other.clone();
            set.push((p.name.as_str(), x));
            criteria(&model, &set)
        };
        let (hi, lo) = (at(v * h.exp()), at(v * (-h).exp()));
        for k in 0..6 {
            let expected = match (hi[k], lo[k]) {
                (Some(a), Some(b)) if a > 0.0 && b > 0.0 => Some((a.ln() - b.ln()) / (2.0 * h)),
                _ => None,
            };
            assert_eq!(p.sensitivity.get(k), expected, "{} criterion {k}", p.name);
        }
        assert_eq!(p.high, Some(v * h.exp()));
    }
    let ranked: Vec<f64> = r
        .params
        .iter()
        .map(|p| p.sensitivity.covariance.yx.unwrap().abs())
        .collect();
    assert!(ranked.windows(2).all(|w| w[0] >= w[1]), "{ranked:?}");
    let threaded = run_with(request, &Threads);
    assert_eq!(
        serde_json::to_string(&threaded).unwrap(),
        serde_json::to_string(&r).unwrap()
    );
}

/// Scaling every noise level (η0, φ, ψ) by one factor scales every variance by its
/// square and leaves the covariance set's criteria (ratios of SKOs) unchanged: by
/// Euler's theorem the three params' S add up to 0. A param no entry uses has S = 0
/// exactly; a param at 0 has none.
#[test]
fn noise_levels_sum_to_zero_and_unused_params_do_not_move() {
    let model = json!({
        "kea_model": 1,
        "params": { "q": 0.7, "r": 0.4, "s0": 2.0, "k": -0.8, "unused": 3.0, "zero": 0.0 },
        "time": { "t0": 0, "t_end": 10, "steps": 2000 },
        "system": {
            "states": ["x", "v"],
            "a": [[0, 1], ["k", "-0.5 + zero"]],
            "b": [[0], [1]],
            "y0": [5, 1],
            "eta0": ["s0", "s0/2"],
            "phi": ["q"]
        },
        "measurement": { "names": ["z"], "c": [[1, 0]], "gamma": [[1]], "psi": ["r"] },
        "options": { "steady_state_shortcut": false }
    });
    let r = run(json!({ "model": model }));
    let s = |name: &str| r.params.iter().find(|p| p.name == name).unwrap();
    for k in 0..3 {
        let sum: f64 = ["q", "r", "s0"]
            .iter()
            .map(|n| s(n).sensitivity.get(k).unwrap())
            .sum();
        let scale: f64 = ["q", "r", "s0"]
            .iter()
            .map(|n| s(n).sensitivity.get(k).unwrap().abs())
            .sum();
        assert!(
            sum.abs() <= 1e-6 * scale.max(1.0),
            "criterion {k}: {sum:e} of {scale}"
        );
        assert!(s("q").sensitivity.get(k).unwrap().abs() > 1e-3, "q matters");
    }
    assert_eq!(s("unused").sensitivity.covariance.yx, Some(0.0));
    assert!(
        s("k").sensitivity.covariance.yx.is_some(),
        "a negative param is scaled too"
    );
    let zero = s("zero");
    assert!(zero.undefined.as_deref().unwrap().contains("is 0"));
    assert_eq!(zero.sensitivity.covariance.yx, None);
    assert_eq!(r.params.last().unwrap().name, "zero", "undefined last");
    // 5 params away from 0: 11 analyses.
    assert_eq!(r.analyses, 11);
}

/// The derivative converges: h = 1e-3 and h = 1e-4 agree to the difference's O(h²).
#[test]
fn the_step_converges() {
    let model = preset_value("helicopter-range");
    let at = |h: f64| run(json!({ "model": model, "params": ["sd", "sv_f"], "relative_step": h }));
    let (a, b) = (at(1e-3), at(1e-4));
    for (p, q) in a.params.iter().zip(&b.params) {
        assert_eq!(p.name, q.name);
        for k in 0..3 {
            let (x, y) = (p.sensitivity.get(k).unwrap(), q.sensitivity.get(k).unwrap());
            assert!(
                (x - y).abs() <= 1e-5 * x.abs().max(1e-2),
                "{} {k}: {x} against {y}",
                p.name
            );
        }
    }
}

#[test]
fn bad_requests_are_refused_at_their_paths() {
    let model = preset_value("cv-tracker");
    let refused = |extra: Value| {
        let mut req = json!({ "model": model });
        for (k, v) in extra.as_object().unwrap() {
            req[k] = v.clone();
        }
        registry::prepare("sensitivity", req)
            .err()
            .expect("refused")
    };
    assert_error_at(
        &refused(json!({"params": ["q", "nope"]})),
        "params[1]",
        "not a param of the model",
    );
    assert_error_at(
        &refused(json!({"params": ["q", "q"]})),
        "params[1]",
        "named twice",
    );
    assert_error_at(&refused(json!({"params": []})), "params", "expected a list");
    assert_error_at(
        &refused(json!({"relative_step": 0.5})),
        "relative_step",
        "expected a number from",
    );
    assert_error_at(
        &refused(json!({"rank_by": "yx"})),
        "rank_by",
        "covariance.yx",
    );
    assert_error_at(&refused(json!({"set": {"nope": 1}})), "set.nope", "");
    let work = registry::prepare("sensitivity", json!({ "model": model, "params": ["q"] }))
        .unwrap()
        .work();
    assert!(work.explain.starts_with("3 analyses"), "{}", work.explain);
}
