//! The `kea` command line as a user runs it: a process, a model file, its output.

use kea_server::cli::MAX_THREADS;
use serde_json::{Value, json};
use std::process::Command;

const KEA: &str = env!("CARGO_BIN_EXE_kea");

/// `kea analyze FILE --json` with only the given one of the engine's build switches
/// (`KEA_NO_SIMD`, `KEA_NO_AVX512`) set, or none; the result without its wall-clock
/// timing.
fn analyze(file: &std::path::Path, switch: Option<&str>) -> Value {
    let mut cmd = Command::new(KEA);
    cmd.arg("analyze").arg(file).arg("--json");
    for var in ["KEA_NO_SIMD", "KEA_NO_AVX512"] {
        if switch == Some(var) {
            cmd.env(var, "1");
        } else {
            cmd.env_remove(var);
        }
    }
    let out = cmd.output().expect("kea runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut v: Value = serde_json::from_slice(&out.stdout).expect("JSON result");
    v.as_object_mut().expect("object").remove("timing");
    v
}

/// An n-state chain, its a(t) time-varying or constant, with measurements that mix
/// states and correlated measurement noise (the whitened path).
fn chain(n: usize, varying: bool) -> Value {
    let a: Vec<Vec<Value>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| match j {
                    _ if j == i && varying => {
                        json!(format!("-0.5 - 0.1*{i} + 0.2*sin(t + {i})"))
                    }
                    _ if j == i => json!(-0.5 - 0.1 * i as f64),
                    _ if j == i + 1 => json!(1.0),
                    _ => json!(0.0),
                })
                .collect()
        })
        .collect();
    let eye = |k: usize| -> Vec<Vec<f64>> {
        (0..k)
            .map(|i| (0..k).map(|j| f64::from(u8::from(i == j))).collect())
            .collect()
    };
    // 1 on the diagonal, `off` on the (cyclic) superdiagonal
    let bidiag = |off: f64| -> Vec<Vec<f64>> {
        (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| match j {
                        _ if j == i => 1.0,
                        _ if j == (i + 1) % n => off,
                        _ => 0.0,
                    })
                    .collect()
            })
            .collect()
    };
    let (c, gamma) = (bidiag(0.5), bidiag(0.3));
    json!({
        "kea_model": 1,
        "time": {"t0": 0.0, "t_end": 5.0, "steps": 3000},
        "system": {
            "states": (0..n).map(|i| format!("x{i}")).collect::<Vec<_>>(),
            "a": a, "b": eye(n), "phi": vec![0.3; n],
            "y0": vec![1.0; n], "eta0": vec![0.1; n]
        },
        "measurement": {
            "names": (0..n).map(|i| format!("z{i}")).collect::<Vec<_>>(),
            "c": c, "gamma": gamma, "psi": vec![1e-2; n]
        }
    })
}

/// The engine runs an AVX-512 or AVX2 + FMA build of its loop where the CPU has
/// them; each must give the same bits as the baseline build (`KEA_NO_SIMD=1`). The
/// files: the seed (N = 1), the helicopter (N = 6, frozen at its steady state), the
/// benchmarks' time-invariant 10-state chain (frozen) and a 13-state time-varying
/// chain (the runtime-sized kernels). On a CPU without AVX-512 the widest and the
/// AVX2 runs take the same path, without AVX2 all three do, and this test checks less.
#[test]
fn simd_builds_agree_bitwise() {
    let dir = tempfile::tempdir().unwrap();
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let (big, frozen) = (
        dir.path().join("chain13.json"),
        dir.path().join("chain10.json"),
    );
    std::fs::write(&big, chain(13, true).to_string()).unwrap();
    std::fs::write(&frozen, chain(10, false).to_string()).unwrap();
    for file in [
        root.join("presets/seed-example.json"),
        root.join("presets/helicopter-range.json"),
        frozen,
        big,
    ] {
        let base = analyze(&file, Some("KEA_NO_SIMD"));
        assert!(
            base["criteria"]["covariance"]["weighted"]["yx"].is_number(),
            "{file:?}: {base}"
        );
        if file.ends_with("chain10.json") {
            assert!(base["steady_state"].is_object(), "the frozen phase is run");
        }
        assert_eq!(analyze(&file, None), base, "{file:?}: the widest build");
        assert_eq!(
            analyze(&file, Some("KEA_NO_AVX512")),
            base,
            "{file:?}: AVX2"
        );
    }
}

/// `kea` with these arguments, `KEA_MAX_WORK` unset: (exit code, stdout, stderr).
fn kea(args: &[&str]) -> (i32, String, String) {
    run(Command::new(KEA).args(args))
}

/// `kea analyze MODEL --csv CSV`: (exit code, stdout, stderr).
fn analyze_csv(model: &str, csv: &std::path::Path) -> (i32, String, String) {
    kea(&["analyze", model, "--csv", csv.to_str().unwrap()])
}

/// Run a `kea` command, `KEA_MAX_WORK` unset: (exit code, stdout, stderr).
fn run(cmd: &mut Command) -> (i32, String, String) {
    let out = cmd.env_remove("KEA_MAX_WORK").output().expect("kea runs");
    let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    (
        out.status.code().unwrap_or(-1),
        text(&out.stdout),
        text(&out.stderr),
    )
}

/// Work above `--max-work` (the server's estimate and default) is refused before
/// anything runs, naming the field that drives it and the flag that lifts it.
/// The Monte Carlo's command is `kea monte-carlo`; `kea simulate`, its former name, is
/// its alias (listed in the help), the same command with the same output.
#[test]
fn simulate_is_an_alias_of_monte_carlo() {
    let (code, help, _) = kea(&["--help"]);
    assert_eq!(code, 0);
    let line = help
        .lines()
        .find(|l| l.trim_start().starts_with("monte-carlo"))
        .unwrap_or_else(|| panic!("no monte-carlo in:\n{help}"));
    assert!(line.contains("[alias: simulate]"), "{line}");
    assert!(
        !help.lines().any(|l| l.trim_start().starts_with("simulate")),
        "{help}"
    );
    let (code, usage, _) = kea(&["simulate", "--help"]);
    assert_eq!(code, 0);
    assert_eq!(usage, kea(&["monte-carlo", "--help"]).1);
    let args = ["preset:cv-tracker", "--runs", "20", "--seed", "2"];
    let report = |command: &str| {
        let (code, text, err) = kea(&[&[command][..], &args[..]].concat());
        assert_eq!(code, 0, "{err}");
        // (but for the wall-clock time in the first line)
        text.lines()
            .filter(|l| !l.contains(" ms, "))
            .map(str::to_owned)
            .collect::<Vec<_>>()
    };
    assert_eq!(report("simulate"), report("monte-carlo"));
}

#[test]
fn work_above_the_limit_is_refused_up_front() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let seed = root.join("presets/seed-example.json");
    let seed = seed.to_str().unwrap();
    // The seed example: D = 10⁶ steps of N = 1, 240 units each (217 for the
    // recursion, 23 for its inputs and its one expression in t), and once 7 parses of
    // 25 000.
    let (code, out, err) = kea(&["analyze", seed, "--max-work", "1e8"]);
    assert_eq!(code, 2, "{err}");
    assert!(out.is_empty(), "{out}");
    assert!(
        err.starts_with("time.steps: estimated work 2.405e8 (D = 1000000 steps")
            && err.contains("+ once 175000 (7 expressions parsed)"),
        "{err}"
    );
    assert!(err.contains("above --max-work 1.000e8"), "{err}");
    // 2.35·10¹⁵ units of Monte Carlo: above the default 1e12, refused at once.
    let (code, _, err) = kea(&["monte-carlo", "preset:seed-example", "--runs", "100000000"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.starts_with("runs: estimated work 2.350e15"), "{err}");
    assert!(err.contains("above --max-work 1.000e12"), "{err}");
    // A limit must be a positive number.
    let (code, _, err) = kea(&["analyze", seed, "--max-work", "0"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("expected a positive number"), "{err}");
    // Within the limit (here the environment's), the analysis runs as before.
    let out = Command::new(KEA)
        .args(["analyze", seed, "--json"])
        .env("KEA_MAX_WORK", "2.5e8")
        .output()
        .expect("kea runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: Value = serde_json::from_slice(&out.stdout).expect("JSON result");
    assert_eq!(v["steps"], 1_000_000);
}

/// `kea analyze preset:NAME` is the preset's file; `--csv` writes the result's traces,
/// one row per trace point, columns `t` then `<series>:<state>`.
#[test]
fn analyze_a_preset_by_name_and_write_its_traces_as_csv() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let by_file = analyze(&root.join("presets/cv-tracker.json"), None);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("traces.csv");
    let (code, out, err) = kea(&[
        "analyze",
        "preset:cv-tracker",
        "--json",
        "--csv",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let mut by_name: Value = serde_json::from_str(&out).expect("JSON result");
    by_name.as_object_mut().unwrap().remove("timing");
    assert_eq!(by_name, by_file);

    let text = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<Vec<&str>> = text.lines().map(|l| l.split(',').collect()).collect();
    let t = by_file["traces"]["t"].as_array().unwrap();
    assert_eq!(rows.len(), 1 + t.len());
    let col = |name: &str| rows[0].iter().position(|h| *h == name).expect(name);
    let (ct, cv) = (col("t"), col("potential_sko:velocity"));
    let state = by_file["traces"]["states"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["state"] == "velocity")
        .unwrap();
    for i in [0, t.len() / 2, t.len() - 1] {
        let cell = |c: usize| rows[1 + i][c].parse::<f64>().unwrap();
        assert_eq!(cell(ct), t[i].as_f64().unwrap(), "row {i}");
        assert_eq!(
            cell(cv),
            state["potential_sko"][i].as_f64().unwrap(),
            "row {i}"
        );
    }

    let (code, _, err) = kea(&["analyze", "preset:no-such-preset"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.starts_with("no preset \"no-such-preset\" (presets: "),
        "{err}"
    );
}

/// Input the user must fix exits 2 before any work, with the file or flag named: a
/// preset's name given as a file gets a hint, text that is not JSON names its file, a
/// `--csv` path that cannot be written is refused before the run; synthesize takes
/// `--model preset:NAME` like the others' `preset:NAME`, and says where a model goes.
#[test]
fn input_errors_name_their_source_and_exit_2_up_front() {
    let (code, _, err) = kea(&["analyze", "cv-tracker"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("(for the preset, write preset:cv-tracker)"),
        "{err}"
    );
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, "{\"time\": ").unwrap();
    let bad = bad.to_str().unwrap();
    let (code, _, err) = kea(&["analyze", bad]);
    assert_eq!(code, 2, "{err}");
    assert!(err.starts_with(&format!("{bad}: not valid JSON")), "{err}");
    // `-` is stdin.
    let mut child = Command::new(KEA)
        .args(["analyze", "-", "--json"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("kea runs");
    let preset = kea(&["preset", "cv-tracker"]).1;
    std::io::Write::write_all(&mut child.stdin.take().unwrap(), preset.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    let mut piped: Value = serde_json::from_slice(&out.stdout).expect("JSON result");
    piped.as_object_mut().unwrap().remove("timing");
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    assert_eq!(piped, analyze(&root.join("presets/cv-tracker.json"), None));
    let nowhere = dir.path().join("no/such/dir/t.csv");
    let (code, out, err) = analyze_csv("preset:seed-example", &nowhere);
    assert_eq!(code, 2, "{err}");
    assert!(out.is_empty(), "ran before refusing: {out}");
    assert!(err.starts_with("cannot write"), "{err}");

    let request = dir.path().join("request.json");
    std::fs::write(
        &request,
        r#"{"target": {"criterion": "yx", "criteria": "covariance", "threshold": 2}, "mode": {"grid": {"params": [{"name": "r", "values": [0.5, 1]}]}}}"#,
    )
    .unwrap();
    let request = request.to_str().unwrap();
    let (code, _, err) = kea(&["synthesize", request]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.starts_with("model: missing: give the model in the request, or with --model"),
        "{err}"
    );
    let by_model = kea(&[
        "synthesize",
        request,
        "--model",
        "preset:cv-tracker",
        "--json",
    ]);
    let by_preset = kea(&["synthesize", request, "--preset", "cv-tracker", "--json"]);
    assert_eq!(by_model.0, 0, "{}", by_model.2);
    let strip = |s: &str| {
        let mut v: Value = serde_json::from_str(s).expect("JSON result");
        v.as_object_mut().unwrap().remove("timing");
        v
    };
    assert_eq!(strip(&by_model.1), strip(&by_preset.1));
}

/// `--threads` (and the server's `--workers`) take 0 (every core) to
/// [`MAX_THREADS`]: more is refused up front with the limit named, not tried (each
/// thread reserves a stack).
#[test]
fn threads_above_the_cap_are_refused() {
    // (The server's address and data directory are such that, were the cap not
    // checked, it would fail at once rather than serve.)
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let data = data.to_str().unwrap();
    let (cap, above) = (MAX_THREADS.to_string(), (MAX_THREADS + 1).to_string());
    for cmd in [
        &[
            "monte-carlo",
            "preset:cv-tracker",
            "--runs",
            "2",
            "--threads",
            "100000",
        ][..],
        &["synthesize", "no-such-request.json", "--threads", &above][..],
        &[
            "serve",
            "--workers",
            "1000",
            "--addr",
            "no-such-address",
            "--data-dir",
            data,
        ][..],
    ] {
        let (code, out, err) = kea(cmd);
        assert_eq!(code, 2, "{cmd:?}: {err}");
        assert!(out.is_empty(), "{cmd:?} ran: {out}");
        assert!(
            err.contains(&format!("at most {cap} threads (0: every core), got")),
            "{cmd:?}: {err}"
        );
    }
    let (code, _, err) = kea(&["monte-carlo", "preset:cv-tracker", "--threads", "many"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("expected a whole number of threads"), "{err}");
    let (code, out, err) = kea(&[
        "monte-carlo",
        "preset:cv-tracker",
        "--runs",
        "2",
        "--threads",
        &cap,
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("\"runs\""), "{out}");
}

/// A synthesis request that finds its point (exit 0) on preset:cv-tracker.
const FOUND_REQUEST: &str = r#"{"target": {"criterion": "yx", "criteria": "covariance", "threshold": 2}, "mode": {"grid": {"params": [{"name": "r", "values": [0.5, 1]}]}}}"#;

/// Every command's output goes through one checked write: stdout that cannot be
/// written (a full disk) is said on stderr and exits 1, never a panic or a silent 0;
/// a `--csv` file that fails while written is the same failure (not input to fix). A
/// closed pipe (`kea … | head`) ends the output quietly, exit 0.
#[cfg(target_os = "linux")]
#[test]
fn output_that_cannot_be_written_is_a_failure_and_a_closed_pipe_is_not() {
    let dir = tempfile::tempdir().unwrap();
    let request = dir.path().join("request.json");
    std::fs::write(&request, FOUND_REQUEST).unwrap();
    let request = request.to_str().unwrap();
    let commands: [&[&str]; 11] = [
        &["presets"],
        &["presets", "--json"],
        &["preset", "cv-tracker"],
        &["analyze", "preset:cv-tracker"],
        &["analyze", "preset:cv-tracker", "--json"],
        &["monte-carlo", "preset:cv-tracker", "--runs", "20"],
        // `simulate`: the former name of `monte-carlo`, still read as it.
        &["simulate", "preset:cv-tracker", "--runs", "20", "--json"],
        &["synthesize", request, "--preset", "cv-tracker"],
        &["synthesize", request, "--preset", "cv-tracker", "--json"],
        &["analyze", "preset:cv-tracker", "--csv", "-"],
        &["--help"],
    ];
    for args in commands {
        let full = std::fs::OpenOptions::new()
            .write(true)
            .open("/dev/full")
            .unwrap();
        let (code, _, err) = run(Command::new(KEA).args(args).stdout(full));
        assert_eq!(code, 1, "{args:?}: {err}");
        assert_eq!(
            err, "cannot write to stdout: No space left on device (os error 28)\n",
            "{args:?}"
        );

        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let (code, _, err) = run(Command::new(KEA).args(args).stdout(writer));
        assert_eq!(code, 0, "{args:?}: {err}");
        assert!(err.is_empty(), "{args:?}: {err}");
    }
    let (code, _, err) = kea(&["analyze", "preset:cv-tracker", "--csv", "/dev/full"]);
    assert_eq!(code, 1, "{err}");
    assert!(err.starts_with("cannot write /dev/full: "), "{err}");
}

/// The Monte Carlo report writes its numbers as the analysis table does: exponent form
/// where four decimals would be unreadable (1.4281e25, not 26 digits; 1.2551e-5, not
/// 0.0000), each close to the JSON's value, and `—` for anything undefined — never NaN.
#[test]
fn monte_carlo_report_numbers_are_readable_and_undefined_is_a_dash() {
    let cases: [&[&str]; 2] = [
        &["monte-carlo", "preset:helicopter-hover", "--runs", "100"],
        &[
            "monte-carlo",
            "preset:cv-tracker",
            "--set",
            "r=1e7",
            "--runs",
            "20",
        ],
    ];
    for args in cases {
        let (code, text, err) = kea(args);
        assert_eq!(code, 0, "{err}");
        let (code, json, err) = kea(&[args, &["--json"]].concat());
        assert_eq!(code, 0, "{err}");
        let json: Value = serde_json::from_str(&json).unwrap();
        for (row, key) in [("F_YZ ", "yz"), ("F_ZX ", "zx"), ("F_YX ", "yx")] {
            let line = text.lines().find(|l| l.starts_with(row)).expect(row);
            let cells: Vec<&str> = line.split_whitespace().skip(1).collect();
            for (cell, set) in cells.iter().zip(["bound", "covariance", "monte_carlo"]) {
                assert!(cell.len() <= 10, "{args:?}: {line}");
                let want = &json["criteria"][set]["weighted"][key];
                match want.as_f64() {
                    Some(want) => {
                        let got: f64 = cell.parse().expect(line);
                        assert!(
                            (got - want).abs() <= 1e-3 * want.abs(),
                            "{args:?} {set} {key}: {got} against {want}"
                        );
                    }
                    None => assert_eq!(*cell, "—", "{args:?}: {line}"),
                }
            }
        }
    }

    // No measurement is ever available: the NIS check has no average and no band.
    let dir = tempfile::tempdir().unwrap();
    let mut model: Value = serde_json::from_str(&kea(&["preset", "helicopter-hover"]).1).unwrap();
    let n = model["measurement"]["names"].as_array().unwrap().len();
    model["measurement"]["schedule"] = json!(vec![json!({"when": "0"}); n]);
    let file = dir.path().join("unmeasured.json");
    std::fs::write(&file, model.to_string()).unwrap();
    let (code, text, err) = kea(&["monte-carlo", file.to_str().unwrap(), "--runs", "20"]);
    assert_eq!(code, 0, "{err}");
    let nis = text
        .lines()
        .find(|l| l.starts_with("NIS:"))
        .expect("NIS line");
    assert!(nis.contains("band [—, —]"), "{nis}");
    for bad in ["NaN", "inf"] {
        assert!(!text.contains(bad), "{text}");
    }

    // A time for reading, not 300 digits.
    let mut model: Value = serde_json::from_str(&kea(&["preset", "cv-tracker"]).1).unwrap();
    model["time"]["t_end"] = json!(1e-300);
    let file = dir.path().join("brief.json");
    std::fs::write(&file, model.to_string()).unwrap();
    let (code, text, err) = kea(&["monte-carlo", file.to_str().unwrap(), "--runs", "20"]);
    assert_eq!(code, 0, "{err}");
    assert!(text.contains("\nAt t = 1e-300: "), "{text}");
}

/// `--csv -` writes the CSV to stdout in place of the table (no file named `-`), and is
/// refused with `--json`; a `--csv` path that is the model file is refused (exit 2)
/// and the model left as it was — for analyze and monte-carlo alike.
#[test]
fn csv_to_stdout_and_never_over_the_model() {
    let dir = tempfile::tempdir().unwrap();
    let by_file = dir.path().join("traces.csv");
    let (code, _, err) = analyze_csv("preset:cv-tracker", &by_file);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = run(Command::new(KEA)
        .args(["analyze", "preset:cv-tracker", "--csv", "-"])
        .current_dir(dir.path()));
    assert_eq!(code, 0, "{err}");
    assert_eq!(out, std::fs::read_to_string(&by_file).unwrap());
    assert!(!dir.path().join("-").exists());
    let (code, out, err) = run(Command::new(KEA)
        .args([
            "monte-carlo",
            "preset:cv-tracker",
            "--runs",
            "20",
            "--csv",
            "-",
        ])
        .current_dir(dir.path()));
    assert_eq!(code, 0, "{err}");
    assert!(
        out.starts_with("t,") && !out.contains("Monte Carlo"),
        "{out}"
    );
    assert!(!dir.path().join("-").exists());

    let model = dir.path().join("m.json");
    let text = kea(&["preset", "cv-tracker"]).1;
    std::fs::write(&model, &text).unwrap();
    let same = dir.path().join(".").join("m.json");
    let (model, same) = (model.to_str().unwrap(), same.to_str().unwrap());
    for cmd in ["analyze", "monte-carlo"] {
        let (code, out, err) = kea(&[cmd, "preset:cv-tracker", "--json", "--csv", "-"]);
        assert_eq!(code, 2, "{err}");
        assert!(out.is_empty(), "{out}");
        assert!(
            err.starts_with("--csv -: stdout carries the --json result"),
            "{err}"
        );
        let (code, _, err) = kea(&[cmd, model, "--csv", same]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("that is the model file"), "{err}");
        assert_eq!(std::fs::read_to_string(model).unwrap(), text);
    }
}

/// stdin can be read once: a synthesis request and its `--model` both `-` is refused.
#[test]
fn synthesize_refuses_stdin_twice() {
    let mut child = Command::new(KEA)
        .args(["synthesize", "-", "--model", "-"])
        .stdin(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("kea runs");
    // (kea may refuse before reading: a closed pipe here is fine.)
    let _ = std::io::Write::write_all(&mut child.stdin.take().unwrap(), FOUND_REQUEST.as_bytes());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("stdin can be read once"), "{err}");
}

/// A `--set` name given twice is refused (exit 2), as a key given twice in JSON is,
/// in every command that takes `--set`; once is fine.
#[test]
fn a_set_name_given_twice_is_refused() {
    for command in ["analyze", "monte-carlo"] {
        let (code, _, err) = kea(&[command, "preset:cv-tracker", "--set", "q=1", "--set", "q=2"]);
        assert_eq!(code, 2, "{command}: {err}");
        assert!(
            err.contains("--set q is given twice (q=1, then q=2)"),
            "{command}: {err}"
        );
    }
    let (code, _, err) = kea(&[
        "analyze",
        "preset:cv-tracker",
        "--set",
        "q=1",
        "--set",
        "r=2",
    ]);
    assert_eq!(code, 0, "{err}");
}

/// The CLI read its input whole, without a limit: `kea analyze /dev/zero` grew until
/// memory ran out. Beyond 64 MiB it is refused (exit 2), from a file or stdin.
#[test]
fn an_endless_input_is_refused_at_the_read_limit() {
    let (code, _, err) = kea(&["analyze", "/dev/zero"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("cannot read /dev/zero: it is larger than 64 MiB, beyond what kea reads"),
        "{err}"
    );
    let mut child = Command::new(KEA)
        .args(["analyze", "-"])
        .stdin(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let feeder = std::thread::spawn(move || {
        let block = vec![b' '; 1 << 20];
        // Until kea stops reading (a broken pipe), or far past the limit.
        for _ in 0..200 {
            if std::io::Write::write_all(&mut stdin, &block).is_err() {
                break;
            }
        }
    });
    let out = child.wait_with_output().unwrap();
    feeder.join().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("cannot read stdin: it is larger than 64 MiB"),
        "{err}"
    );
}

/// A `--set` value below the smallest f64 was read as 0 without a word (`r=1e-400`
/// became a noise-free sensor; `r=1e-200` is refused by the SKO's range).
#[test]
fn a_set_value_that_underflows_is_refused() {
    let (code, _, err) = kea(&["analyze", "preset:cv-tracker", "--set", "r=1e-400"]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains(
            "`r=1e-400`: the value is below the smallest f64 (≈ 4.9e-324) and would be read as 0"
        ),
        "{err}"
    );
    let (code, _, err) = kea(&["analyze", "preset:cv-tracker", "--set", "r=0e-400"]);
    assert_eq!(code, 0, "{err}");
}

/// A model that diverges: A = 1 + aΔt = 1 − 10⁴ at Δt = 0.01, so its covariance
/// overflows within a few dozen steps and the run fails (exit 1).
const DIVERGING_MODEL: &str = r#"{
  "time": {"t0": 0, "t_end": 1, "steps": 100},
  "system": {"states": ["x"], "a": [[-1e6]], "b": [[1]], "y0": [1], "eta0": [1], "phi": [1]},
  "measurement": {"names": ["z"], "c": [[1]], "gamma": [[1]], "psi": [1]}
}"#;

/// The names in a directory, sorted (to see that no temporary file is left behind).
fn names_in(dir: &std::path::Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// A `--csv` file is replaced only by a finished run's CSV: a run that fails, or is
/// killed, leaves the file it named as it was (no truncation up front) and no
/// temporary file beside it — for analyze and monte-carlo alike.
#[test]
fn a_failed_or_killed_run_leaves_the_csv_file_as_it_was() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("diverging.json");
    std::fs::write(&model, DIVERGING_MODEL).unwrap();
    let csv = dir.path().join("traces.csv");
    let before = "t,y:x\n0,1\n";
    std::fs::write(&csv, before).unwrap();
    let (model, csv_arg) = (model.to_str().unwrap(), csv.to_str().unwrap());
    for args in [
        &["analyze", model, "--csv", csv_arg][..],
        &["monte-carlo", model, "--runs", "20", "--csv", csv_arg],
    ] {
        let (code, out, err) = kea(args);
        assert_eq!(code, 1, "{args:?}: the model should diverge: {out}{err}");
        assert_eq!(std::fs::read_to_string(&csv).unwrap(), before, "{args:?}");
        assert_eq!(
            names_in(dir.path()),
            ["diverging.json", "traces.csv"],
            "{args:?}"
        );
    }

    // Killed in the middle of a run of seconds (the seed example at 10⁷ steps).
    let long = dir.path().join("long.json");
    let mut value: Value = serde_json::from_str(&kea(&["preset", "seed-example"]).1).unwrap();
    value["time"]["steps"] = json!(10_000_000);
    std::fs::write(&long, value.to_string()).unwrap();
    let mut child = Command::new(KEA)
        .args(["analyze", long.to_str().unwrap(), "--csv", csv_arg])
        .env_remove("KEA_MAX_WORK")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("kea runs");
    std::thread::sleep(std::time::Duration::from_millis(150));
    let _ = child.kill();
    let status = child.wait().unwrap();
    assert!(!status.success(), "the run finished before it was killed");
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), before);
    assert_eq!(
        names_in(dir.path()),
        ["diverging.json", "long.json", "traces.csv"]
    );
}

/// A finished run replaces the `--csv` file whole: through a symbolic link the file
/// it points to is written (the link stays), and an existing file keeps its mode.
#[cfg(unix)]
#[test]
fn a_finished_run_replaces_the_csv_file_keeping_its_mode_and_links() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let real = dir.path().join("real.csv");
    std::fs::write(&real, "old\n").unwrap();
    std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o640)).unwrap();
    let link = dir.path().join("link.csv");
    std::os::unix::fs::symlink("real.csv", &link).unwrap();
    let (code, expected, err) = kea(&["analyze", "preset:cv-tracker", "--csv", "-"]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = analyze_csv("preset:cv-tracker", &link);
    assert_eq!(code, 0, "{err}");
    assert!(link.symlink_metadata().unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read_to_string(&real).unwrap(), expected);
    let mode = real.metadata().unwrap().permissions().mode() & 0o777;
    assert_eq!(mode, 0o640);
    assert_eq!(names_in(dir.path()), ["link.csv", "real.csv"]);
    // A directory, or a file in one that is missing, is refused before the run; the
    // message names the path given, not the temporary file.
    let dir_arg = dir.path().to_str().unwrap();
    let (code, out, err) = kea(&["analyze", "preset:cv-tracker", "--csv", dir_arg]);
    assert_eq!(code, 2, "{err}");
    assert!(out.is_empty(), "ran before refusing: {out}");
    assert_eq!(
        err,
        format!("cannot write {dir_arg}: Is a directory (os error 21)\n")
    );
    let nowhere = dir.path().join("no/such/t.csv");
    let nowhere = nowhere.to_str().unwrap();
    let (code, _, err) = kea(&["analyze", "preset:cv-tracker", "--csv", nowhere]);
    assert_eq!(code, 2, "{err}");
    assert_eq!(
        err,
        format!("cannot write {nowhere}: No such file or directory (os error 2)\n")
    );
}

/// A synthesis `--set` name that the request's own `set` also gives is refused
/// (exit 2) with both places named, as a `--set` name given twice is, rather than
/// the flag silently winning; a name only one of them gives is fine.
#[test]
fn synthesize_refuses_a_set_name_also_in_the_request() {
    let dir = tempfile::tempdir().unwrap();
    let request = dir.path().join("request.json");
    let mut value: Value = serde_json::from_str(FOUND_REQUEST).unwrap();
    value["set"] = json!({"q": 1});
    std::fs::write(&request, value.to_string()).unwrap();
    let request = request.to_str().unwrap();
    let (code, out, err) = kea(&[
        "synthesize",
        request,
        "--preset",
        "cv-tracker",
        "--set",
        "q=2",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(out.is_empty(), "ran before refusing: {out}");
    assert!(
        err.contains("--set q=2") && err.contains("set.q = 1"),
        "{err}"
    );
    value["set"] = json!({});
    std::fs::write(request, value.to_string()).unwrap();
    let (code, _, err) = kea(&[
        "synthesize",
        request,
        "--preset",
        "cv-tracker",
        "--set",
        "q=2",
    ]);
    assert_eq!(code, 0, "{err}");
}

/// A model file that starts with a UTF-8 byte-order mark (as Windows editors write
/// it) reads as the same file without one — from a file and from stdin.
#[test]
fn a_utf8_byte_order_mark_is_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let text = kea(&["preset", "cv-tracker"]).1;
    let plain = dir.path().join("plain.json");
    std::fs::write(&plain, &text).unwrap();
    let with_bom = dir.path().join("bom.json");
    std::fs::write(&with_bom, format!("\u{feff}{text}")).unwrap();
    assert_eq!(analyze(&with_bom, None), analyze(&plain, None));

    let mut child = Command::new(KEA)
        .args(["analyze", "-"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("kea runs");
    std::io::Write::write_all(
        &mut child.stdin.take().unwrap(),
        format!("\u{feff}{text}").as_bytes(),
    )
    .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A model saved as UTF-16 (PowerShell's `>` writes it so) was refused with "stream
/// did not contain valid UTF-8"; now the message says what the text is and what to do.
#[test]
fn a_utf16_file_is_named_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let text = kea(&["preset", "cv-tracker"]).1;
    let path = dir.path().join("utf16.json");
    let bytes: Vec<u8> = "\u{feff}"
        .chars()
        .chain(text.chars())
        .collect::<String>()
        .encode_utf16()
        .flat_map(u16::to_le_bytes)
        .collect();
    std::fs::write(&path, bytes).unwrap();
    let (code, _, err) = kea(&["analyze", path.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains(
            "not valid JSON: the text is UTF-16 (little-endian, with a byte-order mark), and JSON is read as UTF-8 (RFC 8259 §8.1): save it as UTF-8"
        ),
        "{err}"
    );
}

/// A grid without `cost_order` is a `table` (exit 0) when some cell meets the target,
/// and `not_found` (exit 1) when none does, as with a cost order (docs/synthesis.md).
#[test]
fn a_grid_no_cell_of_which_meets_the_target_is_not_found() {
    let dir = tempfile::tempdir().unwrap();
    let request = dir.path().join("request.json");
    let mut value: Value = serde_json::from_str(FOUND_REQUEST).unwrap();
    for (threshold, code, status) in [(2.0, 0, "table"), (1e9, 1, "not_found")] {
        value["target"]["threshold"] = json!(threshold);
        std::fs::write(&request, value.to_string()).unwrap();
        let (got, out, err) = kea(&[
            "synthesize",
            request.to_str().unwrap(),
            "--preset",
            "cv-tracker",
            "--json",
        ]);
        assert_eq!(got, code, "threshold {threshold}: {err}");
        let v: Value = serde_json::from_str(&out).expect("JSON result");
        assert_eq!(v["status"], status, "threshold {threshold}");
    }
}

/// `kea identify` on the example request: its CSV read relative to the request file,
/// the optimum and standard errors an independent implementation found for this data
/// (tests/data/identification/case_b_oscillator.expected.json: θ̂ and the sample
/// information's standard errors); `--method` replaces the request's; a CSV that is not
/// there, or a bad cell in it, is input to fix (exit 2) with the file, row and column.
#[test]
fn identify_reads_the_request_and_its_csv() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let example = root.join("examples/identification/oscillator.json");
    let example = example.to_str().unwrap();
    let (code, out, err) = kea(&["identify", example, "--json"]);
    assert_eq!(code, 0, "{err}");
    let r: Value = serde_json::from_str(&out).unwrap();
    let reference = [
        ("r", 0.9634378830434038, 0.006262557695822333),
        ("w", 0.30180822241345795, 0.007310165276882946),
        ("sv", 0.5323224117654461, 0.015918323695359088),
    ];
    for (name, value, se) in reference {
        let e = &r["estimate"][name];
        assert!(
            (e["value"].as_f64().unwrap() - value).abs() < 1e-6,
            "{name}: {e}"
        );
        assert!(
            (e["std_error"].as_f64().unwrap() - se).abs() < 1e-5 * se,
            "{name}: {e}"
        );
    }
    assert_eq!(
        (&r["converged"], &r["method"]),
        (&json!(true), &json!("scoring"))
    );
    let (code, out, err) = kea(&["identify", example, "--method", "conjugate"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("conjugate directions: converged"), "{out}");
    // The data file missing, then a bad cell in it.
    let dir = tempfile::tempdir().unwrap();
    let mut request: Value =
        serde_json::from_str(&std::fs::read_to_string(example).unwrap()).unwrap();
    request["data"] = json!({"csv": "data.csv"});
    let file = dir.path().join("request.json");
    std::fs::write(&file, request.to_string()).unwrap();
    let (code, _, err) = kea(&["identify", file.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.starts_with("data.csv: cannot read"), "{err}");
    std::fs::write(
        dir.path().join("data.csv"),
        "t,position_meas\n1,0.5\n2,abc\n",
    )
    .unwrap();
    let (code, _, err) = kea(&["identify", file.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(
        err.contains(
            "data.csv_text: line 3 (data row 2), column \"position_meas\": \"abc\" is not a number"
        ),
        "{err}"
    );
}

/// `kea identify --data-csv FILE` writes the data the fit used — here simulated by the
/// request's `data.simulate` — in the format `data.csv` reads, to the bit: fitting that
/// file gives the same result document as fitting the simulation.
#[test]
fn identify_writes_its_simulated_data_as_a_csv_that_reads_back_to_the_same_fit() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let example = root.join("examples/identification/oscillator.json");
    let mut request: Value =
        serde_json::from_str(&std::fs::read_to_string(example).unwrap()).unwrap();
    request["data"] = json!({"simulate": {"seed": 11}});
    let dir = tempfile::tempdir().unwrap();
    let simulated = dir.path().join("simulated.json");
    std::fs::write(&simulated, request.to_string()).unwrap();
    let csv = dir.path().join("data.csv");
    let args = [
        "identify",
        simulated.to_str().unwrap(),
        "--json",
        "--data-csv",
        csv.to_str().unwrap(),
    ];
    let (code, first, err) = kea(&args);
    assert_eq!(code, 0, "{err}");
    assert!(
        std::fs::read_to_string(&csv)
            .unwrap()
            .starts_with("t,position_meas\n1,")
    );
    request["data"] = json!({"csv": "data.csv"});
    let from_file = dir.path().join("from_file.json");
    std::fs::write(&from_file, request.to_string()).unwrap();
    let (code, second, err) = kea(&["identify", from_file.to_str().unwrap(), "--json"]);
    assert_eq!(code, 0, "{err}");
    let strip = |text: &str| {
        let mut v: Value = serde_json::from_str(text).unwrap();
        v.as_object_mut().unwrap().remove("timing");
        v
    };
    assert_eq!(strip(&first), strip(&second));
}
