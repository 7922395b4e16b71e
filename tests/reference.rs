//! The analysis against independent references: closed forms of the scalar case and
//! scipy's DARE (the team's shared reference values, copied to tests/data/dare_reference.json).

mod common;
use common::matrix;
use kea_core::{AnalysisResult, Model, NoProgress, analyze, model_from_value};
use serde_json::{Value, json};

fn run(model: Value) -> AnalysisResult {
    let m: Model = model_from_value(model).expect("valid model");
    analyze(&m, &Default::default(), &mut NoProgress).expect("analysis runs")
}

fn rel(a: f64, b: f64) -> f64 {
    if b == 0.0 {
        a.abs()
    } else {
        ((a - b) / b).abs()
    }
}

fn max_rel(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let scale = b.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .map(|(x, y)| (x - y).abs() / scale)
        .fold(0.0, f64::max)
}

/// Scalar model: dY/dt = a Y + u + b F, Z = c y + γ Φ, constant coefficients.
#[allow(clippy::too_many_arguments)] // the equation's coefficients, in its order
fn scalar(
    a: f64,
    u: f64,
    b: f64,
    phi: f64,
    c: f64,
    gamma: f64,
    psi: f64,
    y0: f64,
    eta0: f64,
    steps: u64,
    shortcut: bool,
) -> Value {
    json!({
        "params": {},
        "time": {"t0": 0.0, "t_end": 2.0, "steps": steps},
        "system": {"states": ["x"], "a": [[a]], "u": [u], "b": [[b]], "y0": [y0], "eta0": [eta0], "phi": [phi]},
        "measurement": {"names": ["z"], "c": [[c]], "gamma": [[gamma]], "psi": [psi]},
        "options": {"steady_state_shortcut": shortcut}
    })
}

/// The scalar Riccati map r ↦ A² r Rv/(c² r + Rv) + B is a Möbius transformation; its
/// positive fixed point solves c² r² + (Rv − A² Rv − B c²) r − B Rv = 0.
#[test]
fn scalar_steady_state_matches_the_quadratic_closed_form() {
    let (a, b, phi, c, gamma, psi) = (-0.8, 1.3, 0.7, 2.0, 1.0, 0.05);
    let steps = 20_000u64;
    let dt = 2.0 / steps as f64;
    let r = run(scalar(
        a, 0.5, b, phi, c, gamma, psi, 1.0, 0.3, steps, false,
    ));
    let big_a = 1.0 + a * dt;
    let big_b = (b * dt * phi).powi(2);
    let rv = (gamma * psi).powi(2);
    let qa = c * c;
    let qb = rv - big_a * big_a * rv - big_b * c * c;
    let qc = -big_b * rv;
    let r_inf = (-qb + (qb * qb - 4.0 * qa * qc).sqrt()) / (2.0 * qa);
    let post = r_inf * rv / (c * c * r_inf + rv);
    let gain = r_inf * c / (c * c * r_inf + rv);
    let ss = r
        .steady_state
        .as_ref()
        .expect("a time-invariant model reaches steady state");
    assert!(
        rel(r.final_.predicted_covariance[0][0], r_inf) < 1e-9,
        "{} vs {r_inf}",
        r.final_.predicted_covariance[0][0]
    );
    assert!(rel(r.final_.covariance[0][0], post) < 1e-9);
    assert!(rel(r.final_.gain[0][0], gain) < 1e-9);
    assert!(rel(ss.covariance[0][0], post) < 1e-9);
    assert!(!ss.shortcut_used);
}

/// Means (3.3), the bound (3.16) and the open-loop variance in closed form:
/// y_k = A^k y0 + uΔt (A^k − 1)/(A − 1), η_k = A^k η0 + bΔtφ (A^k − 1)/(A − 1) (A > 0),
/// P^Y_k = A^{2k} η0² + B (A^{2k} − 1)/(A² − 1).
#[test]
fn scalar_means_bounds_and_open_loop_match_geometric_sums() {
    let (a, u, b, phi, y0, eta0) = (0.37, -9.81, 2.15, 2e-5, 0.5, 1e-3);
    let steps = 100_000u64;
    let dt = 2.0 / steps as f64;
    let r = run(scalar(a, u, b, phi, 0.5, 1.0, 1e-4, y0, eta0, steps, true));
    let big_a: f64 = 1.0 + a * dt;
    let ak = big_a.powi(steps as i32);
    let geo = (ak - 1.0) / (big_a - 1.0);
    let y_d = ak * y0 + u * dt * geo;
    let eta_d = ak * eta0 + b * dt * phi * geo;
    let big_b = (b * dt * phi).powi(2);
    let a2k = big_a.powi(2 * steps as i32);
    let p_d = a2k * eta0 * eta0 + big_b * (a2k - 1.0) / (big_a * big_a - 1.0);
    let y_last = *r.traces.states[0].y.last().unwrap();
    assert!(rel(y_last, y_d) < 1e-9, "{y_last} vs {y_d}");
    assert!(
        rel(r.final_.eta[0], eta_d) < 1e-9,
        "{} vs {eta_d}",
        r.final_.eta[0]
    );
    assert!(rel(r.final_.open_loop_sko[0], p_d.sqrt()) < 1e-9);
    // y is monotone (negative and growing in modulus here), so y_B = |y_D|
    assert!(rel(r.y_max[0], y_d.abs()) < 1e-9);
    // ẏ_B = sup |a y + u| over the grid: at the last grid point t_{D−1}
    let y_dm1 = big_a.powi(steps as i32 - 1) * y0
        + u * dt * (big_a.powi(steps as i32 - 1) - 1.0) / (big_a - 1.0);
    assert!(rel(r.ydot_max[0], (a * y_dm1 + u).abs()) < 1e-9);
    // λ for P = 0.95
    assert!((r.lambda - 1.959963984540054).abs() < 1e-12);
    assert!(rel(r.final_.delta_y[0], r.lambda * eta_d) < 1e-9);
}

fn reference() -> Value {
    serde_json::from_str(include_str!("data/dare_reference.json")).expect("reference JSON")
}

/// A discrete model (A, Q, H, R) as a kea model with Δt = 1: a = A − I, b = I, W = Q,
/// C = H, Γ = I, V = R (so B = bΔt W bᵀΔt = Q and Rv = R exactly).
fn discrete_model(m: &Value, steps: u64) -> Value {
    let a = matrix(&m["A"]);
    let n = a.len();
    let h = matrix(&m["H"]);
    let nm = h.len();
    let a_minus_i: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| a[i][j] - if i == j { 1.0 } else { 0.0 })
                .collect()
        })
        .collect();
    let eye = |k: usize| -> Vec<Vec<f64>> {
        (0..k)
            .map(|i| (0..k).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
            .collect()
    };
    json!({
        "time": {"t0": 0.0, "t_end": steps as f64, "steps": steps},
        "system": {
            "states": (0..n).map(|i| format!("x{i}")).collect::<Vec<_>>(),
            "a": a_minus_i, "b": eye(n), "W": m["Q"].clone(),
            "y0": vec![1.0; n]
        },
        "measurement": {
            "names": (0..nm).map(|i| format!("z{i}")).collect::<Vec<_>>(),
            "c": h, "gamma": eye(nm), "V": m["R"].clone()
        },
        "options": {"steady_state_shortcut": true, "trace_points": 10}
    })
}

#[test]
fn steady_state_matches_scipy_dare_for_every_reference_model() {
    let refs = reference();
    for (name, m) in refs["models"].as_object().unwrap() {
        let iterations = m["iteration"]["iterations"].as_u64().unwrap();
        let r = run(discrete_model(m, iterations * 2 + 100));
        let ss = r
            .steady_state
            .as_ref()
            .unwrap_or_else(|| panic!("{name}: no steady state"));
        assert!(ss.shortcut_used, "{name}");
        let prior = matrix(&m["P_prior_dare"]);
        let post = matrix(&m["P_post_dare"]);
        let k = matrix(&m["K_dare"]);
        let e_prior = max_rel(&r.final_.predicted_covariance, &prior);
        let e_post = max_rel(&r.final_.covariance, &post);
        let e_gain = max_rel(&r.final_.gain, &k);
        eprintln!(
            "{name}: prior {e_prior:e}, post {e_post:e}, gain {e_gain:e}, steady at {}",
            ss.reached_at_step
        );
        assert!(
            e_prior < 1e-9,
            "{name}: predicted covariance differs by {e_prior:e}"
        );
        assert!(
            e_post < 1e-9,
            "{name}: filtered covariance differs by {e_post:e}"
        );
        assert!(e_gain < 1e-9, "{name}: gain differs by {e_gain:e}");
    }
}

#[test]
fn doubling_algorithm_matches_scipy_dare() {
    let refs = reference();
    for (name, m) in refs["models"].as_object().unwrap() {
        let a = matrix(&m["A"]);
        let n = a.len();
        let h = matrix(&m["H"]);
        let nm = h.len();
        let flat = |x: &Vec<Vec<f64>>| x.iter().flatten().cloned().collect::<Vec<f64>>();
        let mut c_nz = Vec::new();
        for j in 0..nm {
            for i in 0..n {
                if h[j][i] != 0.0 {
                    c_nz.push((j, i, h[j][i]));
                }
            }
        }
        let r_inf = kea_core::numerics::riccati::dare_doubling(
            &flat(&a),
            &c_nz,
            &flat(&matrix(&m["Q"])),
            &flat(&matrix(&m["R"])),
            n,
            nm,
            kea_core::numerics::riccati::MAX_DOUBLINGS,
        )
        .unwrap_or_else(|e| panic!("{name}: doubling failed ({e:?})"));
        let rows: Vec<Vec<f64>> = r_inf.chunks(n).map(|r| r.to_vec()).collect();
        let e = max_rel(&rows, &matrix(&m["P_prior_dare"]));
        assert!(e < 1e-11, "{name}: {e:e}");
    }
}

/// With the shortcut, a time-invariant model gives the same results as the full
/// recursion (criteria, final covariance, traces) to 1e-12 relative — except the
/// filtered bound's traces where that bound grows without limit (1e-11, see
/// `same_values`).
#[test]
fn steady_state_shortcut_equals_full_recursion() {
    let refs = reference();
    for name in ["random10", "helicopter6", "cv2"] {
        let m = &refs["models"][name];
        let mut model = discrete_model(m, 30_000);
        // Buckets of 600 steps, most of them after the freeze.
        model["options"]["trace_points"] = json!(100);
        model["options"]["steady_state_shortcut"] = json!(true);
        let fast = run(model.clone());
        model["options"]["steady_state_shortcut"] = json!(false);
        let full = run(model);
        assert!(fast.steady_state.as_ref().unwrap().shortcut_used);
        assert!(!full.steady_state.as_ref().unwrap().shortcut_used);
        let close = |a: Option<f64>, b: Option<f64>, what: &str| match (a, b) {
            (Some(a), Some(b)) => assert!(rel(a, b) < 1e-12, "{name} {what}: {a} vs {b}"),
            (None, None) => {}
            _ => panic!("{name} {what}: {a:?} vs {b:?}"),
        };
        for set in ["bound", "covariance"] {
            let (f, g) = match set {
                "bound" => (&fast.criteria.bound, &full.criteria.bound),
                _ => (&fast.criteria.covariance, &full.criteria.covariance),
            };
            for (p, q) in f.per_state.iter().zip(&g.per_state) {
                close(p.yz, q.yz, &format!("{set} yz {}", p.state));
                close(p.zx, q.zx, &format!("{set} zx {}", p.state));
                close(p.yx, q.yx, &format!("{set} yx {}", p.state));
            }
            close(f.weighted.yx, g.weighted.yx, set);
        }
        assert!(max_rel(&fast.final_.covariance, &full.final_.covariance) < 1e-12);
        assert!(max_rel(&fast.final_.gain, &full.final_.gain) < 1e-12);
        // Every trace value (the frozen phase decimates the series constant there
        // once per bucket), null where the other is.
        let (a, b) = (
            serde_json::to_value(&fast.traces).unwrap(),
            serde_json::to_value(&full.traces).unwrap(),
        );
        let mut values = 0;
        let growing = full
            .warnings
            .iter()
            .any(|w| w.contains("bound (modulus procedure)"));
        let at = if growing {
            format!("!{name}")
        } else {
            name.to_string()
        };
        same_values(&a, &b, &mut values, &at);
        assert!(values > 1_000, "{name}: {values} trace values compared");
    }
}

/// `a` and `b` have the same shape, nulls and strings, and numbers within 1e-12
/// relative (of the larger; see the exception for a growing bound, marked by a
/// leading `!` in `at`); counts the numbers.
fn same_values(a: &Value, b: &Value, count: &mut usize, at: &str) {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            let d = (x - y).abs() / x.abs().max(y.abs()).max(f64::MIN_POSITIVE);
            // A bound the element-wise |h||A| makes grow without limit (a warning) never
            // contracts the frozen gain's difference (≤ 1e-13, STEADY_TOL) away: its
            // filtered series (χ, D^X, local ZX and YX) keep ≈ 2.5e-12 (random10).
            let bound_x = [".chi[", ".rel_x[", ".local_zx[", ".local_yx["]
                .iter()
                .any(|s| at.contains(s));
            let tol = if bound_x && at.starts_with('!') {
                1e-11
            } else {
                1e-12
            };
            assert!(d < tol, "{at}: {x} vs {y} ({d:e})");
            *count += 1;
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{at}");
            for (i, (x, y)) in x.iter().zip(y).enumerate() {
                same_values(x, y, count, &format!("{at}[{i}]"));
            }
        }
        (Value::Object(x), Value::Object(y)) => {
            assert_eq!(x.len(), y.len(), "{at}");
            for (k, x) in x {
                same_values(x, &y[k], count, &format!("{at}.{k}"));
            }
        }
        _ => assert_eq!(a, b, "{at}"),
    }
}

/// λ = Φ⁻¹((1+P)/2): at P = erf(k/√2) it is k (closed form); the textbook quantiles;
/// and statrs' inverse normal CDF (a second algorithm) over (0, 1).
#[test]
fn laplace_lambda_is_the_two_sided_normal_quantile() {
    use kea_core::analysis::laplace_lambda;
    use statrs::distribution::{ContinuousCDF, Normal};
    for (p, k) in [
        (0.682_689_492_137_085_9, 1.0),
        (0.954_499_736_103_641_6, 2.0),
        (0.997_300_203_936_739_8, 3.0),
    ] {
        assert!(
            rel(laplace_lambda(p), k) < 1e-14,
            "P = {p}: {}",
            laplace_lambda(p)
        );
    }
    assert!(rel(laplace_lambda(0.95), 1.959_963_984_540_054) < 1e-15);
    assert!(rel(laplace_lambda(0.99), 2.575_829_303_548_900_4) < 1e-15);
    let normal = Normal::standard();
    for i in 1..1000 {
        let p = i as f64 / 1000.0;
        let want = normal.inverse_cdf((1.0 + p) / 2.0);
        assert!(rel(laplace_lambda(p), want) < 1e-12, "P = {p}");
    }
    // Near 0, λ = P √(π/2) (1 + O(P²)) (erf(z) = 2z/√π (1 − z²/3 + …)): no rounding
    // of (1 + P)/2 to 1/2, down to the smallest normal P.
    for p in [1e-9, 1e-17, 1e-300, f64::MIN_POSITIVE] {
        let want = p * (std::f64::consts::PI / 2.0).sqrt();
        assert!(
            rel(laplace_lambda(p), want) < 1e-15,
            "P = {p}: {}",
            laplace_lambda(p)
        );
    }
    // Near 1 the tail keeps its accuracy: P = 1 − 1e-12 (so 1 − P = 9.999778782798785e-13
    // in f64), λ = Φ⁻¹(1 − (1 − P)/2) = 7.130509892879273 (scipy's norm.isf((1 − P)/2)).
    let p = 1.0 - 1e-12;
    assert!(
        rel(laplace_lambda(p), 7.130_509_892_879_273) < 1e-13,
        "{}",
        laplace_lambda(p)
    );
}

/// The largest |x| of the numbers in `v`.
fn largest(v: &Value) -> f64 {
    match v {
        Value::Number(x) => x.as_f64().unwrap_or(0.0).abs(),
        Value::Array(a) => a.iter().map(largest).fold(0.0, f64::max),
        Value::Object(o) => o.values().map(largest).fold(0.0, f64::max),
        _ => 0.0,
    }
}

/// Every member of `want` against the same member of `got`: nulls where nulls, numbers
/// to `tol` relative (to the larger of the two, or to 1e-6 of the largest number in the
/// enclosing array: an off-diagonal that cancels to 1e-17 is compared at its scale).
fn agree(path: &str, want: &Value, got: &Value, scale: f64, tol: f64, worst: &mut (f64, String)) {
    match (want, got) {
        (Value::Null, Value::Null) => {}
        (Value::Number(w), Value::Number(g)) => {
            let (w, g) = (w.as_f64().unwrap(), g.as_f64().unwrap());
            let e = (w - g).abs()
                / w.abs()
                    .max(g.abs())
                    .max(1e-6 * scale)
                    .max(f64::MIN_POSITIVE);
            assert!(
                e <= tol,
                "{path}: numpy {w:e}, kea {g:e} (relative {e:.1e})"
            );
            if e > worst.0 {
                *worst = (e, path.to_string());
            }
        }
        (Value::Array(w), Value::Array(g)) => {
            assert_eq!(w.len(), g.len(), "{path}: lengths");
            let scale = largest(want);
            for (i, (w, g)) in w.iter().zip(g).enumerate() {
                agree(&format!("{path}[{i}]"), w, g, scale, tol, worst);
            }
        }
        (Value::Object(w), Value::Object(g)) => {
            for (k, w) in w {
                let g = g
                    .get(k)
                    .unwrap_or_else(|| panic!("{path}.{k}: missing in kea's result"));
                agree(&format!("{path}.{k}"), w, g, largest(w), tol, worst);
            }
        }
        (Value::String(w), Value::String(g)) => assert_eq!(w, g, "{path}"),
        _ => panic!("{path}: numpy {want}, kea {got}"),
    }
}

/// kea against an independent implementation of METHOD §1 in numpy (tests/numpy/
/// kearef.py, written from METHOD.md and the README alone; its output committed by
/// tests/numpy/make_reference.py): the five presets at 2000 steps and fifteen random
/// models (N ≤ 4, expressions in t, phi/W, psi/V, gamma/g, pairs, schedules, weights).
/// y_B, ẏ_B, z_B, the final covariance, gain, η, χ and SKOs, and both criteria sets per
/// state (with excluded steps) and weighted, to 1e-9 relative.
#[test]
fn an_independent_numpy_implementation_agrees() {
    let text = include_str!("data/numpy_reference.json");
    let cases: Vec<Value> = serde_json::from_str(text).unwrap();
    assert_eq!(cases.len(), 20);
    let mut worst = (0.0, String::new());
    for case in &cases {
        let name = case["name"].as_str().unwrap();
        let model = model_from_value(case["model"].clone()).unwrap();
        let r = analyze(&model, &Default::default(), &mut NoProgress)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let got = serde_json::to_value(&r).unwrap();
        agree(name, &case["expected"], &got, 0.0, 1e-9, &mut worst);
    }
    eprintln!("largest difference {:.1e} at {}", worst.0, worst.1);
}
