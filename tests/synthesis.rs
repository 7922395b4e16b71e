//! Synthesis (METHOD §1.7) against independent references: individual analyses cell by
//! cell, threshold checks of the answers, the seed's own Table 2 for the selection
//! logic, and a closed-form scaling argument linking `psi` and `f` (see `psi_and_f`).

use kea_core::exec::{Executor, Sequential};
use kea_core::synthesis::{
    self, Details, RangeParam, Side, Status, SynthesisRequest, SynthesisResult,
};
use kea_core::{Error, Model, NoProgress, Overrides, analyze, presets};
use serde_json::{Value, json};
use std::ops::ControlFlow;

/// Steps for the tests: the criteria of the seed example change by < 1e-3 between
/// D = 5000 and D = 10⁶, and the suite stays fast.
const STEPS: u64 = 5000;

fn seed_model() -> Model {
    let mut m = presets::get("seed-example").expect("preset");
    m.time.steps = kea_core::model::Steps::Fixed(STEPS);
    m
}

/// The seed example with the a-priori error fixed (φ = phi0 = 2e-5, the preset's
/// f·ψ), so that ψ alone is the sensor's accuracy.
fn fixed_phi_model() -> Model {
    let mut m = seed_model();
    m.params.insert("phi0".into(), 2e-5);
    m.system.phi = Some(vec!["phi0".into()]);
    m
}

fn request(model: &Model, target: Value, mode: Value) -> SynthesisRequest {
    synthesis::request_from_value(json!({
        "model": serde_json::to_value(model).unwrap(),
        "target": target,
        "mode": mode,
    }))
    .expect("valid request")
}

fn run(req: &SynthesisRequest) -> SynthesisResult {
    synthesis::synthesize(req, &Sequential, &mut NoProgress).expect("synthesis runs")
}

/// F_YX (bound, weighted) of an individual analysis.
fn f_yx(model: &Model, set: &[(&str, f64)]) -> f64 {
    let set: Overrides = set.iter().map(|(k, v)| (k.to_string(), *v)).collect();
    analyze(model, &set, &mut NoProgress)
        .expect("analysis")
        .criteria
        .bound
        .weighted
        .yx
        .expect("defined")
}

/// A threaded executor (std threads, chunks in order) to show that answers do not
/// depend on the executor or its thread count.
struct Threads(usize);

impl Executor for Threads {
    fn map<T: Send, R: Send, F: Fn(T) -> R + Sync>(&self, items: Vec<T>, f: F) -> Vec<R> {
        let n = items.len();
        let per = n.div_ceil(self.0).max(1);
        let mut chunks: Vec<Vec<T>> = Vec::new();
        let mut it = items.into_iter();
        loop {
            let c: Vec<T> = it.by_ref().take(per).collect();
            if c.is_empty() {
                break;
            }
            chunks.push(c);
        }
        std::thread::scope(|s| {
            let handles: Vec<_> = chunks
                .into_iter()
                .map(|c| s.spawn(|| c.into_iter().map(&f).collect::<Vec<R>>()))
                .collect();
            handles
                .into_iter()
                .flat_map(|h| h.join().unwrap())
                .collect()
        })
    }
    fn threads(&self) -> usize {
        self.0
    }
}

fn seed_grid_request(cost_order: Option<Value>) -> SynthesisRequest {
    let mut grid = json!({"params": [
        {"name": "f", "values": [2.0, 4.0, 8.0]},
        {"name": "c", "values": [0.5, 0.25, 0.125]},
    ]});
    if let Some(c) = cost_order {
        grid["cost_order"] = c;
    }
    request(
        &seed_model(),
        json!({"criterion": "yx", "criteria": "bound", "threshold": 14}),
        json!({ "grid": grid }),
    )
}

#[test]
fn grid_equals_individual_analyses_cell_by_cell() {
    let req = seed_grid_request(None);
    let r = run(&req);
    let Details::Grid(g) = &r.details else {
        panic!("grid details")
    };
    assert_eq!(g.cells.len(), 9);
    assert_eq!(r.analyses, 9);
    assert_eq!(r.steps, STEPS);
    let model = seed_model();
    for cell in &g.cells {
        let (i, j) = (cell.index[0], cell.index[1]);
        let f = [2.0, 4.0, 8.0][i];
        let c = [0.5, 0.25, 0.125][j];
        let set: Overrides = [("f".to_string(), f), ("c".to_string(), c)].into();
        let a = analyze(&model, &set, &mut NoProgress).unwrap();
        let w = &a.criteria.bound.weighted;
        assert_eq!(cell.point.params["f"], f);
        assert_eq!(cell.point.params["c"], c);
        assert_eq!(
            (cell.point.yz, cell.point.zx, cell.point.yx),
            (w.yz, w.zx, w.yx)
        );
        assert_eq!(cell.point.meets, w.yx.unwrap() >= 14.0, "cell f={f} c={c}");
    }
    // kea's criteria do not depend on c (c scales z_B and ζ alike, METHOD §1.9);
    // only f = 8 reaches 14 (f = 4 gives ≈ 12.7).
    let meets: Vec<bool> = g.cells.iter().map(|c| c.point.meets).collect();
    assert_eq!(
        meets,
        [false, false, false, false, false, false, true, true, true]
    );
    assert_eq!(r.status, Status::Table);
    assert!(r.answer.is_none());
}

#[test]
fn grid_cheapest_cell_follows_cost_order_and_is_verified() {
    // Cheaper: a larger c first, then a smaller f.
    let req = seed_grid_request(Some(json!([
        {"name": "c", "cheaper": "higher"},
        {"name": "f", "cheaper": "lower"},
    ])));
    let r = run(&req);
    assert_eq!(r.status, Status::Found, "{}", r.message);
    let a = r.answer.as_ref().unwrap();
    assert_eq!((a.params["f"], a.params["c"]), (8.0, 0.5));
    let Details::Grid(g) = &r.details else {
        panic!()
    };
    assert_eq!(g.cheapest, Some(vec![2, 0]));
    let v = r.verification.as_ref().unwrap();
    assert!(v.passed && v.point.meets);
    assert_eq!(
        v.point.yx,
        Some(f_yx(&seed_model(), &[("f", 8.0), ("c", 0.5)]))
    );
    assert_eq!(r.analyses, 10);

    // The other way round: a smaller c is cheaper → c = 0.125.
    let req = seed_grid_request(Some(json!([{"name": "c", "cheaper": "lower"}])));
    let a = run(&req).answer.unwrap();
    assert_eq!(a.params["c"], 0.125);
    assert_eq!(a.params["f"], 8.0);
}

/// A seed search over ψ and c for F_YX ≥ 14, three points a batch.
fn fixed_phi_seed_search() -> SynthesisRequest {
    request(
        &fixed_phi_model(),
        json!({"criterion": "yx", "threshold": 14}),
        json!({"seed_search": {"params": [
            {"name": "psi", "low": 2.5e-6, "high": 1e-5, "shrink": 0.5},
            {"name": "c", "low": 0.125, "high": 0.5, "shrink": 0.5}
        ], "batch": 3}}),
    )
}

#[test]
fn results_do_not_depend_on_thread_count() {
    let req = seed_grid_request(Some(json!([{"name": "f", "cheaper": "lower"}])));
    let one = run(&req);
    for t in [2, 3, 8] {
        let many = synthesis::synthesize(&req, &Threads(t), &mut NoProgress).unwrap();
        assert_eq!(many, one, "threads = {t}");
    }
    let search = fixed_phi_seed_search();
    let one = run(&search);
    let many = synthesis::synthesize(&search, &Threads(2), &mut NoProgress).unwrap();
    assert_eq!(many, one);
}

#[test]
fn three_param_grid_pages() {
    let req = request(
        &seed_model(),
        json!({"criterion": "yx", "threshold": 10}),
        json!({"grid": {"params": [
            {"name": "f", "values": [4.0, 8.0]},
            {"name": "c", "values": [0.5]},
            {"name": "m_g", "values": [100.0, 50.0]}
        ]}}),
    );
    let r = run(&req);
    let Details::Grid(g) = &r.details else {
        panic!()
    };
    let model = seed_model();
    for cell in &g.cells {
        let p = &cell.point.params;
        let f = f_yx(&model, &[("f", p["f"]), ("c", p["c"]), ("m_g", p["m_g"])]);
        assert_eq!(cell.point.yx, Some(f));
    }
    assert_eq!(
        g.cells.iter().map(|c| c.index.clone()).collect::<Vec<_>>(),
        vec![vec![0, 0, 0], vec![0, 0, 1], vec![1, 0, 0], vec![1, 0, 1]]
    );
    assert!(synthesis::render_text(&r).contains("m_g = 50"));
}

#[test]
fn bisection_answer_meets_and_one_percent_looser_misses() {
    let model = fixed_phi_model();
    let req = request(
        &model,
        json!({"criterion": "yx", "criteria": "bound", "threshold": 14}),
        json!({"bisect": {"param": "psi", "low": 1e-6, "high": 1e-5, "rel_tol": 1e-3}}),
    );
    let r = run(&req);
    assert_eq!(r.status, Status::Found, "{}", r.message);
    let psi = r.answer.as_ref().unwrap().params["psi"];
    // Independent checks by individual analyses.
    assert!(f_yx(&model, &[("psi", psi)]) >= 14.0);
    assert!(f_yx(&model, &[("psi", psi * 1.01)]) < 14.0);
    let v = r.verification.as_ref().unwrap();
    assert!(v.passed);
    assert_eq!(v.looser.as_ref().unwrap().params["psi"], psi * 1.01);
    let Details::Bisect(b) = &r.details else {
        panic!()
    };
    assert_eq!(b.meets_side, Some(Side::Low));
    let [good, bad] = b.bracket.unwrap();
    assert_eq!(good, psi);
    assert!(bad > good && bad / good - 1.0 <= 1e-3);
    assert!(f_yx(&model, &[("psi", bad)]) < 14.0);
    assert_eq!(r.analyses, 9 + b.iterations as u64 + 2);
}

/// With η0 = 0 every SKO scales with ψ when φ = f·ψ, so the criteria depend on f only;
/// with φ fixed at 2e-5, f = 2e-5/ψ. The two bisections must agree: ψ* = 2e-5 / f*.
#[test]
fn psi_and_f_bisections_agree() {
    let by_f = run(&request(
        &seed_model(),
        json!({"criterion": "yx", "threshold": 14}),
        json!({"bisect": {"param": "f", "low": 2.0, "high": 20.0, "rel_tol": 1e-4}}),
    ));
    let by_psi = run(&request(
        &fixed_phi_model(),
        json!({"criterion": "yx", "threshold": 14}),
        json!({"bisect": {"param": "psi", "low": 1e-6, "high": 1e-5, "rel_tol": 1e-4}}),
    ));
    let f = by_f.answer.unwrap().params["f"];
    let psi = by_psi.answer.unwrap().params["psi"];
    let Details::Bisect(b) = &by_f.details else {
        panic!()
    };
    assert_eq!(b.meets_side, Some(Side::High));
    assert!((4.0..8.0).contains(&f), "f* = {f}");
    assert!(
        (psi * f / 2e-5 - 1.0).abs() < 3e-4,
        "psi* = {psi}, f* = {f}"
    );
}

/// The seed's selection logic on the seed's own published Table 2 (METHOD §1.9): the
/// search descends the measured SKO ψ from its upper bound (φ fixed, so f = φ/ψ
/// rises 2 → 4 → 8) and, inside, c (ζ ∝ c) from 0.5 down; it stops at the first cell
/// with F_YX ≥ 14 — the seed's choice f* = 4, c* = 0.25, F_YX = 14.32.
#[test]
fn seed_selection_logic_reproduces_the_seeds_choice_on_table_2() {
    let table2 = |f: f64, c: f64| -> f64 {
        let fi = [2.0, 4.0, 8.0].iter().position(|&x| x == f).unwrap();
        let ci = [0.5, 0.25, 0.125].iter().position(|&x| x == c).unwrap();
        [
            [7.32, 9.27, 4.15],
            [11.66, 14.32, 18.52],
            [23.16, 29.50, 28.99],
        ][fi][ci]
    };
    let params = [
        RangeParam {
            name: "psi".into(),
            low: 2.5e-6,
            high: 1e-5,
            shrink: 0.5,
        },
        RangeParam {
            name: "c".into(),
            low: 0.125,
            high: 0.5,
            shrink: 0.5,
        },
    ];
    let order = synthesis::seed_order(&params);
    assert_eq!(order.len(), 9);
    assert_eq!(order[0], vec![1e-5, 0.5]);
    assert_eq!(order[8], vec![2.5e-6, 0.125]);
    let values: Vec<Option<f64>> = order
        .iter()
        .map(|p| Some(table2((2e-5 / p[0]).round(), p[1])))
        .collect();
    let i = synthesis::first_meeting(&values, 14.0).unwrap();
    assert_eq!(order[i], vec![5e-6, 0.25]);
    assert_eq!(values[i], Some(14.32));
    assert_eq!(i, 4);
}

/// The same search on kea's own analyses: the answer is the first point of the seed's
/// order whose individual analysis meets the target.
#[test]
fn seed_search_stops_at_the_first_point_meeting_the_target() {
    let model = fixed_phi_model();
    let req = request(
        &model,
        json!({"criterion": "yx", "threshold": 14}),
        json!({"seed_search": {"params": [
            {"name": "psi", "low": 2.5e-6, "high": 1e-5, "shrink": 0.5},
            {"name": "c", "low": 0.125, "high": 0.5, "shrink": 0.5}
        ], "batch": 1}}),
    );
    let r = run(&req);
    let order = synthesis::seed_order(match &req.mode {
        synthesis::Mode::SeedSearch(s) => &s.params,
        _ => unreachable!(),
    });
    let values: Vec<Option<f64>> = order
        .iter()
        .map(|p| Some(f_yx(&model, &[("psi", p[0]), ("c", p[1])])))
        .collect();
    let i = synthesis::first_meeting(&values, 14.0).unwrap();
    // kea: c does not matter, ψ = 2.5e-6 (f = 8) is the first level reaching 14.
    assert_eq!(order[i], vec![2.5e-6, 0.5]);
    assert_eq!(r.status, Status::Found, "{}", r.message);
    let a = r.answer.as_ref().unwrap();
    assert_eq!((a.params["psi"], a.params["c"]), (2.5e-6, 0.5));
    assert_eq!(a.value, values[i]);
    let Details::SeedSearch(d) = &r.details else {
        panic!()
    };
    assert_eq!(d.visited.len(), i + 1);
    assert!(d.visited[..i].iter().all(|p| !p.meets));
    assert_eq!(r.analyses, i as u64 + 2); // batch 1: no overshoot, + verification
    assert!(r.verification.unwrap().passed);
}

#[test]
fn infeasible_targets_say_so_and_advise() {
    let model = fixed_phi_model();
    let r = run(&request(
        &model,
        json!({"criterion": "yx", "threshold": 1000}),
        json!({"seed_search": {"params": [
            {"name": "psi", "low": 2.5e-6, "high": 1e-5, "shrink": 0.5}
        ]}}),
    ));
    assert_eq!(r.status, Status::NotFound);
    assert!(r.answer.is_none());
    assert!(r.message.contains("Widen the ranges"), "{}", r.message);
    assert!(r.message.contains("lower the target"), "{}", r.message);
    let Details::SeedSearch(d) = &r.details else {
        panic!()
    };
    assert_eq!(d.visited.len(), 3);

    let r = run(&request(
        &model,
        json!({"criterion": "yx", "threshold": 1000}),
        json!({"bisect": {"param": "psi", "low": 1e-6, "high": 1e-5}}),
    ));
    assert_eq!(r.status, Status::NotFound);
    assert!(r.message.contains("widen the range or lower the target"));

    // A huge target is written as a number is in the other messages (it was printed
    // in full: 309 digits).
    let r = run(&request(
        &model,
        json!({"criterion": "yx", "threshold": 1e308}),
        json!({"grid": {"params": [{"name": "psi", "values": [1e-6, 1e-5]}]}}),
    ));
    assert_eq!(r.status, Status::NotFound);
    assert!(r.message.contains("≥ 1e308"), "{}", r.message);

    // A target met everywhere: the boundary is outside the range.
    let r = run(&request(
        &model,
        json!({"criterion": "yx", "threshold": 1.5}),
        json!({"bisect": {"param": "psi", "low": 1e-7, "high": 1e-6}}),
    ));
    assert_eq!(r.status, Status::WholeRangeMeets, "{}", r.message);
    assert!(r.answer.is_none());
}

/// ψ_eff = ψ·(1 + (k−3)²) with f = 8: f_eff = 8/(1 + (k−3)²) peaks at k = 3, and the
/// effect with it (F_YX rises with f on [2, 20]).
fn humped_model() -> Model {
    let mut m = seed_model();
    m.params.insert("k".into(), 3.0);
    m.params.insert("f".into(), 8.0);
    m.measurement.psi = Some(vec!["psi*(1+(k-3)*(k-3))".into()]);
    m
}

#[test]
fn non_monotonic_criteria_give_no_answer() {
    let model = humped_model();
    let peak = f_yx(&model, &[("k", 3.0)]);
    let edge = f_yx(&model, &[("k", 2.0)]).max(f_yx(&model, &[("k", 4.0)]));
    assert!(peak > edge);
    // Met only around k = 3: two boundaries.
    let r = run(&request(
        &model,
        json!({"criterion": "yx", "threshold": (peak + edge) / 2.0}),
        json!({"bisect": {"param": "k", "low": 2.0, "high": 4.0}}),
    ));
    assert_eq!(r.status, Status::NonMonotonic, "{}", r.message);
    assert!(r.answer.is_none());
    assert!(r.message.contains("not monotonic"));
    // One boundary in [2.8, 4], but the effect rises then falls: still refused.
    let r = run(&request(
        &model,
        json!({"criterion": "yx", "threshold": f_yx(&model, &[("k", 3.5)])}),
        json!({"bisect": {"param": "k", "low": 2.8, "high": 4.0}}),
    ));
    assert_eq!(r.status, Status::NonMonotonic, "{}", r.message);
    // Where the same model is monotonic (k ≥ 3), the boundary is found: k* ≈ 3.5.
    let r = run(&request(
        &model,
        json!({"criterion": "yx", "threshold": f_yx(&model, &[("k", 3.5)])}),
        json!({"bisect": {"param": "k", "low": 3.0, "high": 4.0}}),
    ));
    assert_eq!(r.status, Status::Found, "{}", r.message);
    assert!((r.answer.unwrap().params["k"] / 3.5 - 1.0).abs() < 1e-3);
}

#[test]
fn invalid_requests_name_the_field() {
    let model = serde_json::to_value(seed_model()).unwrap();
    let paths = |v: Value| -> Vec<String> {
        let err = match synthesis::request_from_value(v) {
            Err(e) => e,
            Ok(req) => synthesis::validate(&req).expect_err("invalid"),
        };
        let Error::Invalid(list) = err else {
            panic!("{err:?}")
        };
        list.into_iter().map(|e| e.path).collect()
    };
    let target = json!({"criterion": "yx", "threshold": 14});
    assert_eq!(
        paths(json!({"model": model, "target": target,
            "mode": {"bisect": {"param": "psi", "low": 1e-3, "high": 1e-5}}})),
        ["mode.bisect.high"]
    );
    assert_eq!(
        paths(json!({"model": model, "target": target,
            "mode": {"bisect": {"param": "nope", "low": 0, "high": 1e-5, "rel_tol": 0.05}}})),
        [
            "mode.bisect.param",
            "mode.bisect.low",
            "mode.bisect.rel_tol"
        ]
    );
    assert_eq!(
        paths(
            json!({"model": model, "target": {"criterion": "yx", "threshold": -1, "state": "Q"},
            "mode": {"seed_search": {"params": [{"name": "c", "low": 0.1, "high": 0.5, "shrink": 1.5}]}}})
        ),
        [
            "target.threshold",
            "target.state",
            "mode.seed_search.params[0].shrink"
        ]
    );
    assert_eq!(
        paths(json!({"model": model, "target": target,
            "mode": {"grid": {"params": [{"name": "c", "values": [1]}, {"name": "c", "values": []}],
                "cost_order": [{"name": "f", "cheaper": "lower"}]}}})),
        [
            "mode.grid.params[1].name",
            "mode.grid.params[1].values",
            "mode.grid.cost_order[0].name"
        ]
    );
    // A low the bisection refuses is one error: the model was also checked at it
    // ("the model is invalid with psi = -1"), a second error at the same path.
    assert_eq!(
        paths(json!({"model": model, "target": target,
            "mode": {"bisect": {"param": "psi", "low": -1, "high": 1e-5}}})),
        ["mode.bisect.low"]
    );
    // Subnormal bounds: neighbouring doubles there are further apart than any rel_tol,
    // so the bracket could never narrow (it looped forever before).
    let subnormal = json!({"model": model, "target": target,
        "mode": {"bisect": {"param": "psi", "low": 1e-322, "high": 1e-321, "rel_tol": 1e-3}}});
    assert_eq!(
        paths(subnormal.clone()),
        ["mode.bisect.low", "mode.bisect.high"]
    );
    let req = synthesis::request_from_value(subnormal).expect("readable");
    let said = synthesis::validate(&req).expect_err("invalid").to_string();
    assert!(
        said.contains("mode.bisect.low: expected a finite number ≥ 2.2250738585072014e-308"),
        "{said}"
    );
    // probes: its range in both messages (a non-whole number said "a whole number ≥ 0").
    let message = |probes: Value| {
        let v = json!({"model": model, "target": target,
            "mode": {"bisect": {"param": "psi", "low": 1e-6, "high": 1e-5, "probes": probes}}});
        let err = match synthesis::request_from_value(v) {
            Err(e) => e,
            Ok(req) => synthesis::validate(&req).expect_err("invalid"),
        };
        err.to_string()
    };
    assert_eq!(
        message(json!(2.5)),
        "mode.bisect.probes: expected a whole number from 2 to 64, got 2.5"
    );
    assert_eq!(
        message(json!(-3)),
        "mode.bisect.probes: expected a whole number from 2 to 64, got -3"
    );
    assert_eq!(
        message(json!(1)),
        "mode.bisect.probes: expected a whole number from 2 to 64 (log-spaced points, ends included), got 1"
    );
    assert_eq!(
        synthesis::request_from_value(json!({"model": model, "target": target,
            "mode": {"bisect": {"param": "psi", "low": 1e-6, "high": 1e-5, "probes": 5.0}}}))
        .map(|r| match r.mode {
            synthesis::Mode::Bisect(b) => b.probes,
            _ => 0,
        })
        .ok(),
        Some(5),
        "a whole number written as a float is read"
    );
    // batch: the range in words and the value (it said "expected 1..=1024").
    let batch = |batch: Value| {
        let v = json!({"model": model, "target": target,
            "mode": {"seed_search": {"params": [{"name": "psi", "low": 2.5e-6, "high": 1e-5, "shrink": 0.5}], "batch": batch}}});
        match synthesis::request_from_value(v) {
            Err(e) => e,
            Ok(req) => synthesis::validate(&req).expect_err("invalid"),
        }
        .to_string()
    };
    assert_eq!(
        batch(json!(0)),
        "mode.seed_search.batch: expected a whole number from 1 to 1024, got 0"
    );
    assert_eq!(
        batch(json!(2.5)),
        "mode.seed_search.batch: expected a whole number from 1 to 1024, got 2.5"
    );
    let p = paths(json!({"model": model, "target": target,
        "mode": {"bisect": {"param": "psi", "lo": 1e-7, "high": 1e-5}}}));
    assert_eq!(p.len(), 1);
    assert!(p[0].starts_with("mode.bisect"), "{p:?}");
    assert_eq!(
        paths(
            json!({"model": model, "target": {"criterion": "xy", "threshold": 1},
            "mode": {"grid": {"params": [{"name": "c", "values": [1]}]}}})
        ),
        ["target.criterion"]
    );
    assert_eq!(
        paths(json!({"model": model, "target": target, "set": {"zz": 1},
            "mode": {"grid": {"params": [{"name": "c", "values": [1]}]}}})),
        ["set.zz"]
    );
    // No mode, or two: the message names the three (serde said "expected map with a
    // single key").
    for mode in [json!({}), json!({"grid": {}, "bisect": {}})] {
        let err =
            synthesis::request_from_value(json!({"model": model, "target": target, "mode": mode}))
                .unwrap_err();
        assert!(
            err.to_string().contains(
                "mode: expected the search, an object with exactly one member: seed_search, bisect or grid"
            ),
            "{err}"
        );
    }
}

/// What the model would refuse during the run is refused with the request, at the
/// request's own path: a searched value the model cannot take, a searched param also
/// fixed in `set`, a YZ or ZX target for a state without a measurement.
#[test]
fn values_the_model_refuses_are_named_before_the_run() {
    let model = serde_json::to_value(seed_model()).unwrap();
    let target = json!({"criterion": "yx", "threshold": 14});
    let errors = |v: Value| -> Vec<(String, String)> {
        let req = synthesis::request_from_value(v).expect("readable");
        synthesis::validate(&req)
            .expect_err("invalid")
            .field_errors()
            .into_iter()
            .map(|e| (e.path, e.message))
            .collect()
    };
    // ψ = −1e-5: negative SKOs (φ = fψ, ψ), at the grid value (the column's smallest).
    let e = errors(json!({"model": model, "target": target,
        "mode": {"grid": {"params": [{"name": "psi", "values": [1e-5, -1e-5, 2e-5]}]}}}));
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].0, "mode.grid.params[0].values[1]");
    assert!(
        e[0].1
            .starts_with("the model is invalid with psi = -1e-5: "),
        "{e:?}"
    );
    assert!(e[0].1.contains("an SKO must be ≥ 0"), "{e:?}");
    // m = 0 at a bisection's end: a = s/m is not finite.
    let e = errors(json!({"model": model, "target": target, "set": {"f": 3},
        "mode": {"seed_search": {"params": [{"name": "m", "low": 1e-320, "high": 100, "shrink": 0.5}]}}}));
    assert!(
        e.iter().any(|(p, _)| p == "mode.seed_search.params[0].low"),
        "{e:?}"
    );
    let e = errors(
        json!({"model": model, "target": target, "set": {"psi": 1e-5},
        "mode": {"bisect": {"param": "psi", "low": 1e-6, "high": 1e-4}}}),
    );
    assert_eq!(
        e,
        [(
            "set.psi".to_string(),
            "\"psi\" is a searched param (at mode.bisect.low): the search sets it, so it cannot be fixed in set".to_string()
        )]
    );
    let cv = serde_json::to_value(presets::get("cv-tracker").unwrap()).unwrap();
    let e = errors(
        json!({"model": cv, "target": {"criterion": "yz", "threshold": 2, "state": "velocity"},
        "mode": {"grid": {"params": [{"name": "r", "values": [1]}]}}}),
    );
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!(e[0].0, "target.criterion");
    assert!(e[0].1.contains("no paired measurement"), "{e:?}");
}

#[test]
fn cancellation_stops_the_synthesis() {
    let req = seed_grid_request(None);
    let mut calls = 0;
    let mut stop_early = |_f: f64| {
        calls += 1;
        if calls > 3 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    };
    let err = synthesis::synthesize(&req, &Sequential, &mut stop_early).unwrap_err();
    assert_eq!(err, Error::Cancelled);
    let err = synthesis::synthesize(&req, &Threads(2), &mut |_f: f64| ControlFlow::Break(()))
        .unwrap_err();
    assert_eq!(err, Error::Cancelled);
}

#[test]
fn progress_rises_to_one() {
    let req = seed_grid_request(None);
    let mut seen: Vec<f64> = Vec::new();
    let mut record = |f: f64| {
        seen.push(f);
        ControlFlow::Continue(())
    };
    run_with(&req, &mut record);
    assert!(seen.windows(2).all(|w| w[1] >= w[0] - 1e-12), "{seen:?}");
    assert_eq!(*seen.last().unwrap(), 1.0);
}

fn run_with(req: &SynthesisRequest, p: &mut dyn kea_core::Progress) -> SynthesisResult {
    synthesis::synthesize(req, &Sequential, p).unwrap()
}

/// A synthesis on the bound set reported "found … verified by a fresh analysis" for
/// the helicopter range channel, whose bound grows far beyond the covariance's (the
/// Analysis of the same point warns that the bound set's criteria then describe |A|'s
/// growth). The verification now carries the answer's analysis's warnings, the same
/// the analysis gives, and the text prints them.
#[test]
fn the_verification_carries_the_answers_analysis_warnings() {
    let model = presets::get("helicopter-range").expect("preset");
    let req = request(
        &model,
        json!({"criteria": "bound", "criterion": "yx", "threshold": 0.6}),
        json!({"seed_search": {"params": [{"name": "sd", "low": 0.6, "high": 5, "shrink": 0.5}]}}),
    );
    let r = run(&req);
    assert_eq!(r.status, Status::Found, "{}", r.message);
    let v = r.verification.as_ref().expect("verified");
    let answer: Vec<(&str, f64)> = v
        .point
        .params
        .iter()
        .map(|(k, x)| (k.as_str(), *x))
        .collect();
    let set: Overrides = answer.iter().map(|(k, x)| (k.to_string(), *x)).collect();
    let direct = analyze(&model, &set, &mut NoProgress).unwrap();
    assert!(
        direct
            .warnings
            .iter()
            .any(|w| w.contains("grew far beyond")),
        "{:?}",
        direct.warnings
    );
    assert_eq!(v.warnings, direct.warnings);
    let text = synthesis::render_text(&r);
    assert!(
        text.contains(
            "warning (the answer's analysis): the bound (modulus procedure) grew far beyond"
        ),
        "{text}"
    );
}

/// The bound set's own warnings (its growth far beyond the covariance's interval)
/// say nothing of the covariance set's criteria: a covariance target's verification
/// leaves them out, and keeps the rest of what the analysis says.
#[test]
fn a_covariance_targets_verification_leaves_out_the_bound_sets_warnings() {
    let model = presets::get("cv-tracker").expect("preset");
    let req = request(
        &model,
        json!({"criteria": "covariance", "criterion": "yx", "state": "position", "threshold": 300}),
        json!({"bisect": {"param": "r", "low": 0.05, "high": 5}}),
    );
    let r = run(&req);
    assert_eq!(r.status, Status::Found, "{}", r.message);
    let v = r.verification.as_ref().expect("verified");
    let set: Overrides = v.point.params.clone().into_iter().collect();
    let direct = analyze(&model, &set, &mut NoProgress).unwrap();
    let bound_only: Vec<&String> = direct
        .warnings
        .iter()
        .filter(|w| w.starts_with("the bound (modulus procedure)"))
        .collect();
    assert!(!bound_only.is_empty(), "{:?}", direct.warnings);
    let rest: Vec<String> = direct
        .warnings
        .iter()
        .filter(|w| !bound_only.contains(w))
        .cloned()
        .collect();
    assert_eq!(v.warnings, rest);
    assert!(!synthesis::render_text(&r).contains("warning"));
}

/// A memo in memory, counting what is kept (each kept entry is an analysis run).
#[derive(Default)]
struct CountingMemo {
    kept: std::sync::Mutex<std::collections::HashMap<String, String>>,
    runs: std::sync::atomic::AtomicU64,
}

impl kea_core::exec::Memo for CountingMemo {
    fn recall(&self, key: &str) -> Option<String> {
        self.kept.lock().unwrap().get(key).cloned()
    }
    fn keep(&self, key: &str, value: &str) {
        self.runs.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.kept
            .lock()
            .unwrap()
            .insert(key.to_string(), value.to_string());
    }
}

/// A synthesis interrupted (a server's job stopped by a shutdown) and run again with
/// what it kept gives the uninterrupted result — every mode, one thread and several —
/// while running only the analyses the first run had not done; an entry that does not
/// read back is run again rather than trusted.
#[test]
fn an_interrupted_synthesis_resumes_from_what_it_kept() {
    use std::sync::atomic::Ordering::Relaxed;
    let bisect = request(
        &fixed_phi_model(),
        json!({"criterion": "yx", "criteria": "bound", "threshold": 14}),
        json!({"bisect": {"param": "psi", "low": 1e-6, "high": 1e-5, "rel_tol": 1e-3}}),
    );
    let search = fixed_phi_seed_search();
    let grid = seed_grid_request(Some(json!([{"name": "f", "cheaper": "lower"}])));
    for (name, req) in [("bisect", bisect), ("seed_search", search), ("grid", grid)] {
        let whole = run(&req);
        assert_eq!(whole.recalled_analyses, 0);
        for threads in [1, 3] {
            let memo = CountingMemo::default();
            // Stopped at about half its progress.
            let mut half = |f: f64| {
                if f >= 0.5 {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            };
            let stopped = synthesis::synthesize_resuming(&req, &Threads(threads), &mut half, &memo);
            assert_eq!(stopped.unwrap_err(), Error::Cancelled, "{name}");
            let first = memo.runs.swap(0, Relaxed);
            assert!(first > 0 && first < whole.analyses, "{name}: {first}");
            // One kept entry spoilt: run again, not read as an answer.
            let spoilt = memo.kept.lock().unwrap().keys().next().cloned().unwrap();
            memo.kept.lock().unwrap().insert(spoilt, "{".into());

            let resumed =
                synthesis::synthesize_resuming(&req, &Threads(threads), &mut NoProgress, &memo)
                    .unwrap();
            let again = memo.runs.load(Relaxed);
            let at = format!(
                "{name}, {threads} threads: {} recalled, {again} run",
                resumed.recalled_analyses
            );
            // Each analysis either recalled or run; the spoilt one among those run.
            assert_eq!(resumed.recalled_analyses + again, whole.analyses, "{at}");
            assert!(
                resumed.recalled_analyses > 0 && resumed.recalled_analyses < first,
                "{at}"
            );
            assert!(again >= 1 && again < whole.analyses, "{at}");
            let mut same = resumed.clone();
            same.recalled_analyses = 0;
            assert_eq!(same, whole, "{name}, {threads} threads");
        }
    }
}

/// The target's criteria set is `criteria`; `set`, its former name (a request's own
/// `set` is its parameter overrides), is still read as it: the same request and the
/// same result, which writes the set under both names and reads back either. The two
/// together are refused at the target's `criteria`, by the request reader and by the
/// kind (the server's and the command line's way in); an unknown member names
/// `criteria`.
#[test]
fn the_targets_criteria_set_is_also_read_under_its_former_name_set() {
    let model = serde_json::to_value(seed_model()).unwrap();
    let target = |members: &[&str]| {
        let mut t = json!({"criterion": "yx", "threshold": 14});
        for m in members {
            t[*m] = json!("covariance");
        }
        t
    };
    let mode = json!({"grid": {"params": [{"name": "f", "values": [2.0, 4.0]}]}});
    let body = |t: Value| json!({"model": model, "target": t, "mode": mode});
    let read = |t: Value| synthesis::request_from_value(body(t));
    let new = read(target(&["criteria"])).unwrap();
    let old = read(target(&["set"])).unwrap();
    assert_eq!(old, new);
    assert_eq!(new.target.criteria, synthesis::CriteriaSetName::Covariance);
    let r = run(&old);
    assert_eq!(r, run(&new));
    let written = serde_json::to_value(&r).unwrap();
    assert_eq!(written["target"]["criteria"], "covariance");
    assert_eq!(written["target"]["set"], "covariance");
    let back: SynthesisResult = serde_json::from_value(written.clone()).unwrap();
    assert_eq!(back, r);
    let mut earlier = written;
    earlier["target"]
        .as_object_mut()
        .unwrap()
        .remove("criteria");
    let back: SynthesisResult = serde_json::from_value(earlier).unwrap();
    assert_eq!(back, r, "a result of an earlier version, with `set` alone");

    let twice = "given twice, under its name and a former one; give `criteria` alone";
    let located = |e: Error| -> Vec<(String, String)> {
        e.field_errors()
            .into_iter()
            .map(|f| (f.path, f.message))
            .collect()
    };
    let both = read(target(&["criteria", "set"])).unwrap_err();
    assert_eq!(
        located(both),
        [("target.criteria".to_string(), twice.to_string())]
    );
    let both = kea_core::registry::prepare("synthesis", body(target(&["set", "criteria"])))
        .err()
        .unwrap();
    assert_eq!(
        located(both),
        [("target.criteria".to_string(), twice.to_string())]
    );
    let mut typo = target(&["criteria"]);
    typo["critera"] = json!("bound");
    let unknown = located(read(typo).unwrap_err());
    assert_eq!(unknown.len(), 1, "{unknown:?}");
    assert_eq!(unknown[0].0, "target.critera");
    assert!(unknown[0].1.contains("criteria"), "{unknown:?}");
}
