//! Test harness: start the real `kea` binary on a free port with a temporary data
//! directory, and speak HTTP to it.

#![allow(dead_code)]

use serde_json::Value;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

pub const KEA: &str = env!("CARGO_BIN_EXE_kea");

/// The repository root (presets, README, openapi.yaml).
pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

pub fn preset(name: &str) -> Value {
    serde_json::from_str(kea_core::presets::get_json(name).unwrap()).unwrap()
}

pub struct Server {
    child: Child,
    pub base: String,
    pub data_dir: PathBuf,
    agent: ureq::Agent,
    token: Option<String>,
}

pub struct Reply {
    pub status: u16,
    pub content_type: String,
    pub location: Option<String>,
    pub text: String,
}

impl Reply {
    pub fn json(&self) -> Value {
        serde_json::from_str(&self.text).unwrap_or_else(|e| panic!("not JSON ({e}): {}", self.text))
    }

    /// The `path`s of a problem's `errors`.
    pub fn error_paths(&self) -> Vec<String> {
        self.json()["errors"]
            .as_array()
            .unwrap_or_else(|| panic!("no errors member: {}", self.text))
            .iter()
            .map(|e| e["path"].as_str().unwrap().to_string())
            .collect()
    }
}

fn agent() -> ureq::Agent {
    ureq::Agent::config_builder()
        .http_status_as_error(false)
        .timeout_global(Some(Duration::from_secs(120)))
        .build()
        .into()
}

impl Server {
    /// Start `kea serve` on 127.0.0.1:0 with `data_dir` and extra arguments; waits
    /// for the "listening on" line.
    pub fn start(data_dir: &Path, args: &[&str]) -> Server {
        Server::start_binary(Path::new(KEA), data_dir, args)
    }

    /// [`Server::start`] with the kea executable at `kea`.
    pub fn start_binary(kea: &Path, data_dir: &Path, args: &[&str]) -> Server {
        let mut cmd = Command::new(kea);
        cmd.arg("serve")
            .arg("--addr")
            .arg("127.0.0.1:0")
            .arg("--data-dir")
            .arg(data_dir)
            .args(args)
            .env("KEA_LOG", "warn")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        for (k, _) in std::env::vars() {
            if k.starts_with("KEA_") {
                cmd.env_remove(k);
            }
        }
        cmd.env("KEA_LOG", "warn");
        let mut child = cmd.spawn().expect("start kea serve");
        let stdout = child.stdout.take().unwrap();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut lines = BufReader::new(stdout).lines();
            if let Some(Ok(line)) = lines.next() {
                let _ = tx.send(line);
            }
            for _ in lines {}
        });
        let line = rx
            .recv_timeout(Duration::from_secs(30))
            .expect("kea serve printed its address");
        let base = line
            .strip_prefix("kea: listening on ")
            .unwrap_or_else(|| panic!("unexpected first line: {line}"))
            .to_string();
        let token = args
            .iter()
            .position(|a| *a == "--token")
            .map(|i| args[i + 1].to_string());
        Server {
            child,
            base,
            data_dir: data_dir.to_path_buf(),
            agent: agent(),
            token,
        }
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// SIGKILL, as a crash.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// SIGTERM, then wait for the exit (up to `timeout`); returns whether it exited.
    pub fn terminate(&mut self, timeout: Duration) -> bool {
        let _ = Command::new("kill")
            .arg("-TERM")
            .arg(self.pid().to_string())
            .status();
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.child.try_wait() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }

    pub fn url(&self, path: &str) -> String {
        format!("{}{path}", self.base)
    }

    fn finish(&self, res: Result<ureq::http::Response<ureq::Body>, ureq::Error>) -> Reply {
        let mut res = res.expect("HTTP exchange");
        let header = |n: &str| {
            res.headers()
                .get(n)
                .and_then(|v| v.to_str().ok())
                .map(str::to_string)
        };
        let content_type = header("content-type").unwrap_or_default();
        let location = header("location");
        let status = res.status().as_u16();
        let text = res
            .body_mut()
            .with_config()
            .limit(64 * 1024 * 1024)
            .read_to_string()
            .unwrap_or_default();
        Reply {
            status,
            content_type,
            location,
            text,
        }
    }

    fn auth(&self) -> Option<String> {
        self.token.as_ref().map(|t| format!("Bearer {t}"))
    }

    pub fn get(&self, path: &str) -> Reply {
        let mut req = self.agent.get(self.url(path));
        if let Some(a) = self.auth() {
            req = req.header("authorization", a);
        }
        self.finish(req.call())
    }

    pub fn delete(&self, path: &str) -> Reply {
        let mut req = self.agent.delete(self.url(path));
        if let Some(a) = self.auth() {
            req = req.header("authorization", a);
        }
        self.finish(req.call())
    }

    pub fn post(&self, path: &str, body: &Value) -> Reply {
        self.post_raw(path, "application/json", &body.to_string())
    }

    pub fn post_raw(&self, path: &str, content_type: &str, body: &str) -> Reply {
        self.post_with(path, &[("content-type", content_type)], body)
    }

    /// A POST with explicit headers.
    pub fn post_with(&self, path: &str, headers: &[(&str, &str)], body: &str) -> Reply {
        let mut req = self.agent.post(self.url(path));
        for (k, v) in headers {
            req = req.header(*k, *v);
        }
        if let Some(a) = self.auth() {
            req = req.header("authorization", a);
        }
        self.finish(req.send(body))
    }

    /// A request with explicit headers (for auth tests).
    pub fn get_with(&self, path: &str, headers: &[(&str, &str)]) -> Reply {
        let mut req = self.agent.get(self.url(path));
        for (k, v) in headers {
            req = req.header(*k, *v);
        }
        self.finish(req.call())
    }

    /// A GET or OPTIONS with explicit headers; its status and every response header
    /// (lower-case names), for the CORS tests.
    pub fn headers_of(
        &self,
        method: &str,
        path: &str,
        headers: &[(&str, &str)],
    ) -> (u16, std::collections::BTreeMap<String, String>) {
        let mut req = match method {
            "OPTIONS" => self.agent.options(self.url(path)),
            "GET" => self.agent.get(self.url(path)),
            other => panic!("headers_of: method {other}"),
        };
        for (k, v) in headers {
            req = req.header(*k, *v);
        }
        let res = req.call().expect("HTTP exchange");
        let h = res
            .headers()
            .iter()
            .map(|(k, v)| (k.as_str().to_string(), v.to_str().unwrap_or("").to_string()))
            .collect();
        (res.status().as_u16(), h)
    }

    /// Submit an analysis job of `model`; its id.
    pub fn submit_analysis(&self, model: Value) -> String {
        self.post(
            "/v1/jobs",
            &serde_json::json!({"kind": "analysis", "model": model}),
        )
        .json()["id"]
            .as_str()
            .unwrap()
            .to_string()
    }

    /// Poll a job until `done(job)` or the timeout.
    pub fn wait_job(&self, id: &str, timeout: Duration, done: impl Fn(&Value) -> bool) -> Value {
        let deadline = Instant::now() + timeout;
        loop {
            let r = self.get(&format!("/v1/jobs/{id}"));
            assert_eq!(r.status, 200, "{}", r.text);
            let job = r.json();
            if done(&job) {
                return job;
            }
            assert!(
                Instant::now() < deadline,
                "job {id} did not reach the expected state in {timeout:?}: {job}"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    pub fn wait_finished(&self, id: &str, timeout: Duration) -> Value {
        self.wait_job(id, timeout, |j| {
            matches!(
                j["status"].as_str(),
                Some("succeeded" | "failed" | "cancelled")
            )
        })
    }

    /// Read a server-sent event stream to its end: (event, data) pairs.
    pub fn events(&self, path: &str) -> Vec<(String, Value)> {
        let mut req = self.agent.get(self.url(path));
        if let Some(a) = self.auth() {
            req = req.header("authorization", a);
        }
        let res = req.call().expect("events");
        assert_eq!(res.status().as_u16(), 200);
        let mut text = String::new();
        res.into_body()
            .into_reader()
            .read_to_string(&mut text)
            .expect("read event stream");
        parse_events(&text)
    }
}

/// A server-sent event stream's text as (event, data) pairs.
pub fn parse_events(text: &str) -> Vec<(String, Value)> {
    let mut out = Vec::new();
    for block in text.split("\n\n") {
        let mut event = None;
        let mut data = None;
        for line in block.lines() {
            if let Some(e) = line.strip_prefix("event: ") {
                event = Some(e.to_string());
            } else if let Some(d) = line.strip_prefix("data: ") {
                data = Some(serde_json::from_str(d).expect("event data is JSON"));
            }
        }
        if let (Some(e), Some(d)) = (event, data) {
            out.push((e, d));
        }
    }
    out
}

impl Drop for Server {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Remove `timing` (wall-clock time differs between runs) from a result.
pub fn without_timing(mut v: Value) -> Value {
    v.as_object_mut().unwrap().remove("timing");
    v
}

/// A model with more steps (and no steady-state shortcut), for long jobs.
pub fn long_model(steps: u64) -> Value {
    let mut m = preset("cv-tracker");
    m["time"]["steps"] = steps.into();
    m["options"]["steady_state_shortcut"] = false.into();
    m
}

/// A small identification job: an AR(1) x_k = a x_{k−1} + F, z = x + Φ, with a and the
/// process noise's SKO q estimated from 60 inline rows (a fixed, deterministic series).
pub fn identification_job() -> Value {
    let rows: Vec<Value> = (1..=60)
        .map(|k| {
            let k = k as f64;
            serde_json::json!([k, 0.8 * (1.7 * k).sin() + 0.3 * (0.37 * k).cos()])
        })
        .collect();
    serde_json::json!({
        "kind": "identification",
        "model": {
            "kea_model": 1,
            "name": "ar1",
            "params": {"a": 0.5, "q": 0.5},
            "time": {"t0": 0, "t_end": 60, "steps": 60},
            "system": {"states": ["x"], "transition": [["a"]], "b": [[1]], "phi": ["q"],
                       "eta0": [1]},
            "measurement": {"names": ["z"], "c": [[1]], "gamma": [[1]], "psi": [0.3]}
        },
        "data": {"rows": rows},
        "estimate": {"a": {"initial": 0.5, "min": -0.99, "max": 0.99}, "q": {"initial": 0.5, "min": 0.01}},
        "expected_information": true
    })
}
