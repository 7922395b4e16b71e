//! `openapi.yaml` is kept true: its paths and methods are exactly the route table,
//! the README's example requests validate against it, and real responses validate
//! against its schemas.

mod common;

use common::{Server, preset};
use serde_json::{Value, json};
use std::cell::RefCell;
use std::collections::BTreeSet;

fn spec() -> Value {
    let text = std::fs::read_to_string(common::repo().join("openapi.yaml")).unwrap();
    serde_yaml_ng::from_str(&text).expect("openapi.yaml parses")
}

const METHODS: &[&str] = &["get", "post", "put", "patch", "delete", "head", "options"];

fn spec_routes(spec: &Value) -> BTreeSet<(String, String)> {
    let mut out = BTreeSet::new();
    for (path, item) in spec["paths"].as_object().unwrap() {
        for m in METHODS {
            if item.get(*m).is_some() {
                out.insert((m.to_uppercase(), path.clone()));
            }
        }
    }
    out
}

#[test]
fn every_served_route_is_in_the_spec_and_vice_versa() {
    let served: BTreeSet<(String, String)> = kea_server::serve::routes::route_queries()
        .into_iter()
        .map(|(method, path, _)| (method, path))
        .collect();
    let documented = spec_routes(&spec());
    let missing: Vec<_> = served.difference(&documented).collect();
    let extra: Vec<_> = documented.difference(&served).collect();
    assert!(
        missing.is_empty(),
        "served but not in openapi.yaml: {missing:?}"
    );
    assert!(
        extra.is_empty(),
        "in openapi.yaml but not served: {extra:?}"
    );
}

/// Each route reads exactly the query parameters the spec documents for it (the
/// server refuses any other with a 400; the health check ignores its query).
#[test]
fn every_route_reads_the_query_parameters_the_spec_documents() {
    let spec = spec();
    for (method, path, served) in kea_server::serve::routes::route_queries() {
        let item = &spec["paths"][&path];
        let op = &item[method.to_lowercase().as_str()];
        let mut documented = BTreeSet::new();
        for p in [&item["parameters"], &op["parameters"]] {
            for p in p.as_array().into_iter().flatten() {
                let p = match p["$ref"].as_str() {
                    Some(r) => {
                        let name = r.strip_prefix("#/components/parameters/").unwrap();
                        &spec["components"]["parameters"][name]
                    }
                    None => p,
                };
                if p["in"] == "query" {
                    documented.insert(p["name"].as_str().unwrap().to_string());
                }
            }
        }
        let served: BTreeSet<String> = served.into_iter().collect();
        assert_eq!(served, documented, "{method} {path}: read vs documented");
    }
}

/// A small JSON Schema validator for the subset openapi.yaml uses: type (or a list),
/// required, properties, additionalProperties, items, minItems, maxItems, enum, const,
/// oneOf, allOf, minimum, maximum, exclusiveMinimum, exclusiveMaximum and local `$ref`s.
///
/// Stricter than JSON Schema in one way, on purpose: an object schema that lists
/// `properties` and says nothing of `additionalProperties` is closed (with the
/// properties of its `allOf` siblings), so a member the server sends that the spec
/// does not document is an error. It records the `$ref`s it followed, so a test can
/// check that every schema a response can use was met by a real response.
struct Validator<'a> {
    root: &'a Value,
    visited: RefCell<BTreeSet<String>>,
}

impl<'a> Validator<'a> {
    fn new(root: &'a Value) -> Self {
        Validator {
            root,
            visited: RefCell::new(BTreeSet::new()),
        }
    }

    fn resolve(&self, r: &str) -> &'a Value {
        let target = r
            .trim_start_matches("#/")
            .split('/')
            .fold(self.root, |node, key| &node[key]);
        assert!(!target.is_null(), "dangling $ref {r}");
        target
    }

    /// The property names `schema` documents, through `$ref`s and `allOf`.
    fn property_names(&self, schema: &Value, out: &mut BTreeSet<String>) {
        if let Some(r) = schema.get("$ref").and_then(Value::as_str) {
            return self.property_names(self.resolve(r), out);
        }
        if let Some(p) = schema.get("properties").and_then(Value::as_object) {
            out.extend(p.keys().cloned());
        }
        for s in schema
            .get("allOf")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
        {
            self.property_names(s, out);
        }
    }

    fn check(&self, schema: &Value, v: &Value, path: &str, errors: &mut Vec<String>) {
        self.check_with(schema, v, path, &BTreeSet::new(), errors)
    }

    /// `siblings`: property names documented by the `allOf` this schema is part of.
    fn check_with(
        &self,
        schema: &Value,
        v: &Value,
        path: &str,
        siblings: &BTreeSet<String>,
        errors: &mut Vec<String>,
    ) {
        if let Some(r) = schema.get("$ref").and_then(Value::as_str) {
            self.visited.borrow_mut().insert(r.to_string());
            return self.check_with(self.resolve(r), v, path, siblings, errors);
        }
        if let Some(t) = schema.get("type") {
            let types: Vec<&str> = match t {
                Value::String(s) => vec![s.as_str()],
                Value::Array(a) => a.iter().filter_map(Value::as_str).collect(),
                _ => vec![],
            };
            let ok = types.iter().any(|t| match *t {
                "object" => v.is_object(),
                "array" => v.is_array(),
                "string" => v.is_string(),
                "number" => v.is_number(),
                "integer" => v.is_u64() || v.is_i64(),
                "boolean" => v.is_boolean(),
                "null" => v.is_null(),
                _ => false,
            });
            if !ok {
                errors.push(format!("{path}: expected {types:?}, got {v}"));
                return;
            }
        }
        if let Some(c) = schema.get("const")
            && c != v
        {
            errors.push(format!("{path}: expected {c}, got {v}"));
        }
        if let Some(e) = schema.get("enum").and_then(Value::as_array)
            && !e.contains(v)
        {
            errors.push(format!("{path}: {v} not in {e:?}"));
        }
        if let Some(x) = v.as_f64() {
            let bound = |k: &str| schema.get(k).and_then(Value::as_f64);
            for (k, bad) in [
                ("minimum", bound("minimum").is_some_and(|b| x < b)),
                ("maximum", bound("maximum").is_some_and(|b| x > b)),
                (
                    "exclusiveMinimum",
                    bound("exclusiveMinimum").is_some_and(|b| x <= b),
                ),
                (
                    "exclusiveMaximum",
                    bound("exclusiveMaximum").is_some_and(|b| x >= b),
                ),
            ] {
                if bad {
                    errors.push(format!("{path}: {x} breaks {k} {}", schema[k]));
                }
            }
        }
        if let Some(all) = schema.get("allOf").and_then(Value::as_array) {
            let mut names = siblings.clone();
            self.property_names(schema, &mut names);
            for s in all {
                self.check_with(s, v, path, &names, errors);
            }
        }
        if let Some(one) = schema.get("oneOf").and_then(Value::as_array) {
            let passing = one
                .iter()
                .filter(|s| {
                    let mut e = Vec::new();
                    self.check_with(s, v, path, siblings, &mut e);
                    e.is_empty()
                })
                .count();
            if passing != 1 {
                errors.push(format!(
                    "{path}: matches {passing} of oneOf, expected exactly 1"
                ));
            }
        }
        if let Some(obj) = v.as_object() {
            if let Some(req) = schema.get("required").and_then(Value::as_array) {
                for r in req.iter().filter_map(Value::as_str) {
                    if !obj.contains_key(r) {
                        errors.push(format!("{path}: missing `{r}`"));
                    }
                }
            }
            let props = schema.get("properties").and_then(Value::as_object);
            for (k, x) in obj {
                let sub = format!("{path}.{k}");
                match props.and_then(|p| p.get(k)) {
                    Some(s) => self.check(s, x, &sub, errors),
                    None => match schema.get("additionalProperties") {
                        Some(Value::Bool(false)) if !siblings.contains(k) => {
                            errors.push(format!("{sub}: not allowed"))
                        }
                        Some(s @ Value::Object(_)) => self.check(s, x, &sub, errors),
                        // Closed unless the spec says otherwise (see above).
                        None if props.is_some() && !siblings.contains(k) => {
                            errors.push(format!("{sub}: not documented"))
                        }
                        _ => {}
                    },
                }
            }
        }
        if let Some(arr) = v.as_array() {
            let bound = |k: &str| schema.get(k).and_then(Value::as_u64);
            if bound("minItems").is_some_and(|b| (arr.len() as u64) < b) {
                errors.push(format!(
                    "{path}: fewer than minItems {}",
                    schema["minItems"]
                ));
            }
            if bound("maxItems").is_some_and(|b| (arr.len() as u64) > b) {
                errors.push(format!("{path}: more than maxItems {}", schema["maxItems"]));
            }
        }
        if let (Some(items), Some(arr)) = (schema.get("items"), v.as_array()) {
            for (i, x) in arr.iter().enumerate() {
                self.check(items, x, &format!("{path}[{i}]"), errors);
            }
        }
    }

    fn expect(&self, schema: &Value, v: &Value, what: &str) {
        let mut errors = Vec::new();
        self.check(schema, v, "", &mut errors);
        assert!(errors.is_empty(), "{what} does not validate: {errors:#?}");
    }
}

fn check(spec: &Value, schema: &Value, v: &Value, what: &str) {
    Validator::new(spec).expect(schema, v, what)
}

/// The spec path template matching a concrete path (`/v1/jobs/abc` → `/v1/jobs/{id}`).
fn template(spec: &Value, path: &str) -> Option<String> {
    let parts: Vec<&str> = path.split('/').collect();
    spec["paths"].as_object().unwrap().keys().find_map(|t| {
        let tp: Vec<&str> = t.split('/').collect();
        (tp.len() == parts.len()
            && tp
                .iter()
                .zip(&parts)
                .all(|(a, b)| a == b || a.starts_with('{')))
        .then(|| t.clone())
    })
}

fn request_schema<'a>(spec: &'a Value, method: &str, tpl: &str) -> &'a Value {
    &spec["paths"][tpl][method]["requestBody"]["content"]["application/json"]["schema"]
}

fn response_schema<'a>(
    spec: &'a Value,
    method: &str,
    tpl: &str,
    status: u16,
    ct: &str,
) -> &'a Value {
    let mut r = &spec["paths"][tpl][method]["responses"][status.to_string()];
    if let Some(reference) = r.get("$ref").and_then(Value::as_str) {
        r = reference
            .trim_start_matches("#/")
            .split('/')
            .fold(spec, |n, k| &n[k]);
    }
    let s = &r["content"][ct]["schema"];
    assert!(
        !s.is_null(),
        "no {status} {ct} response documented for {method} {tpl}"
    );
    s
}

/// The README's `## Server` section: every curl request is a documented route, and
/// every JSON body validates against that route's request schema.
#[test]
fn readme_examples_validate_against_the_spec() {
    let spec = spec();
    let readme = std::fs::read_to_string(common::repo().join("README.md")).unwrap();
    let section = readme
        .split("\n## Server")
        .nth(1)
        .expect("README has a ## Server section");
    let section = section.split("\n## ").next().unwrap();
    let mut checked = 0;
    for line in section
        .lines()
        .filter(|l| l.trim_start().starts_with("curl "))
    {
        let url_at = line.find("http://").expect("curl line has a URL");
        let url: String = line[url_at..]
            .chars()
            .take_while(|c| !c.is_whitespace() && *c != '\'' && *c != '"')
            .collect();
        let path = "/".to_string() + url.splitn(4, '/').nth(3).unwrap_or("");
        let path = path.split('?').next().unwrap().to_string();
        let method = if line.contains("-X DELETE") {
            "delete"
        } else if line.contains(" -d ") || line.contains("--data") {
            "post"
        } else {
            "get"
        };
        let tpl = template(&spec, &path).unwrap_or_else(|| panic!("{path} not in the spec"));
        assert!(
            !spec["paths"][&tpl][method].is_null(),
            "README uses {method} {tpl}, not in the spec"
        );
        if let Some(start) = line.find(" -d '") {
            let body = &line[start + 5..];
            let body = &body[..body.find('\'').unwrap()];
            let v: Value = serde_json::from_str(body).expect("README body is JSON");
            check(
                &spec,
                request_schema(&spec, method, &tpl),
                &v,
                &format!("README body {body}"),
            );
        }
        checked += 1;
    }
    assert!(
        checked >= 4,
        "expected the README's curl session, found {checked} requests"
    );
    // The Python example's routes exist too.
    for cap in section.split("f\"{BASE}").skip(1) {
        let path: String = cap.chars().take_while(|c| *c != '"').collect();
        let path = path.replace("{job['id']}", "x").replace("{job_id}", "x");
        assert!(
            template(&spec, &path).is_some(),
            "Python example uses {path}"
        );
    }
}

/// `Analysis` for `analysis`: the prefix of a kind's schemas (`AnalysisJobRequest`,
/// `AnalysisResult`).
fn camel(kind: &str) -> String {
    kind.split('_')
        .map(|w| {
            let mut c = w.chars();
            c.next()
                .map(|f| f.to_uppercase().collect::<String>() + c.as_str())
                .unwrap_or_default()
        })
        .collect()
}

/// The `$ref`s of a `oneOf`.
fn one_of_refs(schema: &Value) -> BTreeSet<String> {
    schema["oneOf"]
        .as_array()
        .unwrap_or_else(|| panic!("no oneOf in {schema}"))
        .iter()
        .map(|s| s["$ref"].as_str().unwrap().to_string())
        .collect()
}

/// Every job kind the server runs is in the spec, and nothing else: `JobKind`, the
/// request's `oneOf` and its discriminator, a `<Kind>JobRequest` whose `kind` is the
/// kind, and a `<Kind>Result` among the result's `oneOf`. (The spec once listed two
/// of the three kinds, with `additionalProperties: false`.) A kind's aliases (former
/// names, still read as it) are in its request's `kind` and the discriminator, mapped
/// to its request, and not in `JobKind`: a job is shown under its kind's name.
#[test]
fn the_spec_knows_every_job_kind() {
    let spec = spec();
    let schemas = &spec["components"]["schemas"];
    let kinds: BTreeSet<String> = kea_server::serve::jobs::names()
        .iter()
        .copied()
        .map(String::from)
        .collect();
    let aliases = |kind: &str| -> Vec<String> {
        kea_core::registry::ALIASES
            .iter()
            .find(|(name, _)| *name == kind)
            .map(|(_, aliases)| aliases.iter().copied().map(String::from).collect())
            .unwrap_or_default()
    };
    let every_alias: BTreeSet<String> = kinds.iter().flat_map(|k| aliases(k)).collect();
    assert!(
        every_alias.contains("simulation"),
        "the Monte Carlo's former name"
    );
    assert!(every_alias.is_disjoint(&kinds));
    let listed: BTreeSet<String> = schemas["JobKind"]["enum"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_str().unwrap().to_string())
        .collect();
    assert_eq!(listed, kinds, "JobKind");
    let request = &schemas["JobRequest"];
    let mapping: BTreeSet<String> = request["discriminator"]["mapping"]
        .as_object()
        .unwrap()
        .keys()
        .cloned()
        .collect();
    assert_eq!(
        mapping,
        kinds.union(&every_alias).cloned().collect(),
        "JobRequest's discriminator"
    );
    let refs = |suffix: &str| -> BTreeSet<String> {
        kinds
            .iter()
            .map(|k| format!("#/components/schemas/{}{suffix}", camel(k)))
            .collect()
    };
    assert_eq!(
        one_of_refs(request),
        refs("JobRequest"),
        "JobRequest's oneOf"
    );
    for k in &kinds {
        let name = format!("{}JobRequest", camel(k));
        let names: Vec<String> = std::iter::once(k.clone()).chain(aliases(k)).collect();
        for n in &names {
            assert_eq!(
                request["discriminator"]["mapping"][n],
                format!("#/components/schemas/{name}")
            );
        }
        let kind = &schemas[&name]["properties"]["kind"];
        if names.len() == 1 {
            assert_eq!(kind["const"], k.as_str());
        } else {
            assert_eq!(kind["enum"], json!(names), "{name}'s kind");
        }
        assert!(
            !schemas[format!("{}Result", camel(k))].is_null(),
            "no {}Result",
            camel(k)
        );
    }
    // A body naming a kind by an alias is that kind's request.
    Validator::new(&spec).expect(
        request,
        &json!({"kind": "simulation", "model_id": "m", "runs": 2}),
        "a Monte Carlo job body under the kind's former name",
    );
    let result = response_schema(
        &spec,
        "get",
        "/v1/jobs/{id}/result",
        200,
        "application/json",
    );
    assert_eq!(one_of_refs(result), refs("Result"), "the result's oneOf");
}

/// The component schemas a response can reach (through `$ref`s, transitively).
fn response_schemas(spec: &Value) -> BTreeSet<String> {
    fn refs(v: &Value, out: &mut Vec<String>) {
        match v {
            Value::Object(m) => {
                if let Some(Value::String(r)) = m.get("$ref") {
                    out.push(r.clone());
                }
                m.values().for_each(|x| refs(x, out));
            }
            Value::Array(a) => a.iter().for_each(|x| refs(x, out)),
            _ => {}
        }
    }
    let mut todo = Vec::new();
    for item in spec["paths"].as_object().unwrap().values() {
        for m in METHODS {
            if let Some(op) = item.get(*m) {
                refs(&op["responses"], &mut todo);
            }
        }
    }
    let mut seen = BTreeSet::new();
    while let Some(r) = todo.pop() {
        if seen.insert(r.clone()) {
            let target = r
                .trim_start_matches("#/")
                .split('/')
                .fold(spec, |node, key| &node[key]);
            refs(target, &mut todo);
        }
    }
    seen.into_iter()
        .filter(|r| r.starts_with("#/components/schemas/"))
        .collect()
}

/// Real responses of the running server validate against the documented schemas —
/// every member documented, every required one present — for every route and every
/// job kind, and every schema a response can use is met by one of them.
#[test]
fn responses_validate_against_the_spec() {
    let spec = spec();
    let v = Validator::new(&spec);
    let dir = tempfile::tempdir().unwrap();
    let s = Server::start(dir.path(), &[]);
    let expect = |method: &str, path: &str, r: &common::Reply, status: u16| {
        assert_eq!(r.status, status, "{method} {path}: {}", r.text);
        let tpl = template(&spec, path).unwrap();
        let ct = r.content_type.split(';').next().unwrap().to_string();
        let schema = response_schema(&spec, method, &tpl, status, &ct);
        if ct.ends_with("json") {
            v.expect(schema, &r.json(), &format!("{method} {path} → {status}"));
        }
    };
    expect("get", "/healthz", &s.get("/healthz"), 200);
    expect("get", "/v1/limits", &s.get("/v1/limits"), 200);
    expect("get", "/v1/limits", &s.get("/v1/limits?x=1"), 400);
    expect("get", "/v1/presets", &s.get("/v1/presets"), 200);
    expect("get", "/v1/presets", &s.get("/v1/presets?x=1"), 400);
    for name in kea_core::presets::names() {
        let p = format!("/v1/presets/{name}");
        expect("get", &p, &s.get(&p), 200);
    }
    expect("get", "/v1/presets/x", &s.get("/v1/presets/x"), 404);
    let created = s.post("/v1/models", &preset("cv-tracker"));
    expect("post", "/v1/models", &created, 201);
    let id = created.json()["id"].as_str().unwrap().to_string();
    s.post("/v1/models", &preset("seed-example"));
    let page = s.get("/v1/models?limit=1");
    expect("get", "/v1/models", &page, 200);
    assert!(page.json()["next_cursor"].is_string());
    expect("get", "/v1/models", &s.get("/v1/models?cursor=x"), 400);
    let mp = format!("/v1/models/{id}");
    expect("get", &mp, &s.get(&mp), 200);
    let body = json!({"model_id": id, "set": {"q": 3}});
    v.expect(
        request_schema(&spec, "post", "/v1/analyze"),
        &body,
        "analyze body",
    );
    expect("post", "/v1/analyze", &s.post("/v1/analyze", &body), 200);
    expect(
        "post",
        "/v1/analyze",
        &s.post("/v1/analyze", &json!({"model": {}})),
        422,
    );
    expect(
        "post",
        "/v1/analyze",
        &s.post_raw("/v1/analyze", "application/json", "{"),
        400,
    );
    // One job of every kind: the request, the job, its result and its traces.
    let mut cv = preset("cv-tracker");
    cv["options"]["trace_points"] = json!(20);
    let jobs = [
        json!({"kind": "analysis", "model": preset("helicopter-range"), "budget": true,
               "truth": {"set": {"sd": 10, "f_f": 0.3}}}),
        json!({"kind": "monte_carlo", "model": cv, "runs": 20, "seed": 1,
               "truth": "process", "model_error": "white", "trace_points": 10}),
        json!({"kind": "monte_carlo", "model": cv, "runs": 20, "truth": {"set": {"q": 2}}}),
        json!({"kind": "synthesis", "model": cv,
               "target": {"criterion": "yx", "criteria": "covariance", "threshold": 1.5},
               "mode": {"grid": {"params": [{"name": "q", "values": [0.5, 2]}],
                                 "cost_order": [{"name": "q", "cheaper": "higher"}]}}}),
        json!({"kind": "synthesis", "model": cv,
               "target": {"criterion": "yx", "criteria": "covariance", "threshold": 1.5},
               "mode": {"bisect": {"param": "r", "low": 0.01, "high": 100}}}),
        common::identification_job(),
        json!({"kind": "nonlinear",
               "model": serde_json::from_str::<Value>(
                   kea_core::nonlinear::request::preset("seed-002").unwrap()).unwrap(),
               "procedure": {"alpha": [1, 0.6, 0.5], "earlier_residuals": "posterior"},
               "data": {"truth": {"seed": 1, "y0": [1000, 50], "phi": [0, 1]}},
               "q_scale": [0.1, 1, 10], "checkpoints": [1, 2000], "trace_points": 20}),
        json!({"kind": "sensitivity", "model": cv, "params": ["q", "r"], "rank_by": "covariance.zx"}),
    ];
    let schemas = &spec["components"]["schemas"];
    let mut kinds_run = BTreeSet::new();
    let mut last = String::new();
    for jb in jobs {
        let kind = jb["kind"].as_str().unwrap().to_string();
        v.expect(
            request_schema(&spec, "post", "/v1/jobs"),
            &jb,
            &format!("{kind} job body"),
        );
        let job = s.post("/v1/jobs", &jb);
        expect("post", "/v1/jobs", &job, 202);
        let jid = job.json()["id"].as_str().unwrap().to_string();
        let done = s.wait_finished(&jid, std::time::Duration::from_secs(120));
        assert_eq!(done["status"], "succeeded", "{done}");
        let jp = format!("/v1/jobs/{jid}");
        expect("get", &jp, &s.get(&jp), 200);
        let qp = format!("/v1/jobs/{jid}/request");
        let stored = s.get(&qp);
        expect("get", &qp, &stored, 200);
        assert_eq!(stored.json(), jb, "the {kind} job's stored request");
        let rp = format!("/v1/jobs/{jid}/result");
        let result = s.get(&rp);
        expect("get", &rp, &result, 200);
        v.expect(
            &schemas[format!("{}Result", camel(&kind))],
            &result.json(),
            &format!("the {kind} result"),
        );
        let tp = format!("/v1/jobs/{jid}/traces.csv");
        let csv = s.get(&tp);
        if kind == "synthesis" || kind == "sensitivity" {
            expect("get", &tp, &csv, 404);
        } else {
            expect("get", &tp, &csv, 200);
            check_csv_header(&spec, &kind, csv.text.lines().next().unwrap());
        }
        kinds_run.insert(kind);
        last = jid;
    }
    let kinds: BTreeSet<String> = kea_server::serve::jobs::names()
        .iter()
        .copied()
        .map(String::from)
        .collect();
    assert_eq!(kinds_run, kinds, "a job of every kind");
    expect("get", "/v1/jobs", &s.get("/v1/jobs?status=succeeded"), 200);
    expect("get", "/v1/jobs", &s.get("/v1/jobs?status=nope"), 400);
    // A job still running, its cancel, a result that is not there yet.
    let mut long = preset("cv-tracker");
    long["time"]["steps"] = json!(20_000_000);
    long["options"]["steady_state_shortcut"] = json!(false);
    let running = s.post("/v1/jobs", &json!({"kind": "analysis", "model": long}));
    let rid = running.json()["id"].as_str().unwrap().to_string();
    let rp = format!("/v1/jobs/{rid}");
    s.wait_job(&rid, std::time::Duration::from_secs(120), |j| {
        j["status"] == "running"
    });
    expect("get", &rp, &s.get(&rp), 200);
    expect(
        "get",
        "/v1/jobs/{id}/result",
        &s.get(&format!("{rp}/result")),
        409,
    );
    expect("delete", &rp, &s.delete(&rp), 200);
    s.wait_finished(&rid, std::time::Duration::from_secs(120));
    let jp = format!("/v1/jobs/{last}");
    expect("delete", &jp, &s.delete(&jp), 409);
    expect("delete", &mp, &s.delete("/v1/models/gone"), 404);
    expect("get", "/v1/jobs/x", &s.get("/v1/jobs/x"), 404);
    let qp = "/v1/jobs/x/request";
    expect("get", qp, &s.get(qp), 404);
    // A failed job carries its error (no measurement error and no initial error:
    // the innovation covariance is singular at the first step).
    let mut singular = preset("cv-tracker");
    singular["measurement"]["psi"] = json!([0]);
    singular["system"]["eta0"] = json!([0, 0]);
    let failed = s.post("/v1/jobs", &json!({"kind": "analysis", "model": singular}));
    expect("post", "/v1/jobs", &failed, 202);
    let fid = failed.json()["id"].as_str().unwrap().to_string();
    let done = s.wait_finished(&fid, std::time::Duration::from_secs(120));
    assert_eq!(done["status"], "failed", "{done}");
    let fp = format!("/v1/jobs/{fid}");
    expect("get", &fp, &s.get(&fp), 200);
    let events = s.events(&format!("/v1/jobs/{last}/events"));
    v.expect(&schemas["Job"], &events.last().unwrap().1, "final event");
    // Every schema a response can use was met by a real one.
    let visited = v.visited.borrow();
    let missed: Vec<String> = response_schemas(&spec)
        .into_iter()
        .filter(|r| !visited.contains(r))
        .collect();
    assert!(missed.is_empty(), "no real response used {missed:?}");
}

/// A traces CSV's header is the one the spec describes for its kind: `series:state`
/// columns for both kinds (then `nees`, `nis` for a Monte Carlo),
/// each series named in the description.
fn check_csv_header(spec: &Value, kind: &str, header: &str) {
    let description =
        spec["paths"]["/v1/jobs/{id}/traces.csv"]["get"]["responses"]["200"]["description"]
            .as_str()
            .unwrap();
    let mut columns = header.split(',');
    assert_eq!(columns.next(), Some("t"), "{header}");
    let documented = |series: &str| description.contains(&format!("`{series}`"));
    let mut checked = 0;
    for c in columns {
        let series = match kind {
            "analysis" => {
                assert!(description.contains("`series:state`"));
                c.split_once(':').map(|(series, _)| series)
            }
            "monte_carlo" | "identification" if c == "nees" || c == "nis" => Some(c),
            "identification" => c.split_once(':').map(|(series, _)| series),
            "nonlinear" if c == "n" => Some(c),
            "nonlinear" => c.split_once(':').map(|(series, _)| {
                // (`iterate1` … `iterateK`: documented as `iterateK`.)
                match series.strip_prefix("iterate") {
                    Some(k) if k.parse::<u32>().is_ok() => "iterateK",
                    _ => series,
                }
            }),
            "monte_carlo" => {
                assert!(description.contains("`series:state`"));
                c.split_once(':').map(|(series, _)| series)
            }
            other => panic!("{other} has no traces"),
        };
        let series = series.unwrap_or_else(|| panic!("column `{c}` of {kind}: {header}"));
        assert!(
            documented(series),
            "`{series}` ({kind}) not in: {description}"
        );
        checked += 1;
    }
    assert!(checked > 0, "{header}");
}

/// Submit a Monte Carlo job of `m` and wait for its end: its id and final record.
fn monte_carlo_job(s: &Server, m: &Value, runs: u64, trace_points: u64) -> (String, Value) {
    let job = s.post(
        "/v1/jobs",
        &json!({"kind": "monte_carlo", "model": m, "runs": runs, "trace_points": trace_points}),
    );
    assert_eq!(job.status, 202, "{}", job.text);
    let id = job.json()["id"].as_str().unwrap().to_string();
    let done = s.wait_finished(&id, std::time::Duration::from_secs(120));
    (id, done)
}

/// A Monte Carlo run whose bound overflows f64 (the textbook tracker over 1000 s): χ is
/// null in the result (with a warning). The spec said `Numbers`, so a client validating
/// the result refused it. (A model whose simulated process diverges stops with an error
/// instead: its sample SKOs would be rounding.)
#[test]
fn an_overflowing_monte_carlo_validates_against_the_spec() {
    let spec = spec();
    let v = Validator::new(&spec);
    let dir = tempfile::tempdir().unwrap();
    let s = Server::start(dir.path(), &[]);
    let mut m = preset("cv-tracker");
    m["time"] = json!({"t0": 0, "t_end": 1000, "steps": 10000});
    let (id, done) = monte_carlo_job(&s, &m, 10, 20);
    assert_eq!(done["status"], "succeeded", "{done}");
    let result = s.get(&format!("/v1/jobs/{id}/result")).json();
    let fin = &result["final"];
    assert!(
        fin["chi"].as_array().unwrap().iter().any(Value::is_null),
        "expected an overflowed (null) chi: {fin}"
    );
    assert!(!result["warnings"].as_array().unwrap().is_empty());
    v.expect(
        &spec["components"]["schemas"]["MonteCarloResult"],
        &result,
        "the overflowing Monte Carlo's result",
    );
    // The diverging model: a failed job whose error names the state and the step.
    m["system"]["a"] = json!([[0, 1], [0, 10]]);
    m["time"] = json!({"t0": 0, "t_end": 100, "steps": 1000});
    let (_, done) = monte_carlo_job(&s, &m, 10, 20);
    assert_eq!(done["status"], "failed", "{done}");
    let text = done["error"].to_string();
    assert!(
        text.contains("the simulated process of \\\"position\\\" reached"),
        "{text}"
    );
}

/// A Monte Carlo run with no measurement at any step: NIS has no degrees of freedom,
/// so its band is [null, null] — the spec said numbers.
#[test]
fn a_monte_carlo_without_measurements_validates_against_the_spec() {
    let spec = spec();
    let v = Validator::new(&spec);
    let dir = tempfile::tempdir().unwrap();
    let s = Server::start(dir.path(), &[]);
    let mut m = preset("cv-tracker");
    m["measurement"]["schedule"] = json!([{"when": "-1"}]);
    let (id, done) = monte_carlo_job(&s, &m, 5, 20);
    assert_eq!(done["status"], "succeeded", "{done}");
    let result = s.get(&format!("/v1/jobs/{id}/result")).json();
    assert_eq!(result["consistency"]["nis"]["band"], json!([null, null]));
    v.expect(
        &spec["components"]["schemas"]["MonteCarloResult"],
        &result,
        "a Monte Carlo without measurements",
    );
}

/// max |dy/dt| and max |C y| of a model whose mean stays finite can overflow f64;
/// they are null then, in the analysis and in the Monte Carlo. The spec said `Numbers`.
#[test]
fn an_overflowing_maximum_validates_against_the_spec() {
    let spec = spec();
    let v = Validator::new(&spec);
    let schemas = &spec["components"]["schemas"];
    let dir = tempfile::tempdir().unwrap();
    let s = Server::start(dir.path(), &[]);
    let mut m = preset("helicopter-range");
    m["system"]["y0"][2] = json!(1e308);
    m["measurement"]["c"][1][2] = json!(1e10);
    let r = s.post("/v1/analyze", &json!({ "model": m }));
    assert_eq!(r.status, 200, "{}", r.text);
    let result = r.json();
    assert!(result["ydot_max"][2].is_null(), "{}", result["ydot_max"]);
    assert!(result["z_max"][1].is_null(), "{}", result["z_max"]);
    v.expect(&schemas["AnalysisResult"], &result, "the analysis result");
    // Simulated, the state of size 1e308 leaves no digits for its filter errors: the
    // job fails, naming it.
    let (_, done) = monte_carlo_job(&s, &m, 2, 10);
    assert_eq!(done["status"], "failed", "{done}");
    assert!(
        done["error"]
            .to_string()
            .contains("the simulated process of"),
        "{done}"
    );
}

/// Where a model rule fits a schema keyword, the spec states it: every one of these
/// models is refused by the server (422, at the member) and by the `Model` schema.
/// (The spec admitted them all: a client or a fuzzer generating from it sent models
/// the server was bound to refuse.)
#[test]
fn the_model_schema_states_the_rules_a_keyword_can_state() {
    let spec = spec();
    let model_schema = &spec["components"]["schemas"]["Model"];
    let dir = tempfile::tempdir().unwrap();
    let s = Server::start(dir.path(), &[]);
    let cv = preset("cv-tracker");
    check(&spec, model_schema, &cv, "cv-tracker");
    type Edit = fn(&mut Value);
    let cases: &[(&str, Edit)] = &[
        ("kea_model", |m| m["kea_model"] = json!(0)),
        ("kea_model", |m| m["kea_model"] = json!(2)),
        ("time.steps", |m| m["time"]["steps"] = json!(0)),
        ("time.steps", |m| m["time"]["steps"] = json!(100_000_001u64)),
        ("time.auto.tolerance", |m| {
            m["time"]["steps"] = json!("auto");
            m["time"]["auto"] = json!({"tolerance": 0});
        }),
        ("time.auto.initial_steps", |m| {
            m["time"]["steps"] = json!("auto");
            m["time"]["auto"] = json!({"initial_steps": 0});
        }),
        ("time.auto.max_steps", |m| {
            m["time"]["steps"] = json!("auto");
            m["time"]["auto"] = json!({"max_steps": 100_000_001u64});
        }),
        ("system.states", |m| m["system"]["states"] = json!([])),
        ("system.states", |m| {
            m["system"]["states"] = json!((0..201).map(|i| format!("s{i}")).collect::<Vec<_>>())
        }),
        ("measurement.names", |m| {
            m["measurement"]["names"] = json!([])
        }),
        ("criteria.confidence", |m| {
            m["criteria"]["confidence"] = json!(0)
        }),
        ("criteria.confidence", |m| {
            m["criteria"]["confidence"] = json!(1)
        }),
    ];
    let v = Validator::new(&spec);
    for (path, edit) in cases {
        let mut m = cv.clone();
        edit(&mut m);
        let r = s.post("/v1/models", &m);
        assert_eq!(r.status, 422, "{path}: {}", r.text);
        assert!(
            r.error_paths().iter().any(|p| p == path),
            "{path}: {}",
            r.text
        );
        let mut errors = Vec::new();
        v.check(model_schema, &m, "", &mut errors);
        assert!(
            !errors.is_empty(),
            "the spec admits the model the server refuses at {path}: {}",
            r.text
        );
    }
}

/// The ids that `POST /v1/models` and `POST /v1/jobs` return are linked to the
/// operations that take them (OpenAPI links, which stateful clients and testers
/// follow), and every link names a real operation and its real parameters.
#[test]
fn created_resources_link_to_the_operations_on_them() {
    let spec = spec();
    let mut operations = std::collections::BTreeMap::new();
    for (path, item) in spec["paths"].as_object().unwrap() {
        for m in METHODS {
            if let Some(op) = item.get(*m) {
                let mut params: BTreeSet<String> = BTreeSet::new();
                for p in [&item["parameters"], &op["parameters"]] {
                    for p in p.as_array().into_iter().flatten() {
                        if let Some(n) = p["name"].as_str() {
                            params.insert(n.to_string());
                        }
                    }
                }
                let id = op["operationId"].as_str().unwrap().to_string();
                operations.insert(id, (path.clone(), params, op.clone()));
            }
        }
    }
    let links = |path: &str, status: &str| -> BTreeSet<String> {
        let links = &spec["paths"][path]["post"]["responses"][status]["links"];
        let links = links
            .as_object()
            .unwrap_or_else(|| panic!("no links on POST {path} {status}"));
        for (name, link) in links {
            let target = link["operationId"].as_str().unwrap();
            let (_, params, op) = operations
                .get(target)
                .unwrap_or_else(|| panic!("link {name}: no operation {target}"));
            for (p, expr) in link["parameters"].as_object().into_iter().flatten() {
                assert!(params.contains(p), "link {name}: {target} has no `{p}`");
                assert_eq!(expr, "$response.body#/id", "link {name}");
            }
            if let Some(body) = link.get("requestBody") {
                check(
                    &spec,
                    &op["requestBody"]["content"]["application/json"]["schema"],
                    &serde_json::from_str(&body.to_string().replace("$response.body#/id", "x"))
                        .unwrap(),
                    &format!("link {name}'s body"),
                );
            }
        }
        links
            .values()
            .map(|l| l["operationId"].as_str().unwrap().to_string())
            .collect()
    };
    let by_id = |prefix: &str| -> BTreeSet<String> {
        operations
            .iter()
            .filter(|(_, (path, params, _))| path.starts_with(prefix) && params.contains("id"))
            .map(|(id, _)| id.clone())
            .collect()
    };
    let jobs = links("/v1/jobs", "202");
    assert_eq!(jobs, by_id("/v1/jobs/"), "POST /v1/jobs's links");
    let models = links("/v1/models", "201");
    assert!(
        by_id("/v1/models/").is_subset(&models),
        "POST /v1/models's links: {models:?}"
    );
}

/// An optional model member sent as null is taken as left out, and a stored model is
/// returned as it was sent: the request and `GET /v1/models/{id}`'s answer both
/// validate. (The spec allowed no null there, so the answer broke its own schema.)
#[test]
fn null_optional_model_members_are_in_the_spec() {
    let spec = spec();
    let v = Validator::new(&spec);
    let dir = tempfile::tempdir().unwrap();
    let s = Server::start(dir.path(), &[]);
    let mut m = preset("cv-tracker");
    m["description"] = Value::Null;
    m["time"]["auto"] = Value::Null;
    for k in ["u", "y0", "eta0", "W"] {
        m["system"][k] = Value::Null;
    }
    for k in ["g", "V", "schedule", "pairs"] {
        m["measurement"][k] = Value::Null;
    }
    m["criteria"]["weights"] = json!({"yz": null, "zx": null, "yx": null});
    v.expect(
        request_schema(&spec, "post", "/v1/models"),
        &m,
        "the model with nulls",
    );
    let created = s.post("/v1/models", &m);
    assert_eq!(created.status, 201, "{}", created.text);
    let path = format!("/v1/models/{}", created.json()["id"].as_str().unwrap());
    let got = s.get(&path);
    assert_eq!(got.status, 200, "{}", got.text);
    assert_eq!(got.json()["model"], m);
    v.expect(
        response_schema(&spec, "get", "/v1/models/{id}", 200, "application/json"),
        &got.json(),
        "the stored model with nulls",
    );
}

/// Each server-sent event, `{event, data}`, validates against the spec's
/// `text/event-stream` schema, and its data against the schema the spec names.
/// (The schema was `type: string`, which no event is.)
#[test]
fn job_events_validate_against_the_spec() {
    let spec = spec();
    let v = Validator::new(&spec);
    let dir = tempfile::tempdir().unwrap();
    let s = Server::start(dir.path(), &[]);
    let id = s.submit_analysis(common::long_model(2_000_000));
    let events = s.events(&format!("/v1/jobs/{id}/events"));
    assert!(events.len() >= 2, "{events:?}");
    let schema = response_schema(
        &spec,
        "get",
        "/v1/jobs/{id}/events",
        200,
        "text/event-stream",
    );
    for (event, data) in &events {
        let e = json!({"event": event, "data": data.to_string()});
        v.expect(schema, &e, &format!("event {e}"));
        if event == "status" {
            v.expect(
                &spec["components"]["schemas"]["Job"],
                data,
                "the status event",
            );
        }
    }
    assert_eq!(events.last().unwrap().0, "status");
}
