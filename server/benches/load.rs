//! Load benchmark of `kea serve` (figures in BENCHMARKS.md, `## Server`):
//!
//! 1. small synchronous analyses (N = 2, D = 1000: the cv-tracker preset) with `wrk`
//!    (Debian: `apt-get install -y wrk`): requests/s and latency percentiles;
//! 2. job throughput for D = 10⁵ (cv-tracker, no steady-state shortcut): jobs/s from
//!    the first submission to the last completion.
//!
//! Run: `cargo bench -p kea-server --bench load` (release build). Options by
//! environment: KEA_BENCH_SECONDS (default 10), KEA_BENCH_CONNECTIONS (64),
//! KEA_BENCH_JOBS (100), KEA_BENCH_TRACE_POINTS (the preset's 1000).

use serde_json::{Value, json};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    if std::env::args().any(|a| a == "--list") {
        return; // `cargo test --benches` asks for a list; nothing to list.
    }
    let seconds = env_or("KEA_BENCH_SECONDS", 10);
    let connections = env_or("KEA_BENCH_CONNECTIONS", 64);
    let jobs = env_or("KEA_BENCH_JOBS", 100);
    let dir = tempfile::tempdir().unwrap();
    let mut server = Command::new(env!("CARGO_BIN_EXE_kea"))
        .args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
        .arg(dir.path())
        .env("KEA_LOG", "warn")
        .env_remove("KEA_TOKEN")
        .stdout(Stdio::piped())
        .spawn()
        .expect("start kea serve");
    let line = BufReader::new(server.stdout.take().unwrap())
        .lines()
        .next()
        .unwrap()
        .unwrap();
    let base = line.strip_prefix("kea: listening on ").unwrap().to_string();
    let mut model: Value =
        serde_json::from_str(kea_core::presets::get_json("cv-tracker").unwrap()).unwrap();
    // Fewer trace points = a smaller response (the preset's 1000 make ~350 kB of JSON).
    if let Ok(tp) = std::env::var("KEA_BENCH_TRACE_POINTS") {
        model["options"]["trace_points"] = tp.parse::<u64>().expect("a count").into();
    }
    assert_eq!(model["time"]["steps"], 1000);
    println!(
        "server {base}, {} cores",
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );

    // 1. Synchronous analyses with wrk.
    let body = json!({ "model": model }).to_string();
    let script = dir.path().join("post.lua");
    std::fs::write(
        &script,
        format!(
            "wrk.method = \"POST\"\nwrk.headers[\"Content-Type\"] = \"application/json\"\nwrk.body = {}\n",
            lua_string(&body)
        ),
    )
    .unwrap();
    let out = Command::new("wrk")
        .args([
            "-t",
            "2",
            "-c",
            &connections.to_string(),
            "-d",
            &format!("{seconds}s"),
            "--latency",
            "-s",
        ])
        .arg(&script)
        .arg(format!("{base}/v1/analyze"))
        .output()
        .expect("run wrk (apt-get install -y wrk)");
    let report = String::from_utf8_lossy(&out.stdout);
    println!(
        "== POST /v1/analyze (N = 2, D = 1000, trace_points = {}), wrk -t2 -c{connections} -d{seconds}s\n{report}",
        model["options"]["trace_points"]
    );
    assert!(!report.contains("Non-2xx"), "some requests failed");

    // 2. Job throughput, D = 1e5.
    let agent: ureq::Agent = ureq::Agent::config_builder()
        .http_status_as_error(false)
        .build()
        .into();
    let mut long = model.clone();
    long["time"]["steps"] = 100_000.into();
    long["options"]["steady_state_shortcut"] = false.into();
    let job_body = json!({ "kind": "analysis", "model": long }).to_string();
    let start = Instant::now();
    let ids: Vec<String> = (0..jobs)
        .map(|_| {
            let mut r = agent
                .post(format!("{base}/v1/jobs"))
                .header("content-type", "application/json")
                .send(&job_body)
                .unwrap();
            assert_eq!(r.status().as_u16(), 202);
            let v: Value = serde_json::from_str(&r.body_mut().read_to_string().unwrap()).unwrap();
            v["id"].as_str().unwrap().to_string()
        })
        .collect();
    let submitted = start.elapsed();
    for id in &ids {
        loop {
            let mut r = agent.get(format!("{base}/v1/jobs/{id}")).call().unwrap();
            let v: Value = serde_json::from_str(&r.body_mut().read_to_string().unwrap()).unwrap();
            match v["status"].as_str().unwrap() {
                "succeeded" => break,
                "queued" | "running" => std::thread::sleep(Duration::from_millis(20)),
                other => panic!("job {id} {other}: {v}"),
            }
        }
    }
    let total = start.elapsed().as_secs_f64();
    println!(
        "== jobs: {jobs} analyses with D = 1e5 (N = 2, no shortcut): submitted in {:.2} s, \
         all done in {total:.2} s → {:.1} jobs/s ({:.0} ms per job per worker)",
        submitted.as_secs_f64(),
        jobs as f64 / total,
        total * 1e3 / jobs as f64
            * std::thread::available_parallelism().map_or(1, |n| n.get()) as f64
    );
    let _ = server.kill();
    let _ = server.wait();
}

/// A Lua long string literal holding `s`.
fn lua_string(s: &str) -> String {
    let mut eq = String::new();
    while s.contains(&format!("]{eq}]")) {
        eq.push('=');
    }
    format!("[{eq}[{s}]{eq}]")
}
