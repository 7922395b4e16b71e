//! The real server over HTTP: every route, errors, auth, jobs, persistence.

mod common;

use common::{Server, long_model, preset, without_timing};
use serde_json::{Value, json};
use std::process::Command;
use std::time::Duration;

const LONG: Duration = Duration::from_secs(120);

fn tmp() -> tempfile::TempDir {
    tempfile::tempdir().unwrap()
}

/// Submit a 4·10⁶-step analysis job and wait until it runs with some progress; its id
/// and that snapshot of it.
fn start_long_job(s: &Server) -> (String, Value) {
    let id = s.submit_analysis(long_model(4_000_000));
    let running = s.wait_job(&id, LONG, |j| {
        j["status"] == "running" && j["progress"].as_f64().unwrap() > 0.0
    });
    (id, running)
}

#[test]
fn health_and_presets() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let h = s.get("/healthz");
    assert_eq!(h.status, 200);
    assert_eq!(
        h.json(),
        json!({"status": "ok", "version": env!("CARGO_PKG_VERSION")})
    );

    let list = s.get("/v1/presets");
    assert_eq!(list.status, 200);
    let names: Vec<String> = list.json()["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(names, kea_core::presets::names());
    assert_eq!(list.json()["items"][2]["states"], 2);

    let one = s.get("/v1/presets/cv-tracker");
    assert_eq!(one.status, 200);
    assert_eq!(one.content_type, "application/json");
    assert_eq!(one.text, kea_core::presets::get_json("cv-tracker").unwrap());

    let missing = s.get("/v1/presets/nope");
    assert_eq!(missing.status, 404);
    assert_eq!(missing.content_type, "application/problem+json");
    assert_eq!(missing.json()["status"], 404);

    // The synthesis example, as shipped; with the preset's model it is a job that
    // finds its answer.
    let example = s.get("/v1/presets/cv-tracker/synthesis");
    assert_eq!(example.status, 200);
    assert_eq!(example.content_type, "application/json");
    assert_eq!(
        example.text,
        kea_core::presets::synthesis_json("cv-tracker").unwrap()
    );
    let mut request = example.json();
    request["kind"] = json!("synthesis");
    request["model"] = one.json();
    let job = s.post("/v1/jobs", &request);
    assert_eq!(job.status, 202, "{}", job.text);
    let id = job.json()["id"].as_str().unwrap().to_string();
    let done = s.wait_finished(&id, Duration::from_secs(60));
    assert_eq!(done["status"], "succeeded", "{done}");
    let result = s.get(&format!("/v1/jobs/{id}/result"));
    assert_eq!(result.json()["status"], "found", "{}", result.text);
    assert_eq!(s.get("/v1/presets/nope/synthesis").status, 404);
}

/// A stored model came back re-serialised: members sorted, `1e3` as `1000.0`,
/// `0.10000000000000000555` as `0.1`. openapi says "returned as it was sent".
#[test]
fn a_stored_model_is_returned_as_it_was_sent() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let text = r#"{"time": {"steps": 1e3, "t_end": 1.50, "t0": 0},
  "system": {"states": ["x"], "a": [[-1]], "b": [[1]], "phi": [1], "y0": [1], "eta0": [1]},
  "measurement": {"names": ["z"], "c": [[1]], "gamma": [[1]], "psi": [0.10000000000000000555]},
  "name": "as sent"}"#;
    let r = s.post_raw(
        "/v1/models",
        "application/json",
        &format!("\u{feff}{text}\n"),
    );
    assert_eq!(r.status, 201, "{}", r.text);
    let id = r.json()["id"].as_str().unwrap().to_string();
    let got = s.get(&format!("/v1/models/{id}"));
    assert_eq!(got.status, 200);
    assert!(
        got.text.ends_with(&format!(",\"model\":{text}}}")),
        "{}",
        got.text
    );
    let v = got.json();
    assert_eq!(v["id"], id.as_str());
    assert_eq!(v["name"], "as sent");
    // And it runs from its id as the model it is.
    let r = s.post("/v1/analyze", &json!({"model_id": id}));
    assert_eq!(r.status, 200, "{}", r.text);
    assert_eq!(r.json()["steps"], 1000);
    // In any case, as the path's ids.
    let r = s.post("/v1/analyze", &json!({"model_id": id.to_uppercase()}));
    assert_eq!(r.status, 200, "{}", r.text);
    // A null id beside a model said "give either `model` or `model_id`, not both".
    let r = s.post(
        "/v1/analyze",
        &json!({"model_id": null, "model": preset("cv-tracker")}),
    );
    assert_eq!(r.status, 422, "{}", r.text);
    assert!(
        r.text.contains("null beside `model`: leave `model_id` out"),
        "{}",
        r.text
    );
}

/// An error in a stored model read `model.measurement.psi[0]` although the request
/// had no `model`. The path stays the resolved request's (as a job's stored request
/// has it), and the message names the stored model it is in; errors of the request's
/// own members are as they were.
#[test]
fn an_error_in_a_stored_model_names_it() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let r = s.post("/v1/models", &preset("cv-tracker"));
    assert_eq!(r.status, 201, "{}", r.text);
    let id = r.json()["id"].as_str().unwrap().to_string();
    for (path, body) in [
        ("/v1/analyze", json!({"model_id": id, "set": {"r": -1}})),
        (
            "/v1/jobs",
            json!({"kind": "analysis", "model_id": id, "set": {"r": -1}}),
        ),
    ] {
        let r = s.post(path, &body);
        assert_eq!(r.status, 422, "{}", r.text);
        let e = &r.json()["errors"][0];
        assert_eq!(e["path"], "model.measurement.psi[0]", "{}", r.text);
        let message = e["message"].as_str().unwrap();
        assert!(
            message.ends_with(&format!("(in the stored model `{id}`)")),
            "{message}"
        );
    }
    let r = s.post("/v1/analyze", &json!({"model_id": id, "set": {"nope": 1}}));
    assert_eq!(r.status, 422, "{}", r.text);
    assert!(!r.text.contains("in the stored model"), "{}", r.text);
}

#[test]
fn models_are_stored_listed_paged_and_deleted() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let mut ids = Vec::new();
    for name in ["seed-example", "helicopter-range", "cv-tracker"] {
        let r = s.post("/v1/models", &preset(name));
        assert_eq!(r.status, 201, "{}", r.text);
        let id = r.json()["id"].as_str().unwrap().to_string();
        assert_eq!(
            r.location.as_deref(),
            Some(format!("/v1/models/{id}").as_str())
        );
        ids.push(id);
    }
    let got = s.get(&format!("/v1/models/{}", ids[2]));
    assert_eq!(got.status, 200);
    assert_eq!(got.json()["model"], preset("cv-tracker"));
    assert_eq!(got.json()["name"], "Constant-velocity tracker (textbook)");

    // Newest first, two per page.
    let p1 = s.get("/v1/models?limit=2").json();
    let page_ids = |p: &Value| -> Vec<String> {
        p["items"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m["id"].as_str().unwrap().to_string())
            .collect()
    };
    assert_eq!(page_ids(&p1), vec![ids[2].clone(), ids[1].clone()]);
    let cursor = p1["next_cursor"].as_str().unwrap();
    let p2 = s.get(&format!("/v1/models?limit=2&cursor={cursor}")).json();
    assert_eq!(page_ids(&p2), vec![ids[0].clone()]);
    assert_eq!(p2["next_cursor"], Value::Null);
    // UUID text is case-insensitive (RFC 9562): an upper-case id or cursor names the
    // same model and page (they were 404 and 400).
    let upper = s.get(&format!(
        "/v1/models?limit=2&cursor={}",
        cursor.to_uppercase()
    ));
    assert_eq!(upper.status, 200, "{}", upper.text);
    assert_eq!(page_ids(&upper.json()), vec![ids[0].clone()]);
    let got = s.get(&format!("/v1/models/{}", ids[2].to_uppercase()));
    assert_eq!(got.status, 200, "{}", got.text);
    assert_eq!(got.json()["id"], ids[2].as_str());

    assert_eq!(s.delete(&format!("/v1/models/{}", ids[0])).status, 204);
    assert_eq!(s.get(&format!("/v1/models/{}", ids[0])).status, 404);
    assert_eq!(s.delete(&format!("/v1/models/{}", ids[0])).status, 404);
    assert_eq!(page_ids(&s.get("/v1/models").json()).len(), 2);
}

/// The JSON `kea ARGS…` prints (it must succeed).
fn kea_json<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Value {
    let out = Command::new(common::KEA).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `kea analyze --json` for a preset with overrides.
fn cli_result(preset_name: &str, set: &[&str]) -> Value {
    let file = common::repo()
        .join("presets")
        .join(format!("{preset_name}.json"));
    let mut args = vec!["analyze".into(), file.into_os_string(), "--json".into()];
    for s in set {
        args.extend(["--set".into(), s.into()]);
    }
    kea_json(&args)
}

#[test]
fn analyze_sync_and_job_equal_the_cli() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    for (name, set_cli, set_json) in [
        (
            "cv-tracker",
            vec!["q=2", "r=0.25"],
            json!({"q": 2, "r": 0.25}),
        ),
        ("helicopter-range", vec![], json!({})),
    ] {
        let cli = without_timing(cli_result(name, &set_cli));
        let sync = s.post(
            "/v1/analyze",
            &json!({"model": preset(name), "set": set_json}),
        );
        assert_eq!(sync.status, 200, "{}", sync.text);
        assert!(sync.json()["timing"]["wall_ms"].as_f64().unwrap() > 0.0);
        assert_eq!(without_timing(sync.json()), cli, "sync analysis of {name}");

        // By stored model id, as a job.
        let id = s.post("/v1/models", &preset(name)).json()["id"].clone();
        let job = s.post(
            "/v1/jobs",
            &json!({"kind": "analysis", "model_id": id, "set": set_json}),
        );
        assert_eq!(job.status, 202, "{}", job.text);
        let job_id = job.json()["id"].as_str().unwrap().to_string();
        assert_eq!(
            job.location.as_deref(),
            Some(format!("/v1/jobs/{job_id}").as_str())
        );
        let done = s.wait_finished(&job_id, LONG);
        assert_eq!(done["status"], "succeeded", "{done}");
        assert_eq!(done["progress"], 1.0);
        let result = s.get(&format!("/v1/jobs/{job_id}/result"));
        assert_eq!(result.status, 200);
        assert_eq!(without_timing(result.json()), cli, "job analysis of {name}");

        let csv = s.get(&format!("/v1/jobs/{job_id}/traces.csv"));
        assert_eq!(csv.status, 200);
        assert!(csv.content_type.starts_with("text/csv"));
        let header = csv.text.lines().next().unwrap();
        assert!(header.starts_with("t,"), "{header}");
        let rows = csv.text.lines().count() - 1;
        assert_eq!(rows, cli["traces"]["t"].as_array().unwrap().len());
    }
}

/// An analysis with its error budget: `kea analyze --budget`, the synchronous route and
/// a job give the same bits; the job's progress ends at 1 (its two passes share it).
#[test]
fn a_budget_is_the_same_from_the_cli_the_api_and_a_job() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let file = common::repo().join("presets").join("helicopter-range.json");
    let args = vec![
        "analyze".into(),
        file.into_os_string(),
        "--json".into(),
        "--budget".into(),
    ];
    let cli = without_timing(kea_json(&args));
    assert_eq!(cli["budget"]["sources"].as_array().unwrap().len(), 12);
    let body = json!({"model": preset("helicopter-range"), "budget": true});
    let sync = s.post("/v1/analyze", &body);
    assert_eq!(sync.status, 200, "{}", sync.text);
    assert_eq!(
        without_timing(sync.json()),
        cli,
        "sync analysis with its budget"
    );
    let mut job_body = body.clone();
    job_body["kind"] = json!("analysis");
    let job = s.post("/v1/jobs", &job_body);
    assert_eq!(job.status, 202, "{}", job.text);
    let job_id = job.json()["id"].as_str().unwrap().to_string();
    let done = s.wait_finished(&job_id, LONG);
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(done["progress"], 1.0);
    let result = s.get(&format!("/v1/jobs/{job_id}/result"));
    assert_eq!(
        without_timing(result.json()),
        cli,
        "job analysis with its budget"
    );
    // Not a yes/no: a 422 at its path.
    let bad = s.post(
        "/v1/analyze",
        &json!({"model": preset("helicopter-range"), "budget": 1}),
    );
    assert_eq!(bad.status, 422, "{}", bad.text);
    assert!(bad.text.contains("\"budget\""), "{}", bad.text);
}

/// A Monte Carlo job gives `kea monte-carlo`'s result, bit for bit — also without a
/// seed, where both take the documented default (the server once took 0, the CLI 1).
#[test]
fn a_monte_carlo_job_equals_kea_monte_carlo() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let cli = |seed: &str| {
        without_timing(kea_json(&[
            "monte-carlo",
            "preset:cv-tracker",
            "--runs",
            "20",
            "--seed",
            seed,
            "--json",
        ]))
    };
    let (default_seed, seed_0) = (cli("1"), cli("0"));
    assert_ne!(
        default_seed["final"], seed_0["final"],
        "the seed changes the runs"
    );
    // (`runs` 20.0: a whole number written as a float is that number, as in the model)
    for (request, expected) in [
        (json!({}), &default_seed),
        (json!({"seed": 0, "runs": 20.0}), &seed_0),
    ] {
        let mut body = json!({"kind": "monte_carlo", "model": preset("cv-tracker"), "runs": 20});
        body.as_object_mut()
            .unwrap()
            .extend(request.as_object().unwrap().clone());
        let job = s.post("/v1/jobs", &body);
        assert_eq!(job.status, 202, "{}", job.text);
        let id = job.json()["id"].as_str().unwrap().to_string();
        assert_eq!(s.wait_finished(&id, LONG)["status"], "succeeded");
        let result = without_timing(s.get(&format!("/v1/jobs/{id}/result")).json());
        assert_eq!(&result, expected, "Monte Carlo job {request}");
    }
}

/// `simulation`, the Monte Carlo kind's former name, still reads as it: a job submitted
/// under it is stored and shown as a `monte_carlo` job with the same result, `kea
/// simulate` is `kea monte-carlo`, and the jobs an earlier kea stored under it — one
/// finished, one still queued — are read, listed and run as Monte Carlo jobs.
#[test]
fn jobs_of_the_former_kind_name_simulation_are_monte_carlo_jobs() {
    let dir = tmp();
    let mut s = Server::start(dir.path(), &["--workers", "1"]);
    let body = |kind: &str| {
        json!({"kind": kind, "model": preset("cv-tracker"), "runs": 20, "seed": 4,
               "trace_points": 10})
    };
    let run = |s: &Server, kind: &str| {
        let job = s.post("/v1/jobs", &body(kind));
        assert_eq!(job.status, 202, "{}", job.text);
        assert_eq!(job.json()["kind"], "monte_carlo", "{}", job.text);
        let id = job.json()["id"].as_str().unwrap().to_string();
        let done = s.wait_finished(&id, LONG);
        assert_eq!(done["status"], "succeeded", "{done}");
        assert_eq!(done["kind"], "monte_carlo");
        id
    };
    let result =
        |s: &Server, id: &str| without_timing(s.get(&format!("/v1/jobs/{id}/result")).json());
    let traces = |s: &Server, id: &str| s.get(&format!("/v1/jobs/{id}/traces.csv")).text;
    let fresh = run(&s, "monte_carlo");
    let expected = (result(&s, &fresh), traces(&s, &fresh));
    let aliased = run(&s, "simulation");
    assert_eq!((result(&s, &aliased), traces(&s, &aliased)), expected);
    let stored = s.get(&format!("/v1/jobs/{aliased}/request")).json();
    assert_eq!(stored, body("monte_carlo"), "stored under the kind's name");
    let cli = |command: &str| {
        without_timing(kea_json(&[
            command,
            "preset:cv-tracker",
            "--runs",
            "20",
            "--seed",
            "4",
            "--trace-points",
            "10",
            "--json",
        ]))
    };
    assert_eq!(cli("simulate"), expected.0);
    assert_eq!(cli("monte-carlo"), expected.0);
    assert!(s.terminate(LONG), "kea serve exits on SIGTERM");

    // What an earlier kea left: the finished job's row as it stored it, and a queued
    // job of the same request, both of the kind `simulation`.
    let queued = "0190a3c2-7b1e-7c3d-9f00-5a1e0c0ffee1";
    {
        let c = rusqlite::Connection::open(dir.path().join("kea.sqlite")).unwrap();
        let changed = c
            .execute(
                "UPDATE jobs SET kind = 'simulation' WHERE id = ?1",
                [&aliased],
            )
            .unwrap();
        assert_eq!(changed, 1);
        let mut request = body("simulation");
        request.as_object_mut().unwrap().remove("kind");
        c.execute(
            "INSERT INTO jobs (id, kind, status, request_json, work, created_at)
             VALUES (?1, 'simulation', 'queued', ?2, 1, '2026-01-01T00:00:00Z')",
            rusqlite::params![queued, request.to_string()],
        )
        .unwrap();
    }
    let s = Server::start(dir.path(), &["--workers", "1"]);
    let old = s.get(&format!("/v1/jobs/{aliased}")).json();
    assert_eq!(old["kind"], "monte_carlo", "{old}");
    assert_eq!((result(&s, &aliased), traces(&s, &aliased)), expected);
    let stored = s.get(&format!("/v1/jobs/{aliased}/request")).json();
    assert_eq!(stored, body("monte_carlo"));
    let done = s.wait_finished(queued, LONG);
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_eq!(done["kind"], "monte_carlo");
    assert_eq!((result(&s, queued), traces(&s, queued)), expected);
    let listed = s.get("/v1/jobs").json();
    let kinds: Vec<&Value> = listed["items"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| &j["kind"])
        .collect();
    assert_eq!(kinds.len(), 3, "{listed}");
    assert!(kinds.iter().all(|k| *k == "monte_carlo"), "{listed}");
    // Run again: its stored request, posted back as it is.
    assert_eq!(result(&s, &run_stored(&s, queued)), expected.0);
}

/// A job's stored request (`GET /v1/jobs/{id}/request`) posted back to `POST /v1/jobs`
/// (the web page's Run again), run to its end: the new job's id.
fn run_stored(s: &Server, id: &str) -> String {
    let stored = s.get(&format!("/v1/jobs/{id}/request")).json();
    let job = s.post("/v1/jobs", &stored);
    assert_eq!(job.status, 202, "{}", job.text);
    let again = job.json()["id"].as_str().unwrap().to_string();
    assert_eq!(s.wait_finished(&again, LONG)["status"], "succeeded");
    again
}

#[test]
fn jobs_list_events_and_status_filter() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let id = s.submit_analysis(preset("cv-tracker"));
    let events = s.events(&format!("/v1/jobs/{id}/events"));
    let (last_event, last) = events.last().unwrap();
    assert_eq!(last_event, "status");
    assert_eq!(last["status"], "succeeded");
    assert_eq!(last["id"], id.as_str());
    for (e, d) in &events[..events.len() - 1] {
        assert_eq!(e, "progress");
        assert!(matches!(d["status"].as_str(), Some("queued" | "running")));
    }
    let job = s.get(&format!("/v1/jobs/{id}")).json();
    for member in [
        "id",
        "kind",
        "status",
        "progress",
        "created_at",
        "started_at",
        "finished_at",
    ] {
        assert!(!job[member].is_null(), "{member} in {job}");
    }
    let ok = s.get("/v1/jobs?status=succeeded").json();
    assert_eq!(ok["items"][0]["id"], id.as_str());
    let none = s.get("/v1/jobs?status=failed").json();
    assert_eq!(none["items"], json!([]));
    let bad = s.get("/v1/jobs?status=done");
    assert_eq!(bad.status, 400);
    assert_eq!(bad.error_paths(), vec!["status"]);
}

#[test]
fn cancel_running_and_queued_jobs() {
    let dir = tmp();
    let s = Server::start(dir.path(), &["--workers", "1"]);
    let submit = |m: Value| {
        let r = s.post("/v1/jobs", &json!({"kind": "analysis", "model": m}));
        assert_eq!(r.status, 202, "{}", r.text);
        r.json()["id"].as_str().unwrap().to_string()
    };
    let running = submit(long_model(50_000_000));
    let queued = submit(preset("cv-tracker"));
    s.wait_job(&running, LONG, |j| {
        j["status"] == "running" && j["progress"].as_f64().unwrap() > 0.0
    });
    // Unfinished: no result yet.
    let early = s.get(&format!("/v1/jobs/{running}/result"));
    assert_eq!(early.status, 409);
    assert_eq!(s.get(&format!("/v1/jobs/{running}/traces.csv")).status, 409);

    // The queued one is cancelled at once; the running one at its next progress report.
    let c = s.delete(&format!("/v1/jobs/{queued}"));
    assert_eq!(c.status, 200, "{}", c.text);
    assert_eq!(c.json()["status"], "cancelled");
    let c = s.delete(&format!("/v1/jobs/{running}"));
    assert_eq!(c.status, 200, "{}", c.text);
    let done = s.wait_finished(&running, LONG);
    assert_eq!(done["status"], "cancelled");
    assert!(done["progress"].as_f64().unwrap() < 1.0);
    assert_eq!(s.get(&format!("/v1/jobs/{running}/result")).status, 409);
    assert_eq!(s.delete(&format!("/v1/jobs/{running}")).status, 409);
    let events = s.events(&format!("/v1/jobs/{queued}/events"));
    assert_eq!(events.len(), 1);
    assert_eq!(events[0].0, "status");
    assert_eq!(events[0].1["status"], "cancelled");
    assert_eq!(s.delete("/v1/jobs/no-such-job").status, 404);
}

/// `DELETE …?purge=true` deletes a finished job with its result (and only a finished
/// one); the other jobs stay.
#[test]
fn a_finished_job_is_purged_with_its_result() {
    let dir = tmp();
    let s = Server::start(dir.path(), &["--workers", "1"]);
    let done = s.submit_analysis(preset("cv-tracker"));
    let kept = s.submit_analysis(preset("cv-tracker"));
    assert_eq!(s.wait_finished(&done, LONG)["status"], "succeeded");
    assert_eq!(s.wait_finished(&kept, LONG)["status"], "succeeded");
    let (running, _) = start_long_job(&s);

    // Only finished jobs: a running one is a conflict, and stays running.
    let r = s.delete(&format!("/v1/jobs/{running}?purge=true"));
    assert_eq!(r.status, 409, "{}", r.text);
    assert!(
        r.json()["detail"]
            .as_str()
            .unwrap()
            .contains("cancel it first"),
        "{}",
        r.text
    );
    assert_eq!(
        s.get(&format!("/v1/jobs/{running}")).json()["status"],
        "running"
    );
    // A value other than true or false, or another parameter: 400 naming it.
    let r = s.delete(&format!("/v1/jobs/{done}?purge=yes"));
    assert_eq!(r.status, 400, "{}", r.text);
    assert_eq!(r.json()["errors"][0]["path"], "purge", "{}", r.text);
    assert_eq!(s.delete(&format!("/v1/jobs/{done}?force=1")).status, 400);
    // purge=false is the cancel: a finished job has nothing to cancel.
    assert_eq!(
        s.delete(&format!("/v1/jobs/{done}?purge=false")).status,
        409
    );

    let r = s.delete(&format!("/v1/jobs/{done}?purge=true"));
    assert_eq!(r.status, 204, "{}", r.text);
    assert_eq!(s.get(&format!("/v1/jobs/{done}")).status, 404);
    assert_eq!(s.get(&format!("/v1/jobs/{done}/result")).status, 404);
    assert_eq!(s.delete(&format!("/v1/jobs/{done}?purge=true")).status, 404);
    let listed: Vec<Value> = s.get("/v1/jobs").json()["items"]
        .as_array()
        .unwrap()
        .clone();
    assert!(
        listed.iter().all(|j| j["id"] != done.as_str()),
        "{listed:?}"
    );
    assert_eq!(s.get(&format!("/v1/jobs/{kept}/result")).status, 200);

    // Cancelled, then purged.
    assert_eq!(s.delete(&format!("/v1/jobs/{running}")).status, 200);
    assert_eq!(s.wait_finished(&running, LONG)["status"], "cancelled");
    assert_eq!(
        s.delete(&format!("/v1/jobs/{running}?purge=true")).status,
        204
    );
    assert_eq!(s.get(&format!("/v1/jobs/{running}")).status, 404);
}

/// `--keep-finished`: a finished job goes with its result once it has been finished
/// that long (the sweep runs every second here); /v1/limits says so; without the
/// option nothing is deleted.
#[test]
fn finished_jobs_go_after_keep_finished() {
    let dir = tmp();
    let s = Server::start(dir.path(), &["--keep-finished", "2"]);
    assert_eq!(s.get("/v1/limits").json()["server"]["keep_finished_s"], 2);
    let id = s.submit_analysis(preset("cv-tracker"));
    assert_eq!(s.wait_finished(&id, LONG)["status"], "succeeded");
    assert_eq!(s.get(&format!("/v1/jobs/{id}/result")).status, 200);
    let started = std::time::Instant::now();
    while s.get(&format!("/v1/jobs/{id}")).status != 404 {
        assert!(
            started.elapsed() < Duration::from_secs(30),
            "job {id} still kept after 30 s"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    // Within the retention and the sweep's interval (2 + 1 s), with slack for a busy host.
    assert!(started.elapsed() < Duration::from_secs(10));
    assert_eq!(s.get(&format!("/v1/jobs/{id}/result")).status, 404);

    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    assert_eq!(
        s.get("/v1/limits").json()["server"]["keep_finished_s"],
        Value::Null
    );
}

/// A job's request reads back as stored — its `model_id` replaced by the model, its
/// `set` kept — and submitted again it gives the same result; the job's view names
/// the model.
#[test]
fn a_jobs_request_reads_back_and_runs_again() {
    let dir = tmp();
    let s = Server::start(dir.path(), &["--workers", "1"]);
    let model = preset("cv-tracker");
    let name = model["name"].as_str().unwrap().to_string();
    let stored = s.post("/v1/models", &model).json()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let r = s.post(
        "/v1/jobs",
        &json!({"kind": "analysis", "model_id": stored, "set": {"q": 2}}),
    );
    assert_eq!(r.status, 202, "{}", r.text);
    assert_eq!(r.json()["model_name"], name.as_str(), "{}", r.text);
    let first = r.json()["id"].as_str().unwrap().to_string();
    assert_eq!(s.wait_finished(&first, LONG)["status"], "succeeded");
    // The stored model may go: the job's request has its own copy.
    assert_eq!(s.delete(&format!("/v1/models/{stored}")).status, 204);

    let r = s.get(&format!("/v1/jobs/{first}/request"));
    assert_eq!(r.status, 200, "{}", r.text);
    let request = r.json();
    assert_eq!(request["kind"], "analysis");
    assert_eq!(request["model"], model);
    assert_eq!(request["set"], json!({"q": 2}));
    assert!(request.get("model_id").is_none(), "{}", r.text);
    let listed = s.get("/v1/jobs").json();
    assert_eq!(listed["items"][0]["id"], first.as_str());
    assert_eq!(listed["items"][0]["model_name"], name.as_str());

    let again = s.post("/v1/jobs", &request);
    assert_eq!(again.status, 202, "{}", again.text);
    let again = again.json()["id"].as_str().unwrap().to_string();
    assert_eq!(s.wait_finished(&again, LONG)["status"], "succeeded");
    let result = |id: &str| without_timing(s.get(&format!("/v1/jobs/{id}/result")).json());
    let (a, b) = (result(&first), result(&again));
    assert_eq!(a, b);
    // `set` took effect (q = 2 is not the preset's value).
    assert_ne!(model["params"]["q"], json!(2));
    let unset = s.post("/v1/analyze", &json!({"model": model})).json();
    assert_ne!(a["criteria"], unset["criteria"]);

    // A model without a name: null.
    let mut unnamed = model.clone();
    unnamed.as_object_mut().unwrap().remove("name");
    let r = s.post("/v1/jobs", &json!({"kind": "analysis", "model": unnamed}));
    assert_eq!(r.json()["model_name"], Value::Null, "{}", r.text);
    assert_eq!(
        s.get("/v1/jobs/00000000-0000-0000-0000-000000000000/request")
            .status,
        404
    );
}

/// A synthesis's analyses run beside each other and reported nothing, so a cancel (or
/// the time limit, or a shutdown) waited for the analyses in hand: an audit saw a
/// cancel take 22.5 s, and SIGTERM 21.4 s against a 10 s grace. Each analysis now asks
/// the job whether to stop as it goes.
#[test]
fn a_synthesis_job_is_cancelled_inside_its_analyses() {
    let dir = tmp();
    let s = Server::start(dir.path(), &["--workers", "1"]);
    // Two grid points whose analyses take tens of seconds each (6 states, 10⁸ steps).
    let mut model = preset("helicopter-range");
    model["time"]["steps"] = json!(100_000_000);
    model["options"]["steady_state_shortcut"] = json!(false);
    let r = s.post(
        "/v1/jobs",
        &json!({
            "kind": "synthesis",
            "model": model,
            "target": {"criterion": "yx", "criteria": "covariance", "threshold": 1e9},
            "mode": {"grid": {"params": [{"name": "sd", "values": [2.5, 5.0]}]}}
        }),
    );
    assert_eq!(r.status, 202, "{}", r.text);
    let id = r.json()["id"].as_str().unwrap().to_string();
    s.wait_job(&id, LONG, |j| j["status"] == "running");
    std::thread::sleep(Duration::from_millis(500));
    let asked = std::time::Instant::now();
    assert_eq!(s.delete(&format!("/v1/jobs/{id}")).status, 200);
    let done = s.wait_finished(&id, LONG);
    let took = asked.elapsed();
    assert_eq!(done["status"], "cancelled", "{done}");
    assert!(
        took < Duration::from_secs(5),
        "the cancel took {took:?}, as long as the analyses in hand"
    );
}

#[test]
fn two_hundred_concurrent_jobs_all_complete_correctly() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let q = |i: usize| 0.5 + i as f64 / 100.0;
    let ids: Vec<(usize, String)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..8)
            .map(|t| {
                let s = &s;
                scope.spawn(move || {
                    (0..25)
                        .map(|k| {
                            let i = t * 25 + k;
                            let body = json!({"kind": "analysis", "model": preset("cv-tracker"), "set": {"q": q(i)}});
                            let r = s.post("/v1/jobs", &body);
                            assert_eq!(r.status, 202, "{}", r.text);
                            (i, r.json()["id"].as_str().unwrap().to_string())
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    assert_eq!(ids.len(), 200);
    for (i, id) in &ids {
        let job = s.wait_finished(id, LONG);
        assert_eq!(job["status"], "succeeded", "{job}");
        let got = without_timing(s.get(&format!("/v1/jobs/{id}/result")).json());
        let want = s.post(
            "/v1/analyze",
            &json!({"model": preset("cv-tracker"), "set": {"q": q(*i)}}),
        );
        assert_eq!(got, without_timing(want.json()), "job {i}");
    }
}

#[test]
fn a_job_survives_a_crash_and_finishes_after_restart() {
    let dir = tmp();
    let mut s = Server::start(dir.path(), &["--workers", "1"]);
    let (id, first) = start_long_job(&s);
    // Behind it on the one worker.
    let queued = s.submit_analysis(preset("cv-tracker"));
    assert!(first["progress"].as_f64().unwrap() < 1.0, "{first}");
    s.kill();

    let s = Server::start(dir.path(), &["--workers", "1"]);
    let done = s.wait_finished(&id, LONG);
    assert_eq!(done["status"], "succeeded", "{done}");
    assert_ne!(done["started_at"], first["started_at"], "it was run again");
    let result = s.get(&format!("/v1/jobs/{id}/result")).json();
    assert_eq!(result["steps"], 4_000_000);
    assert_eq!(s.wait_finished(&queued, LONG)["status"], "succeeded");
}

/// The job `body` (of `steps` steps), killed part way, goes on after the restart from
/// the state it kept (`--state-every 1`: every second): its result says from which
/// step, and is the one a fresh run of the same request gives, but for the timing.
fn resumes_after_a_crash(body: Value, steps: u64) {
    let dir = tmp();
    let args = ["--workers", "1", "--state-every", "1"];
    let submit = |s: &Server| {
        let job = s.post("/v1/jobs", &body);
        assert_eq!(job.status, 202, "{}", job.text);
        job.json()["id"].as_str().unwrap().to_string()
    };
    let mut s = Server::start(dir.path(), &args);
    assert_eq!(s.get("/v1/limits").json()["server"]["state_every_s"], 1);
    let id = submit(&s);
    let first = s.wait_job(&id, LONG, |j| j["progress"].as_f64().unwrap() >= 0.4);
    assert_eq!(first["status"], "running", "{first}");
    s.kill();

    let s = Server::start(dir.path(), &args);
    assert_eq!(s.wait_finished(&id, LONG)["status"], "succeeded");
    let resumed = s.get(&format!("/v1/jobs/{id}/result")).json();
    let from = resumed["timing"]["resumed_from_step"]
        .as_u64()
        .expect("resumed");
    assert!(
        from > steps / 10 && from < steps,
        "resumed from step {from}"
    );
    let again = submit(&s);
    assert_eq!(s.wait_finished(&again, LONG)["status"], "succeeded");
    let whole = s.get(&format!("/v1/jobs/{again}/result")).json();
    assert_eq!(whole["timing"].get("resumed_from_step"), None);
    assert_eq!(without_timing(resumed), without_timing(whole));
}

/// An analysis: its step loop's state.
#[test]
fn an_analysis_resumes_after_a_crash_from_the_state_it_kept() {
    let steps = 40_000_000;
    resumes_after_a_crash(
        json!({"kind": "analysis", "model": long_model(steps)}),
        steps,
    );
}

/// A Monte Carlo: its runs' state, kept between chunks.
#[test]
fn a_monte_carlo_resumes_after_a_crash_from_the_state_it_kept() {
    let steps = 600_000;
    let body = json!({"kind": "monte_carlo", "model": long_model(steps), "runs": 500, "seed": 5});
    resumes_after_a_crash(body, steps);
}

/// A job's kept state is taken only by the kea executable that kept it: after an
/// upgrade (here, a copy of kea: another file) the job starts over, and its result is
/// the new executable's alone.
#[test]
fn a_job_kept_by_another_kea_executable_starts_over() {
    let dir = tmp();
    let args = ["--workers", "1", "--state-every", "1"];
    let steps = 40_000_000;
    let mut s = Server::start(dir.path(), &args);
    let id = s.submit_analysis(long_model(steps));
    let first = s.wait_job(&id, LONG, |j| j["progress"].as_f64().unwrap() >= 0.4);
    assert_eq!(first["status"], "running", "{first}");
    s.kill();

    let other = tmp();
    let upgraded = other.path().join("kea");
    std::fs::copy(common::KEA, &upgraded).expect("copy kea");
    let s = Server::start_binary(&upgraded, dir.path(), &args);
    assert_eq!(s.wait_finished(&id, LONG)["status"], "succeeded");
    let result = s.get(&format!("/v1/jobs/{id}/result")).json();
    assert_eq!(
        result["timing"].get("resumed_from_step"),
        None,
        "{}",
        result["timing"]
    );
    assert_eq!(result["steps"], steps);
}

/// A job the server dies running three times (as one that brings it down would)
/// fails with a problem instead of running at every start; the next job runs.
#[test]
fn a_job_the_server_dies_running_three_times_is_not_run_again() {
    let dir = tmp();
    let mut s = Server::start(dir.path(), &["--workers", "1"]);
    let (id, _) = start_long_job(&s);
    let behind = s.submit_analysis(preset("cv-tracker"));
    for _ in 0..2 {
        s.kill();
        s = Server::start(dir.path(), &["--workers", "1"]);
        s.wait_job(&id, LONG, |j| j["status"] == "running");
    }
    s.kill();
    let s = Server::start(dir.path(), &["--workers", "1"]);
    let job = s.get(&format!("/v1/jobs/{id}")).json();
    assert_eq!(job["status"], "failed", "{job}");
    assert_eq!(job["error"]["type"], "urn:kea:problem:interrupted", "{job}");
    assert!(
        job["error"]["detail"].as_str().unwrap().contains("3 times"),
        "{job}"
    );
    assert!(job["finished_at"].is_string(), "{job}");
    assert_eq!(s.get(&format!("/v1/jobs/{id}/result")).status, 409);
    assert_eq!(s.wait_finished(&behind, LONG)["status"], "succeeded");
}

#[test]
fn a_cancel_is_not_lost_when_the_process_dies() {
    let dir = tmp();
    let mut s = Server::start(dir.path(), &["--workers", "1"]);
    let (id, _) = start_long_job(&s);
    let cancel = s.delete(&format!("/v1/jobs/{id}"));
    assert_eq!(cancel.status, 200, "{}", cancel.text);
    // Killed at once: the job has (most likely) not yet seen the in-memory flag.
    s.kill();
    let s = Server::start(dir.path(), &["--workers", "1"]);
    let job = s.wait_finished(&id, LONG);
    assert_eq!(job["status"], "cancelled", "{job}");
    assert_eq!(s.get(&format!("/v1/jobs/{id}/result")).status, 409);
}

#[test]
fn graceful_shutdown_requeues_and_restart_finishes() {
    let dir = tmp();
    let mut s = Server::start(dir.path(), &["--workers", "1", "--shutdown-grace", "0"]);
    let (id, _) = start_long_job(&s);
    let before = s.get(&format!("/v1/jobs/{id}")).json()["progress"]
        .as_f64()
        .unwrap();
    // A client following the job's events is told why its stream ends (it ended
    // after a progress event, as if complete).
    let url = s.url(&format!("/v1/jobs/{id}/events"));
    let follower = std::thread::spawn(move || {
        let res = ureq::get(&url).call().expect("events");
        let text = res.into_body().read_to_string().expect("read event stream");
        common::parse_events(&text)
    });
    std::thread::sleep(Duration::from_millis(300));
    assert!(
        s.terminate(Duration::from_secs(30)),
        "kea serve exits on SIGTERM"
    );
    let events = follower.join().unwrap();
    let (last, data) = events.last().expect("events");
    assert_eq!(last, "shutdown", "{events:?}");
    assert_eq!(data["status"], "running", "{data}");
    assert!(
        data["message"].as_str().unwrap().contains("re-queued"),
        "{data}"
    );
    let s = Server::start(dir.path(), &["--workers", "1"]);
    // Run again, it shows at least the progress it had reached: never backwards.
    let again = s.get(&format!("/v1/jobs/{id}")).json();
    assert!(
        again["progress"].as_f64().unwrap() >= before,
        "{again} after {before}"
    );
    assert_eq!(s.wait_finished(&id, LONG)["status"], "succeeded");
}

#[test]
fn auth_on_and_off() {
    let dir = tmp();
    let s = Server::start(dir.path(), &["--token", "s3cret"]);
    // With the token (the harness sends it), everything works.
    assert_eq!(s.get("/v1/presets").status, 200);
    // Without, or wrong: 401 problem with a challenge; health stays open.
    let none = s.get_with("/v1/presets", &[]);
    assert_eq!(none.status, 401);
    assert_eq!(none.content_type, "application/problem+json");
    let wrong = s.get_with("/v1/jobs", &[("authorization", "Bearer nope")]);
    assert_eq!(wrong.status, 401);
    assert_eq!(s.get_with("/healthz", &[]).status, 200);
    drop(s);

    let open = Server::start(tmp().path(), &[]);
    assert_eq!(open.get_with("/v1/presets", &[]).status, 200);
}

/// A server without a token trusted any Host, so a web page whose name was pointed
/// at 127.0.0.1 (DNS rebinding) could read the stored models and submit jobs through
/// the user's browser. Its API now answers only requests addressed to this machine,
/// or to a name given with --allowed-host; a token, or --allow-no-token, lifts it.
#[test]
fn without_a_token_the_api_answers_only_requests_addressed_to_this_machine() {
    use std::io::{Read, Write};
    // (status line, body) of a GET with the given Host.
    let get = |s: &Server, path: &str, host: &str| {
        let addr = s.base.trim_start_matches("http://");
        let mut tcp = std::net::TcpStream::connect(addr).unwrap();
        tcp.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
        write!(
            tcp,
            "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut answer = String::new();
        tcp.read_to_string(&mut answer).unwrap();
        let status = answer.lines().next().unwrap_or_default().to_string();
        (status, answer)
    };
    let open = Server::start(tmp().path(), &["--allowed-host", "kea.lab"]);
    let port = open.base.rsplit(':').next().unwrap().to_string();
    for here in [
        format!("127.0.0.1:{port}"),
        format!("localhost:{port}"),
        "kea.lab".to_string(),
    ] {
        let (status, body) = get(&open, "/v1/models", &here);
        assert!(status.contains(" 200 "), "{here}: {body}");
    }
    let (status, body) = get(&open, "/v1/models", &format!("attacker.example:{port}"));
    assert!(status.contains(" 403 "), "{body}");
    assert!(body.contains("application/problem+json"), "{body}");
    assert!(body.contains("urn:kea:problem:forbidden-host"), "{body}");
    assert!(body.contains("not to `attacker.example:"), "{body}");
    assert!(body.contains("--allowed-host"), "{body}");
    // The health check and the UI stay open; they reveal nothing.
    let (status, _) = get(&open, "/healthz", "attacker.example");
    assert!(status.contains(" 200 "), "{status}");
    drop(open);
    // With a token, the token is the check.
    let guarded = Server::start(tmp().path(), &["--token", "s3cret"]);
    let (status, body) = get(&guarded, "/v1/models", "attacker.example");
    assert!(status.contains(" 401 "), "{body}");
}

/// A second `kea serve` on a data directory in use took over the first one's running
/// jobs (re-queued them as if the first had died) and ran them again. Now it is
/// refused; once the first has stopped, the directory is free again.
#[test]
fn refuses_a_data_directory_another_kea_is_using() {
    let dir = tmp();
    let mut first = Server::start(dir.path(), &[]);
    let mut second = Command::new(common::KEA)
        .args(["serve", "--addr", "127.0.0.1:0", "--data-dir"])
        .arg(dir.path())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while second.try_wait().unwrap().is_none() {
        if std::time::Instant::now() > deadline {
            let _ = second.kill();
            panic!("a second kea serve started on a data directory in use");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = second.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("is in use by another kea process") && err.contains("kea.lock"),
        "{err}"
    );
    assert_eq!(first.get("/healthz").status, 200, "the first one serves on");
    first.kill();
    let again = Server::start(dir.path(), &[]);
    assert_eq!(again.get("/healthz").status, 200);
}

/// Limits that refuse all work (0, NaN) were accepted at start-up; the server then
/// turned every request away ("above the limit of NaN"). They are refused up front,
/// as the CLI's --max-work is.
#[test]
fn refuses_limits_that_would_refuse_everything() {
    for (option, value, expected) in [
        ("--max-work", "nan", "expected a positive number (or inf)"),
        (
            "--sync-work-limit",
            "0",
            "expected a positive number (or inf)",
        ),
        (
            "--job-time-limit",
            "0",
            "expected a whole number of at least 1",
        ),
        (
            "--queue-limit",
            "0",
            "expected a whole number of at least 1",
        ),
        (
            "--max-body-bytes",
            "0",
            "expected a whole number of at least 1",
        ),
        (
            "--read-timeout",
            "0",
            "expected a whole number of at least 1",
        ),
        (
            "--keep-finished",
            "0",
            "expected a whole number of at least 1",
        ),
    ] {
        let dir = tmp();
        let out = Command::new(common::KEA)
            .args([
                "serve",
                "--addr",
                "127.0.0.1:0",
                option,
                value,
                "--data-dir",
            ])
            .arg(dir.path())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{option} {value}: {err}");
        assert!(err.contains(option) && err.contains(expected), "{err}");
    }
}

#[test]
fn refuses_a_public_address_without_a_token() {
    let dir = tmp();
    let out = Command::new(common::KEA)
        .args(["serve", "--addr", "0.0.0.0:0", "--data-dir"])
        .arg(dir.path())
        .env_remove("KEA_TOKEN")
        .env_remove("KEA_ALLOW_NO_TOKEN")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("without a token"), "{err}");
}

#[test]
fn limits_sync_work_and_absurd_work() {
    let dir = tmp();
    let s = Server::start(
        dir.path(),
        &["--sync-work-limit", "1e5", "--max-work", "1e8"],
    );
    let r = s.post("/v1/analyze", &json!({"model": long_model(100_000)}));
    assert_eq!(r.status, 422, "{}", r.text);
    assert_eq!(r.json()["type"], "urn:kea:problem:use-a-job");
    assert_eq!(r.error_paths(), vec!["model.time.steps"]);
    assert!(r.text.contains("POST /v1/jobs"), "{}", r.text);
    let r = s.post(
        "/v1/jobs",
        &json!({"kind": "analysis", "model": long_model(50_000_000)}),
    );
    assert_eq!(r.status, 422, "{}", r.text);
    assert_eq!(r.json()["type"], "urn:kea:problem:too-much-work");

    // GET /v1/limits reports these limits as started, and the core's as enforced.
    let limits = s.get("/v1/limits").json();
    assert_eq!(limits["server"]["sync_work"], 1e5);
    assert_eq!(limits["server"]["max_work"], 1e8);
    assert_eq!(limits["server"]["max_body_bytes"], 8 * 1024 * 1024);
    let max_steps = limits["model"]["max_steps"].as_u64().unwrap();
    let r = s.post(
        "/v1/jobs",
        &json!({"kind": "analysis", "model": long_model(max_steps + 1)}),
    );
    assert_eq!(r.status, 422, "{}", r.text);
    assert_eq!(r.error_paths(), vec!["model.time.steps"], "{}", r.text);
    assert!(
        r.text.contains(&format!("limit of {max_steps}")),
        "{}",
        r.text
    );
}

/// A body that stops arriving (a Content-Length of 100, then 4 bytes) is answered 408
/// once `--read-timeout` has passed, and headers that stop arriving close the
/// connection, instead of holding it open.
#[test]
fn a_request_that_stops_arriving_times_out() {
    use std::io::{Read, Write};
    let dir = tmp();
    let s = Server::start(dir.path(), &["--read-timeout", "1"]);
    let host = s.base.trim_start_matches("http://");
    let mut tcp = std::net::TcpStream::connect(host).unwrap();
    tcp.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    write!(
        tcp,
        "POST /v1/analyze HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/json\r\nContent-Length: 100\r\n\r\n{{\"mo"
    )
    .unwrap();
    let started = std::time::Instant::now();
    let mut answer = Vec::new();
    let mut buf = [0u8; 4096];
    while !String::from_utf8_lossy(&answer).contains("body-timeout") {
        match tcp.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => answer.extend_from_slice(&buf[..n]),
            Err(e) => panic!("no answer after {:?}: {e}", started.elapsed()),
        }
    }
    let answer = String::from_utf8_lossy(&answer);
    assert!(answer.starts_with("HTTP/1.1 408"), "{answer}");
    assert!(answer.contains("urn:kea:problem:body-timeout"), "{answer}");
    assert!(answer.contains("4 bytes came"), "{answer}");
    assert!(started.elapsed() < Duration::from_secs(10));

    let mut tcp = std::net::TcpStream::connect(host).unwrap();
    tcp.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    write!(tcp, "POST /v1/analyze HTTP/1.1\r\nHost: {host}\r\n").unwrap();
    let started = std::time::Instant::now();
    let mut rest = Vec::new();
    // The server closes the connection (an end of stream, or a reset).
    let _ = tcp.read_to_end(&mut rest);
    let waited = started.elapsed();
    assert!(
        waited >= Duration::from_millis(900) && waited < Duration::from_secs(10),
        "closed after {waited:?}"
    );
    // The service itself is unaffected.
    assert_eq!(s.get("/healthz").status, 200);
}

/// A body declared larger than `--max-body-bytes` is answered 413 at once, whether
/// the client starts sending it or waits for `100 Continue`; the server waited for the
/// body and answered 408 after `--read-timeout`.
#[test]
fn a_body_declared_too_large_is_refused_at_once() {
    use std::io::{Read, Write};
    let dir = tmp();
    let s = Server::start(
        dir.path(),
        &["--max-body-bytes", "1000", "--read-timeout", "30"],
    );
    let host = s.base.trim_start_matches("http://");
    for (expect, start_of_body) in [("", "{\"pad\": \""), ("Expect: 100-continue\r\n", "")] {
        let mut tcp = std::net::TcpStream::connect(host).unwrap();
        tcp.set_read_timeout(Some(Duration::from_secs(40))).unwrap();
        write!(
            tcp,
            "POST /v1/models HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/json\r\n\
             Content-Length: 1000000000\r\n{expect}\r\n{start_of_body}"
        )
        .unwrap();
        let started = std::time::Instant::now();
        let mut answer = Vec::new();
        let mut buf = [0u8; 4096];
        while !String::from_utf8_lossy(&answer).contains("}") {
            match tcp.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => answer.extend_from_slice(&buf[..n]),
                Err(e) => panic!("no answer after {:?}: {e}", started.elapsed()),
            }
        }
        let answer = String::from_utf8_lossy(&answer);
        assert!(answer.starts_with("HTTP/1.1 413"), "{expect}: {answer}");
        assert!(
            answer.contains("urn:kea:problem:body-too-large"),
            "{answer}"
        );
        assert!(answer.contains("declared as 1000000000 bytes"), "{answer}");
        assert!(
            started.elapsed() < Duration::from_secs(10),
            "{:?}",
            started.elapsed()
        );
    }
    assert_eq!(s.get("/healthz").status, 200);
}

/// `--queue-limit` holds under concurrent submissions: with the one worker busy, 20
/// submissions at once queue exactly 2 (the count and the insert were two steps, and
/// 3 got in).
#[test]
fn the_queue_limit_holds_under_concurrent_submissions() {
    let dir = tmp();
    let s = Server::start(dir.path(), &["--workers", "1", "--queue-limit", "2"]);
    let (running, _) = start_long_job(&s);
    let request = json!({"kind": "analysis", "model": long_model(4_000_000)});
    let statuses: Vec<u16> = std::thread::scope(|scope| {
        let submits: Vec<_> = (0..20)
            .map(|_| scope.spawn(|| s.post("/v1/jobs", &request).status))
            .collect();
        submits.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let accepted = statuses.iter().filter(|&&c| c == 202).count();
    assert_eq!(accepted, 2, "{statuses:?}");
    assert!(
        statuses.iter().all(|&c| c == 202 || c == 429),
        "{statuses:?}"
    );
    let queued = s.get("/v1/jobs?status=queued").json()["items"]
        .as_array()
        .unwrap()
        .len();
    assert_eq!(queued, 2);
    assert_eq!(
        s.get(&format!("/v1/jobs/{running}")).json()["status"],
        "running"
    );
}

#[test]
fn time_limit_fails_a_job() {
    let dir = tmp();
    let s = Server::start(dir.path(), &["--job-time-limit", "1"]);
    let id = s.submit_analysis(long_model(100_000_000));
    let done = s.wait_finished(&id, LONG);
    assert_eq!(done["status"], "failed");
    assert_eq!(done["error"]["type"], "urn:kea:problem:too-much-work");
    assert!(
        done["error"]["title"]
            .as_str()
            .unwrap()
            .contains("time limit")
    );
}

/// Bad requests: each gets the right 4xx, a problem document and the field paths.
#[test]
fn bad_request_corpus() {
    let dir = tmp();
    let s = Server::start(dir.path(), &["--max-body-bytes", "100000"]);
    let cv = preset("cv-tracker");
    let with = |path: &str, value: Value| {
        let mut m = cv.clone();
        let mut cur = &mut m;
        let parts: Vec<&str> = path.split('.').collect();
        for p in &parts[..parts.len() - 1] {
            cur = &mut cur[*p];
        }
        cur[*parts.last().unwrap()] = value;
        m
    };
    let json_cases: Vec<(&str, Value, u16, Vec<&str>)> = vec![
        ("/v1/analyze", json!([1, 2]), 422, vec![""]),
        ("/v1/analyze", json!({}), 422, vec!["model"]),
        (
            "/v1/analyze",
            json!({"model": cv, "extra": 1}),
            422,
            vec!["extra"],
        ),
        (
            "/v1/analyze",
            json!({"model": cv, "set": {"q": "x"}}),
            422,
            vec!["set.q"],
        ),
        (
            "/v1/analyze",
            json!({"model": cv, "set": [1]}),
            422,
            vec!["set"],
        ),
        // A value that makes a valid model invalid: where (φ), and that `set` did it.
        (
            "/v1/analyze",
            json!({"model": cv, "set": {"q": -3}}),
            422,
            vec!["model.system.phi[0]", "set"],
        ),
        (
            "/v1/jobs",
            json!({"kind": "monte_carlo", "runs": 2, "model": cv, "set": {"q": -3}}),
            422,
            vec!["model.system.phi[0]", "set"],
        ),
        (
            "/v1/analyze",
            json!({"model": cv, "set": {"nope": 1}}),
            422,
            vec!["set.nope"],
        ),
        (
            "/v1/analyze",
            json!({"model": with("time.t_end", json!("soon"))}),
            422,
            vec!["model.time.t_end"],
        ),
        (
            "/v1/analyze",
            json!({"model": with("system.a", json!([[0, 1], [0]]))}),
            422,
            vec!["model.system.a[1]"],
        ),
        (
            "/v1/analyze",
            json!({"model": cv, "model_id": "x"}),
            422,
            vec!["model_id"],
        ),
        (
            "/v1/analyze",
            json!({"model_id": "missing"}),
            422,
            vec!["model_id"],
        ),
        ("/v1/analyze", json!({"model_id": 7}), 422, vec!["model_id"]),
        ("/v1/jobs", json!({"model": cv}), 422, vec!["kind"]),
        (
            "/v1/jobs",
            json!({"kind": "alchemy", "model": cv}),
            422,
            vec!["kind"],
        ),
        (
            "/v1/jobs",
            json!({"kind": 3, "model": cv}),
            422,
            vec!["kind"],
        ),
        (
            "/v1/jobs",
            json!({"kind": "analysis", "model": with("measurement.psi", json!(["-r"]))}),
            422,
            vec![],
        ),
        ("/v1/models", with("time", json!(1)), 422, vec!["time"]),
        (
            "/v1/models",
            json!({"time": 1}),
            422,
            vec!["system", "measurement"],
        ),
        (
            "/v1/models",
            with("system.states", json!("x")),
            422,
            vec!["system.states"],
        ),
    ];
    for (path, body, status, paths) in json_cases {
        let r = s.post(path, &body);
        assert_eq!(r.status, status, "POST {path} {body}: {}", r.text);
        assert_eq!(r.content_type, "application/problem+json", "{}", r.text);
        assert_eq!(r.json()["status"], status);
        if !paths.is_empty() {
            assert_eq!(r.error_paths(), paths, "POST {path} {body}");
        } else {
            assert!(!r.error_paths().is_empty(), "{}", r.text);
        }
    }
    // Not JSON, wrong media type, too large.
    let r = s.post_raw("/v1/analyze", "application/json", "{\"model\": ");
    assert_eq!(
        (r.status, r.error_paths()),
        (400, vec![String::new()]),
        "{}",
        r.text
    );
    assert_eq!(r.json()["type"], "urn:kea:problem:malformed-json");
    // A key twice: refused, not the last one run silently.
    let twice = format!("{{\"model\": {cv}, \"model\": {cv}}}");
    let r = s.post_raw("/v1/analyze", "application/json", &twice);
    assert_eq!(r.status, 400, "{}", r.text);
    assert!(r.text.contains("appears twice"), "{}", r.text);
    let r = s.post_raw("/v1/jobs", "text/plain", "{}");
    assert_eq!(r.status, 415, "{}", r.text);
    // "+json" alone is no media type, and a charset other than UTF-8 would be read as
    // UTF-8 regardless: both were answered 200. A …+json type and UTF-8 still pass.
    for ct in [
        "+json",
        "application/json; charset=latin1",
        "application/json;charset=utf-16",
    ] {
        let r = s.post_raw("/v1/analyze", ct, "{}");
        assert_eq!(r.status, 415, "{ct}: {}", r.text);
    }
    let r = s.post_raw("/v1/analyze", "application/json; charset=latin1", "{}");
    assert!(r.text.contains("not charset=latin1"), "{}", r.text);
    for ct in [
        "application/json; charset=UTF-8",
        "application/vnd.kea+json",
        "Application/JSON",
    ] {
        let r = s.post_raw("/v1/analyze", ct, "{}");
        assert_eq!(r.status, 422, "{ct}: {}", r.text);
    }
    // A compressed body: said so, not "not valid JSON".
    let r = s.post_with(
        "/v1/jobs",
        &[
            ("content-type", "application/json"),
            ("content-encoding", "gzip"),
        ],
        "{}",
    );
    assert_eq!(r.status, 415, "{}", r.text);
    assert!(r.text.contains("must not be compressed"), "{}", r.text);
    let big = format!("{{\"pad\": \"{}\"}}", "x".repeat(200_000));
    let r = s.post_raw("/v1/models", "application/json", &big);
    assert_eq!(r.status, 413, "{}", r.text);
    assert_eq!(r.content_type, "application/problem+json");
    // Unknown things.
    for path in [
        "/v1/jobs/nope",
        "/v1/jobs/nope/result",
        "/v1/jobs/nope/traces.csv",
        "/v1/jobs/nope/events",
        "/v1/models/nope",
        "/v1/nothing",
    ] {
        let r = s.get(path);
        assert_eq!(r.status, 404, "GET {path}: {}", r.text);
        assert_eq!(r.content_type, "application/problem+json");
    }
    let r = s.get("/v1/models?limit=0");
    assert_eq!(
        (r.status, r.error_paths()),
        (400, vec!["limit".to_string()])
    );
    let r = s.get("/v1/models?color=red");
    assert_eq!(
        (r.status, r.error_paths()),
        (400, vec!["color".to_string()])
    );
    let r = s.delete("/v1/presets");
    assert_eq!(r.status, 405, "{}", r.text);
    assert_eq!(r.content_type, "application/problem+json");
}

/// A path parameter that percent-decodes to no UTF-8 text is a problem+json 400 that
/// names the parameter and says what it should be (axum answered text/plain "Invalid
/// URL: Invalid UTF-8 in `id`").
#[test]
fn a_path_parameter_that_is_not_utf8_is_a_problem() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let cases = [
        ("GET", "/v1/jobs/%ff", "id", "job id"),
        ("DELETE", "/v1/jobs/%ff", "id", "job id"),
        ("GET", "/v1/jobs/%ff/result", "id", "job id"),
        ("GET", "/v1/jobs/%ff/traces.csv", "id", "job id"),
        ("GET", "/v1/jobs/%ff/events", "id", "job id"),
        ("GET", "/v1/models/%ff", "id", "model id"),
        ("DELETE", "/v1/models/%ff", "id", "model id"),
        ("GET", "/v1/presets/%ff%fe", "name", "preset name"),
    ];
    for (method, path, param, expected) in cases {
        let r = match method {
            "GET" => s.get(path),
            _ => s.delete(path),
        };
        assert_eq!(r.status, 400, "{method} {path}: {}", r.text);
        assert_eq!(r.content_type, "application/problem+json", "{}", r.text);
        assert_eq!(r.error_paths(), vec![param], "{}", r.text);
        let message = r.json()["errors"][0]["message"]
            .as_str()
            .unwrap()
            .to_string();
        assert!(message.contains(expected), "{message}");
        assert!(message.contains("UTF-8"), "{message}");
    }
}

/// At most 100 errors are listed, then one entry at the top level counts the rest,
/// and `detail` counts them all: for the server's own checks (300 unknown members gave
/// 300 entries) as for the core's (the entry sat at `model` for `set` names, and
/// `detail` said "(and 100 more)" of 400).
#[test]
fn at_most_100_errors_are_listed_and_the_rest_are_counted() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let cv = preset("cv-tracker");
    let many = |n: usize, value: Value| -> Value {
        (0..n)
            .map(|i| (format!("x{i:03}"), value.clone()))
            .collect::<serde_json::Map<_, _>>()
            .into()
    };
    let mut unknown_members = many(300, json!(1));
    unknown_members["model"] = cv.clone();
    let cases = [
        ("unknown members", unknown_members, 300, "x000"),
        (
            "set values",
            json!({"model": cv, "set": many(300, json!("x"))}),
            300,
            "set.x000",
        ),
        (
            "set names",
            json!({"model": cv, "set": many(400, json!(1))}),
            400,
            "set.x000",
        ),
    ];
    for (what, body, total, first) in cases {
        for route in ["/v1/analyze", "/v1/jobs"] {
            let mut body = body.clone();
            if route == "/v1/jobs" {
                body["kind"] = json!("analysis");
            }
            let r = s.post(route, &body);
            assert_eq!(r.status, 422, "{what}: {}", r.text);
            let problem = r.json();
            let errors = problem["errors"].as_array().unwrap();
            assert_eq!(errors.len(), 101, "{what} at {route}");
            assert_eq!(errors[0]["path"], first, "{what}");
            assert_eq!(errors[100]["path"], "", "{what}");
            let more = total - 100;
            assert_eq!(
                errors[100]["message"],
                format!("… and {more} more errors (only the first 100 are listed)"),
                "{what}"
            );
            let detail = problem["detail"].as_str().unwrap();
            let all_but_one = total - 1;
            assert!(
                detail.ends_with(&format!("(and {all_but_one} more)")),
                "{what}: {detail}"
            );
        }
    }
}

type Headers = std::collections::BTreeMap<String, String>;

#[test]
fn cors_answers_only_the_configured_origins() {
    let dir = tmp();
    let ui = "https://ui.example";
    let s = Server::start(dir.path(), &["--cors-origin", ui, "--token", "t0ken"]);
    // The browser's preflight for an authorised JSON POST: answered before the token
    // check, for the configured origin only.
    let preflight = |origin: &str| {
        s.headers_of(
            "OPTIONS",
            "/v1/analyze",
            &[
                ("origin", origin),
                ("access-control-request-method", "POST"),
                (
                    "access-control-request-headers",
                    "authorization,content-type",
                ),
            ],
        )
    };
    // A response header's value; a header list that must name every one of `words`.
    let header = |h: &Headers, name: &str| h.get(name).cloned();
    let lists = |h: &Headers, name: &str, words: &[&str]| {
        let list = h[name].to_lowercase();
        assert!(words.iter().all(|w| list.contains(w)), "{name}: {list}");
    };
    let (status, h) = preflight(ui);
    assert_eq!(status, 200, "{h:?}");
    assert_eq!(
        header(&h, "access-control-allow-origin").as_deref(),
        Some(ui)
    );
    lists(&h, "access-control-allow-methods", &["post", "delete"]);
    lists(
        &h,
        "access-control-allow-headers",
        &["authorization", "content-type"],
    );
    assert_eq!(
        header(&h, "access-control-max-age").as_deref(),
        Some("3600")
    );
    let (_, h) = preflight("https://other.example");
    assert!(!h.contains_key("access-control-allow-origin"), "{h:?}");

    // An actual request: the origin is allowed, and Location / x-request-id readable.
    let (status, h) = s.headers_of(
        "GET",
        "/v1/presets",
        &[("origin", ui), ("authorization", "Bearer t0ken")],
    );
    assert_eq!(status, 200);
    assert_eq!(
        header(&h, "access-control-allow-origin").as_deref(),
        Some(ui)
    );
    lists(
        &h,
        "access-control-expose-headers",
        &["location", "x-request-id"],
    );
    let (_, h) = s.headers_of(
        "GET",
        "/v1/presets",
        &[
            ("origin", "https://other.example"),
            ("authorization", "Bearer t0ken"),
        ],
    );
    assert!(!h.contains_key("access-control-allow-origin"), "{h:?}");

    // Without --cors-origin there is no CORS at all.
    let dir2 = tmp();
    let plain = Server::start(dir2.path(), &[]);
    let (_, h) = plain.headers_of("GET", "/v1/presets", &[("origin", ui)]);
    assert!(!h.keys().any(|k| k.starts_with("access-control-")), "{h:?}");
}

/// A chain of `n` states with `l` noise sources of each kind, b(t) all time-dependent
/// (`sin(k*t)/1e3`, each entry its own expression), Γ constant.
fn heavy_inputs_model(n: usize, l: usize, steps: u64) -> Value {
    let a: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| {
                    if i == j {
                        -1.0
                    } else if j == i + 1 {
                        1.0
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    let b: Vec<Vec<String>> = (0..n)
        .map(|i| {
            (0..l)
                .map(|k| format!("sin({}*t)/1e3", i * l + k + 1))
                .collect()
        })
        .collect();
    let gamma: Vec<Vec<f64>> = (0..n)
        .map(|j| (0..l).map(|m| if m == j { 1.0 } else { 0.01 }).collect())
        .collect();
    let c: Vec<Vec<f64>> = (0..n)
        .map(|j| (0..n).map(|i| if i == j { 1.0 } else { 0.0 }).collect())
        .collect();
    json!({
        "time": {"t0": 0, "t_end": steps as f64 * 1e-3, "steps": steps},
        "system": {"states": (0..n).map(|i| format!("x{i}")).collect::<Vec<_>>(),
                   "a": a, "b": b, "phi": vec![1.0; l], "eta0": vec![1.0; n]},
        "measurement": {"names": (0..n).map(|j| format!("z{j}")).collect::<Vec<_>>(),
                        "c": c, "gamma": gamma, "psi": vec![1.0; l]},
        "options": {"trace_points": 10, "steady_state_shortcut": false}
    })
}

/// The work estimate counts what a step does with L and M noise sources and with
/// time-dependent expressions: N = 10, L = M = 200 and 2000 expressions in b(t) took
/// 30–53 s over 170 000 steps while estimated at 4.76e8 (N³ + 16N² + 200 alone), below
/// the synchronous limit, so POST /v1/analyze ran it and blocked the server.
#[test]
fn heavy_inputs_are_not_answered_synchronously() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let started = std::time::Instant::now();
    let r = s.post(
        "/v1/analyze",
        &json!({"model": heavy_inputs_model(10, 200, 170_000)}),
    );
    assert_eq!(r.status, 422, "{}", &r.text[..r.text.len().min(500)]);
    assert_eq!(r.json()["type"], "urn:kea:problem:use-a-job");
    assert_eq!(r.error_paths(), vec!["model.time.steps"]);
    let message = r.json()["errors"][0]["message"]
        .as_str()
        .unwrap()
        .to_string();
    assert!(
        message.contains("2000 expressions in t") && message.contains("inputs varying in t"),
        "{message}"
    );
    assert!(
        started.elapsed() < Duration::from_secs(10),
        "{:?}",
        started.elapsed()
    );
    // The same model over few steps is small enough, and runs.
    let r = s.post(
        "/v1/analyze",
        &json!({"model": heavy_inputs_model(10, 200, 500)}),
    );
    assert_eq!(r.status, 200, "{}", &r.text[..r.text.len().min(500)]);
    // A job of it reports the estimate: ≈ 1.7e5 units a step, not N³ + 16N² + 200.
    let job = s.post(
        "/v1/jobs",
        &json!({"kind": "analysis", "model": heavy_inputs_model(10, 200, 500)}),
    );
    assert_eq!(job.status, 202, "{}", job.text);
    let per_step = job.json()["work"].as_f64().unwrap() / 500.0;
    assert!((1e5..3e5).contains(&per_step), "{per_step}");
}

/// Every list route refuses a query it cannot honour with 400 naming the parameter: a
/// cursor that no page gave (it was read as "from the start"), an empty one (it gave
/// an empty page) and a repeated parameter (the last one silently won).
#[test]
fn query_parameters_are_checked() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    for name in ["cv-tracker", "seed-example"] {
        assert_eq!(s.post("/v1/models", &preset(name)).status, 201);
    }
    for _ in 0..2 {
        let job = s.submit_analysis(preset("cv-tracker"));
        s.wait_finished(&job, LONG);
    }
    let refused = |query: &str, path: &str| {
        let r = s.get(query);
        assert_eq!(r.status, 400, "GET {query}: {}", r.text);
        assert_eq!(r.content_type, "application/problem+json", "{query}");
        assert_eq!(r.json()["status"], 400);
        assert_eq!(r.error_paths(), vec![path.to_string()], "GET {query}");
        r.json()["errors"][0]["message"]
            .as_str()
            .unwrap()
            .to_string()
    };
    for list in ["/v1/models", "/v1/jobs"] {
        let m = refused(&format!("{list}?cursor=garbage"), "cursor");
        assert!(m.contains("next_cursor"), "{m}");
        let m = refused(&format!("{list}?cursor="), "cursor");
        assert!(m.contains("empty"), "{m}");
        let m = refused(&format!("{list}?limit=1&limit=2"), "limit");
        assert!(m.contains("2 times"), "{m}");
        refused(&format!("{list}?limit=1&cursor=x&cursor=y"), "cursor");
        // A real cursor, but not as the server wrote it: upper case is the same UUID
        // (RFC 9562), without its hyphens it is not a cursor.
        let page = s.get(&format!("{list}?limit=1")).json();
        let cursor = page["next_cursor"].as_str().unwrap().to_string();
        let upper = s.get(&format!("{list}?limit=1&cursor={}", cursor.to_uppercase()));
        assert_eq!(upper.status, 200, "{}", upper.text);
        refused(
            &format!("{list}?cursor={}", cursor.replace('-', "")),
            "cursor",
        );
        // As written, it continues the listing.
        let next = s.get(&format!("{list}?limit=1&cursor={cursor}"));
        assert_eq!(next.status, 200, "{}", next.text);
        assert_eq!(next.json()["items"].as_array().unwrap().len(), 1);
    }
    refused("/v1/jobs?status=queued&status=running", "status");
    refused("/v1/jobs?status=", "status");
    let m = refused("/v1/presets?limit=1", "limit");
    assert!(m.contains("takes none"), "{m}");
    assert_eq!(s.get("/v1/presets").status, 200);
    // "+5" (%2B: a bare + is a space) is not the integer the spec asks for (Rust's
    // parse would take it).
    for list in ["/v1/models", "/v1/jobs"] {
        let m = refused(&format!("{list}?limit=%2B5"), "limit");
        assert!(m.contains("`+5`"), "{m}");
    }
    // Routes that read no query refuse one, as the lists refuse an unknown one;
    // the health check ignores its query.
    let model = s.post("/v1/models", &preset("cv-tracker"));
    let id = model.json()["id"].as_str().unwrap().to_string();
    let job = s.submit_analysis(preset("cv-tracker"));
    s.wait_finished(&job, LONG);
    for route in [
        "/v1/presets/cv-tracker".to_string(),
        format!("/v1/models/{id}"),
        format!("/v1/jobs/{job}"),
        format!("/v1/jobs/{job}/result"),
        format!("/v1/jobs/{job}/traces.csv"),
    ] {
        let m = refused(&format!("{route}?fields=y"), "fields");
        assert!(m.contains("takes none"), "{route}: {m}");
        assert_eq!(s.get(&route).status, 200, "{route}");
    }
    let r = s.post("/v1/analyze?wait=1", &preset("cv-tracker"));
    assert_eq!(r.status, 400, "{}", r.text);
    assert_eq!(r.error_paths(), vec!["wait".to_string()]);
    assert_eq!(s.get("/healthz?probe=1").status, 200);
}

/// Job requests' errors name the member and say what is expected, in the API's words:
/// serde's "missing field `target`" at the root, "invalid value: map, expected map
/// with a single key", "invalid type: string \"5\", expected u64" leaked through.
#[test]
fn job_request_errors_name_the_member_and_what_is_expected() {
    let dir = tmp();
    let s = Server::start(dir.path(), &[]);
    let cv = preset("cv-tracker");
    let target = json!({"criterion": "yx", "threshold": 2});
    let bisect = json!({"param": "q", "low": 0.1, "high": 10});
    let mut bad_t_end = cv.clone();
    bad_t_end["time"]["t_end"] = json!("soon");
    let cases: Vec<(Value, Vec<&str>, Vec<&str>)> = vec![
        (
            json!({"kind": "synthesis", "model": cv, "mode": {"bisect": bisect}}),
            vec!["target"],
            vec!["missing", "criterion", "threshold"],
        ),
        (
            json!({"kind": "synthesis", "model": cv, "target": target}),
            vec!["mode"],
            vec!["missing", "seed_search", "bisect", "grid"],
        ),
        (
            json!({"kind": "synthesis", "model": cv}),
            vec!["target", "mode"],
            vec!["missing"],
        ),
        (
            json!({"kind": "synthesis", "model": cv, "target": target,
                   "mode": {"bisect": bisect, "grid": {"params": []}}}),
            vec!["mode"],
            vec!["exactly one", "seed_search", "bisect", "grid", "got 2"],
        ),
        (
            json!({"kind": "synthesis", "model": cv, "target": target, "mode": {}}),
            vec!["mode"],
            vec!["exactly one", "empty"],
        ),
        (
            json!({"kind": "synthesis", "model": cv, "target": target, "mode": "bisect"}),
            vec!["mode"],
            vec!["expected an object", "got a string"],
        ),
        (
            json!({"kind": "synthesis", "model": cv, "target": target, "mode": {"newton": {}}}),
            vec!["mode.newton"],
            vec!["unknown mode", "seed_search, bisect, grid"],
        ),
        (
            json!({"kind": "synthesis", "model": cv, "target": {"threshold": 2},
                   "mode": {"bisect": bisect}}),
            vec!["target.criterion"],
            vec!["missing", "yz, zx, yx"],
        ),
        (
            json!({"kind": "synthesis", "model": cv, "target": {"criterion": "yx", "threshold": "2"},
                   "mode": {"bisect": bisect}}),
            vec!["target.threshold"],
            vec!["expected a number", "got a string"],
        ),
        (
            json!({"kind": "synthesis", "model": cv, "target": target,
                   "mode": {"bisect": {"low": 1, "high": 2}}}),
            vec!["mode.bisect.param"],
            vec!["missing", "param"],
        ),
        (
            json!({"kind": "monte_carlo", "model": cv, "runs": "5"}),
            vec!["runs"],
            vec!["expected a whole number of runs", "got a string"],
        ),
        (
            json!({"kind": "simulation", "model": cv, "runs": 5, "truth": "real"}),
            vec!["truth"],
            vec!["\"process\"", "\"mean\""],
        ),
        (
            json!({"kind": "monte_carlo", "model": cv, "runs": 5, "model_error": 3}),
            vec!["model_error"],
            vec!["\"white\"", "\"constant\"", "got 3"],
        ),
        (
            json!({"kind": "analysis", "model": bad_t_end}),
            vec!["model.time.t_end"],
            vec!["expected a number", "got a string"],
        ),
    ];
    let serde_words = [
        "missing field",
        "invalid type",
        "invalid value",
        "single key",
        "variant",
        "f64",
        "u64",
        "usize",
        "struct ",
        "sequence",
    ];
    for (body, paths, words) in cases {
        let r = s.post("/v1/jobs", &body);
        assert_eq!(r.status, 422, "{body}: {}", r.text);
        assert_eq!(r.error_paths(), paths, "{}", r.text);
        let messages: Vec<String> = r.json()["errors"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["message"].as_str().unwrap().to_string())
            .collect();
        let all = messages.join(" | ");
        for w in &words {
            assert!(all.contains(w), "`{w}` not in {all}");
        }
        for w in serde_words {
            assert!(!all.contains(w), "serde's `{w}` in {all}");
        }
    }
}

/// What GET /v1/jobs/{id} reports never goes back, around a cancel too (polls showed
/// 0.0903, then DELETE, then 0.0899: the cancelled job showed the progress last
/// written to the store), and a requested cancel shows before the job stops.
#[test]
fn progress_never_goes_back_and_a_requested_cancel_shows() {
    let dir = tmp();
    let s = Server::start(dir.path(), &["--workers", "1"]);
    let id = s.submit_analysis(long_model(50_000_000));
    let path = format!("/v1/jobs/{id}");
    let first = s.wait_job(&id, LONG, |j| {
        j["status"] == "running" && j["progress"].as_f64().unwrap() > 0.0
    });
    assert_eq!(first["cancel_requested"], false, "{first}");
    let mut seen = vec![first["progress"].as_f64().unwrap()];
    // Long enough for the progress to be written to the store (every 0.5 s).
    let until = std::time::Instant::now() + Duration::from_millis(800);
    while std::time::Instant::now() < until {
        seen.push(s.get(&path).json()["progress"].as_f64().unwrap());
        std::thread::sleep(Duration::from_millis(5));
    }
    let c = s.delete(&path);
    assert_eq!(c.status, 200, "{}", c.text);
    assert_eq!(c.json()["cancel_requested"], true);
    seen.push(c.json()["progress"].as_f64().unwrap());
    let done = loop {
        let job = s.get(&path).json();
        assert_eq!(job["cancel_requested"], true, "{job}");
        seen.push(job["progress"].as_f64().unwrap());
        if job["status"] != "running" {
            break job;
        }
    };
    assert_eq!(done["status"], "cancelled", "{done}");
    for _ in 0..3 {
        seen.push(s.get(&path).json()["progress"].as_f64().unwrap());
    }
    let back: Vec<(f64, f64)> = seen
        .windows(2)
        .filter(|w| w[1] < w[0])
        .map(|w| (w[0], w[1]))
        .collect();
    assert!(back.is_empty(), "progress went back: {back:?}");
    let listed = s.get("/v1/jobs?status=cancelled").json();
    assert_eq!(listed["items"][0]["cancel_requested"], true);
    let events = s.events(&format!("{path}/events"));
    assert_eq!(events.last().unwrap().1["cancel_requested"], true);
    // A job never asked to cancel says so when it has finished.
    let other = s.submit_analysis(preset("cv-tracker"));
    assert_eq!(s.wait_finished(&other, LONG)["cancel_requested"], false);
}

/// A synthesis stopped by a shutdown resumes after the restart from the analyses it
/// had finished, kept in the store: its result is an uninterrupted run's, but for
/// `recalled_analyses` (how many it did not run again) and the timing. (Before, a
/// re-queued job started over.)
#[test]
fn a_synthesis_resumes_after_a_restart_from_the_analyses_it_kept() {
    let dir = tmp();
    let mut model = preset("seed-example");
    model["time"]["steps"] = 20_000.into();
    let values: Vec<f64> = (0..600).map(|i| 1.0 + 0.025 * i as f64).collect();
    let request = json!({
        "kind": "synthesis",
        "model": model,
        "target": {"criterion": "yx", "threshold": 14},
        "mode": {"grid": {"params": [{"name": "f", "values": values}]}},
    });
    let mut s = Server::start(dir.path(), &["--shutdown-grace", "0"]);
    let r = s.post("/v1/jobs", &request);
    assert_eq!(r.status, 202, "{}", r.text);
    let id = r.json()["id"].as_str().unwrap().to_string();
    s.wait_job(&id, LONG, |j| j["progress"].as_f64().unwrap() >= 0.3);
    assert!(
        s.terminate(Duration::from_secs(30)),
        "kea serve exits on SIGTERM"
    );

    let s = Server::start(dir.path(), &[]);
    let resumed = s.wait_finished(&id, LONG);
    assert_eq!(resumed["status"], "succeeded", "{resumed}");
    let mut resumed = s.get(&format!("/v1/jobs/{id}/result")).json();
    // The same request again, uninterrupted.
    let r = s.post("/v1/jobs", &request);
    let again = r.json()["id"].as_str().unwrap().to_string();
    assert_eq!(s.wait_finished(&again, LONG)["status"], "succeeded");
    let mut whole = s.get(&format!("/v1/jobs/{again}/result")).json();

    assert_eq!(
        whole["recalled_analyses"],
        Value::Null,
        "{}",
        whole["analyses"]
    );
    let recalled = resumed["recalled_analyses"].as_u64().unwrap_or(0);
    let analyses = whole["analyses"].as_u64().unwrap();
    // At least the analyses kept by 30 % (less the last half second's), not all.
    assert!(
        recalled >= analyses / 5 && recalled < analyses,
        "{recalled} of {analyses} recalled"
    );
    for r in [&mut resumed, &mut whole] {
        let o = r.as_object_mut().unwrap();
        o.remove("timing");
        o.remove("recalled_analyses");
    }
    assert_eq!(resumed, whole);
}

/// The server process's CPU time so far (user + system, /proc's clock ticks).
fn cpu_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    // The fields after the command's closing parenthesis: utime and stime are 12th and 13th.
    let rest = &stat[stat.rfind(')').unwrap() + 2..];
    let fields: Vec<&str> = rest.split(' ').collect();
    fields[11].parse::<u64>().unwrap() + fields[12].parse::<u64>().unwrap()
}

/// A synchronous analysis its estimate lets through but that runs longer than the
/// synchronous time limit is stopped there (422, use a job), and one whose client
/// goes away stops: the server falls idle instead of computing for nobody.
#[test]
fn a_synchronous_analysis_stops_at_its_time_limit_and_when_its_client_goes() {
    use std::io::Write;
    let dir = tmp();
    let s = Server::start(
        dir.path(),
        &["--sync-work-limit", "inf", "--job-time-limit", "1"],
    );
    assert_eq!(s.get("/v1/limits").json()["server"]["sync_time_s"], 1);
    let started = std::time::Instant::now();
    let r = s.post("/v1/analyze", &json!({"model": long_model(100_000_000)}));
    assert_eq!(r.status, 422, "{}", r.text);
    let p = r.json();
    assert_eq!(p["type"], "urn:kea:problem:use-a-job");
    let detail = p["detail"].as_str().unwrap();
    assert!(
        detail.starts_with("stopped after 1 s, the limit of a synchronous analysis")
            && detail.contains("POST /v1/jobs"),
        "{detail}"
    );
    assert!(started.elapsed() < Duration::from_secs(20));

    // The default limit (60 s); the client sends its request and goes after 0.5 s.
    let dir = tmp();
    let s = Server::start(dir.path(), &["--sync-work-limit", "inf"]);
    assert_eq!(s.get("/v1/limits").json()["server"]["sync_time_s"], 60);
    let host = s.base.trim_start_matches("http://").to_string();
    let body = json!({"model": long_model(100_000_000)}).to_string();
    let mut tcp = std::net::TcpStream::connect(&host).unwrap();
    write!(
        tcp,
        "POST /v1/analyze HTTP/1.1\r\nHost: {host}\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let busy = cpu_ticks(s.pid());
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        cpu_ticks(s.pid()) > busy,
        "the analysis runs while its client waits"
    );
    drop(tcp);
    std::thread::sleep(Duration::from_millis(500));
    let before = cpu_ticks(s.pid());
    std::thread::sleep(Duration::from_secs(2));
    let spent = cpu_ticks(s.pid()) - before;
    // A tick is 10 ms: a run left going would have spent about 200.
    assert!(
        spent < 40,
        "{spent} ticks of CPU in the 2 s after the client went"
    );
    assert_eq!(s.get("/healthz").status, 200);
}

/// One nonlinear request — the reference scenario b's data as a CSV file for the
/// command line, as its text for the server — gives the same result, bit for bit,
/// from `kea nonlinear --json` and from a job; a bad request is 422 with the path.
#[test]
fn nonlinear_gives_the_same_bits_from_the_command_line_and_a_job() {
    let csv_path = common::repo().join("tests/data/nonlinear/b_wrong_model_manoeuvre.data.csv");
    let csv = std::fs::read_to_string(&csv_path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("data.csv"), &csv).unwrap();
    let request = json!({"model": "preset:seed-002", "data": {"csv": "data.csv"},
                         "q_scale": [0.1, 1, 10], "checkpoints": [1000], "trace_points": 50});
    let file = dir.path().join("request.json");
    std::fs::write(&file, request.to_string()).unwrap();
    let out = Command::new(common::KEA)
        .args(["nonlinear", file.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cli: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(cli["i_star"], 3); // (the reference's)

    let data = tempfile::tempdir().unwrap();
    let s = Server::start(data.path(), &[]);
    let mut job = request.clone();
    job["kind"] = json!("nonlinear");
    job["data"] = json!({"csv_text": csv});
    let reply = s.post("/v1/jobs", &job);
    assert_eq!(reply.status, 202, "{}", reply.text);
    let id = reply.json()["id"].as_str().unwrap().to_string();
    let done = s.wait_finished(&id, LONG);
    assert_eq!(done["status"], "succeeded", "{done}");
    let result = s.get(&format!("/v1/jobs/{id}/result")).json();
    assert_eq!(without_timing(result), without_timing(cli));

    job["procedure"] = json!({"alpha": [1, 1.5]});
    let bad = s.post("/v1/jobs", &job);
    assert_eq!(bad.status, 422, "{}", bad.text);
    assert!(bad.text.contains("procedure.alpha[1]"), "{}", bad.text);
}
