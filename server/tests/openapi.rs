//! `openapi.yaml` is kept true: its paths and methods are exactly the route table,
//! the README's example requests validate against it, and real responses validate
//! against its schemas.

mod common;

use common::{Server, preset};
use serde_json::{Value, json};
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
    let served: BTreeSet<(String, String)> = kea_server::serve::routes::route_list()
        .into_iter()
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

/// A small JSON Schema validator for the subset openapi.yaml uses: type (or a list),
/// required, properties, additionalProperties, items, enum, const, oneOf, allOf,
/// minimum, maximum and local `$ref`s.
fn validate(root: &Value, schema: &Value, v: &Value, path: &str, errors: &mut Vec<String>) {
    if let Some(r) = schema.get("$ref").and_then(Value::as_str) {
        let target = r
            .trim_start_matches("#/")
            .split('/')
            .fold(root, |node, key| &node[key]);
        assert!(!target.is_null(), "dangling $ref {r}");
        return validate(root, target, v, path, errors);
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
    if let Some(c) = schema.get("const") {
        if c != v {
            errors.push(format!("{path}: expected {c}, got {v}"));
        }
    }
    if let Some(e) = schema.get("enum").and_then(Value::as_array) {
        if !e.contains(v) {
            errors.push(format!("{path}: {v} not in {e:?}"));
        }
    }
    if let (Some(min), Some(x)) = (schema.get("minimum").and_then(Value::as_f64), v.as_f64()) {
        if x < min {
            errors.push(format!("{path}: {x} < {min}"));
        }
    }
    if let (Some(max), Some(x)) = (schema.get("maximum").and_then(Value::as_f64), v.as_f64()) {
        if x > max {
            errors.push(format!("{path}: {x} > {max}"));
        }
    }
    if let Some(all) = schema.get("allOf").and_then(Value::as_array) {
        for s in all {
            validate(root, s, v, path, errors);
        }
    }
    if let Some(one) = schema.get("oneOf").and_then(Value::as_array) {
        let passing = one
            .iter()
            .filter(|s| {
                let mut e = Vec::new();
                validate(root, s, v, path, &mut e);
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
                Some(s) => validate(root, s, x, &sub, errors),
                None => match schema.get("additionalProperties") {
                    Some(Value::Bool(false)) => errors.push(format!("{sub}: not allowed")),
                    Some(s @ Value::Object(_)) => validate(root, s, x, &sub, errors),
                    _ => {}
                },
            }
        }
    }
    if let (Some(items), Some(arr)) = (schema.get("items"), v.as_array()) {
        for (i, x) in arr.iter().enumerate() {
            validate(root, items, x, &format!("{path}[{i}]"), errors);
        }
    }
}

fn check(spec: &Value, schema: &Value, v: &Value, what: &str) {
    let mut errors = Vec::new();
    validate(spec, schema, v, "", &mut errors);
    assert!(errors.is_empty(), "{what} does not validate: {errors:#?}");
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

/// Real responses of the running server validate against the documented schemas.
#[test]
fn responses_validate_against_the_spec() {
    let spec = spec();
    let dir = tempfile::tempdir().unwrap();
    let s = Server::start(dir.path(), &[]);
    let expect = |method: &str, path: &str, r: &common::Reply, status: u16| {
        assert_eq!(r.status, status, "{method} {path}: {}", r.text);
        let tpl = template(&spec, path).unwrap();
        let ct = r.content_type.split(';').next().unwrap().to_string();
        let schema = response_schema(&spec, method, &tpl, status, &ct);
        check(
            &spec,
            schema,
            &r.json(),
            &format!("{method} {path} → {status}"),
        );
    };
    expect("get", "/healthz", &s.get("/healthz"), 200);
    expect("get", "/v1/presets", &s.get("/v1/presets"), 200);
    for name in kea_core::presets::names() {
        let p = format!("/v1/presets/{name}");
        expect("get", &p, &s.get(&p), 200);
    }
    expect("get", "/v1/presets/x", &s.get("/v1/presets/x"), 404);
    let created = s.post("/v1/models", &preset("cv-tracker"));
    expect("post", "/v1/models", &created, 201);
    let id = created.json()["id"].as_str().unwrap().to_string();
    expect("get", "/v1/models", &s.get("/v1/models?limit=1"), 200);
    let mp = format!("/v1/models/{id}");
    expect("get", &mp, &s.get(&mp), 200);
    let body = json!({"model_id": id, "set": {"q": 3}});
    check(
        &spec,
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
    let jb = json!({"kind": "analysis", "model": preset("helicopter-range")});
    check(
        &spec,
        request_schema(&spec, "post", "/v1/jobs"),
        &jb,
        "job body",
    );
    let job = s.post("/v1/jobs", &jb);
    expect("post", "/v1/jobs", &job, 202);
    let jid = job.json()["id"].as_str().unwrap().to_string();
    s.wait_finished(&jid, std::time::Duration::from_secs(120));
    let jp = format!("/v1/jobs/{jid}");
    expect("get", &jp, &s.get(&jp), 200);
    expect("get", "/v1/jobs", &s.get("/v1/jobs?status=succeeded"), 200);
    expect("get", "/v1/jobs", &s.get("/v1/jobs?status=nope"), 400);
    let rp = format!("/v1/jobs/{jid}/result");
    expect("get", &rp, &s.get(&rp), 200);
    expect("delete", &jp, &s.delete(&jp), 409);
    expect("delete", &mp, &s.delete("/v1/models/gone"), 404);
    let events = s.events(&format!("/v1/jobs/{jid}/events"));
    check(
        &spec,
        &spec["components"]["schemas"]["Job"],
        &events.last().unwrap().1,
        "final event",
    );
}
