//! Reading requests: the JSON body (size limit, media type, syntax), query strings,
//! and the pieces every computation request shares (`model` | `model_id`, `set`).

use super::problem::{Problem, kind};
use super::state::AppState;
use axum::extract::path::ErrorKind;
use axum::extract::rejection::PathRejection;
use axum::extract::{FromRequest, FromRequestParts, Path, Request};
use axum::http::request::Parts;
use axum::http::{StatusCode, header};
use kea_core::FieldError;
pub use kea_core::error::{got, json_kind};
use serde_json::{Map, Value};
use std::collections::BTreeMap;

/// A JSON request body, read under the configured size limit. Every failure is a
/// problem+json 4xx: 415 (not JSON), 413 (too large), 408 (too slow), 400 (malformed).
/// With the bytes as sent (valid UTF-8 once parsed): a stored model is kept as its text.
pub struct JsonBody(pub Value, pub Vec<u8>);

impl FromRequest<AppState> for JsonBody {
    type Rejection = Problem;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, Problem> {
        let ct = req
            .headers()
            .get(header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .unwrap_or("");
        // application/json or a …+json type ("+json" alone is no media type); a
        // charset, if given, must be UTF-8: the body is read as UTF-8 (RFC 8259 §8.1),
        // so `charset=latin1` would be decoded wrongly without a word.
        let media = ct.parse::<mime::Mime>().ok();
        let json = media.as_ref().is_some_and(|m| {
            m.type_() == mime::APPLICATION
                && (m.subtype() == mime::JSON || m.suffix() == Some(mime::JSON))
        });
        if !json {
            return Err(Problem::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                kind::MEDIA_TYPE,
                "the body must be JSON",
            )
            .detail(format!(
                "send the header `Content-Type: application/json` (got `{ct}`)"
            )));
        }
        if let Some(charset) = media.as_ref().and_then(|m| m.get_param(mime::CHARSET))
            && charset != mime::UTF_8
        {
            return Err(Problem::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                kind::MEDIA_TYPE,
                "the body must be UTF-8",
            )
            .detail(format!(
                "kea reads JSON as UTF-8 (RFC 8259 §8.1), not charset={charset}: send it as UTF-8, with `charset=utf-8` or no charset"
            )));
        }
        // A compressed body would reach the JSON parser as bytes (400 "not valid JSON");
        // kea takes none, so say that.
        if let Some(enc) = req.headers().get(header::CONTENT_ENCODING) {
            let enc = enc.to_str().unwrap_or("?").trim().to_ascii_lowercase();
            if enc != "identity" {
                return Err(Problem::new(
                    StatusCode::UNSUPPORTED_MEDIA_TYPE,
                    kind::MEDIA_TYPE,
                    "the body must not be compressed",
                )
                .detail(format!(
                    "send the JSON uncompressed, without `Content-Encoding: {enc}`"
                )));
            }
        }
        let limits = &state.config.limits;
        if let Some(declared) = declared_length(&req).filter(|&n| n > limits.max_body_bytes as u64)
        {
            // Answer now: waiting for a body that will be refused anyway held the
            // connection until --read-timeout (and then said 408, not 413).
            drain_in_background(req, limits.read_timeout);
            return Err(too_large(limits.max_body_bytes)
                .detail(format!(
                    "the body is declared as {declared} bytes (Content-Length); the limit is {} bytes (server option --max-body-bytes)",
                    limits.max_body_bytes
                )));
        }
        let bytes = read_limited(req, limits.max_body_bytes, limits.read_timeout).await?;
        let value = kea_core::parse_json(&bytes).map_err(|e| {
            Problem::new(
                StatusCode::BAD_REQUEST,
                kind::MALFORMED,
                "the body is not valid JSON",
            )
            .detail(e.to_string())
            .error("", format!("not valid JSON: {e}"))
        })?;
        Ok(JsonBody(value, bytes))
    }
}

/// How much of an over-large body is still read (and dropped) before answering 413,
/// so the connection closes cleanly and the client sees the answer, not a reset.
const DRAIN_BEYOND_LIMIT: usize = 16 * 1024 * 1024;

/// Read the body up to `limit` bytes; over it, 413 (after draining a bounded amount);
/// not whole within `within`, 408 — a client that sent a Content-Length and then
/// trickled or stopped held its connection for as long as it liked.
async fn read_limited(
    req: Request,
    limit: usize,
    within: std::time::Duration,
) -> Result<Vec<u8>, Problem> {
    use futures_util::StreamExt;
    let mut stream = req.into_body().into_data_stream();
    let mut buf = Vec::new();
    let mut total = 0usize;
    let deadline = tokio::time::Instant::now() + within;
    loop {
        let Ok(next) = tokio::time::timeout_at(deadline, stream.next()).await else {
            return Err(Problem::new(
                StatusCode::REQUEST_TIMEOUT,
                kind::BODY_TIMEOUT,
                "the request body did not arrive in time",
            )
            .detail(format!(
                "a body must arrive whole within {} s (server option --read-timeout); {total} bytes came",
                within.as_secs()
            )));
        };
        let Some(chunk) = next else { break };
        let chunk = chunk.map_err(|e| {
            Problem::new(
                StatusCode::BAD_REQUEST,
                kind::MALFORMED,
                "cannot read the body",
            )
            .detail(e.to_string())
        })?;
        total += chunk.len();
        if total <= limit {
            buf.extend_from_slice(&chunk);
        } else if total > limit + DRAIN_BEYOND_LIMIT {
            break;
        }
    }
    if total > limit {
        return Err(too_large(limit));
    }
    Ok(buf)
}

fn too_large(limit: usize) -> Problem {
    Problem::new(
        StatusCode::PAYLOAD_TOO_LARGE,
        kind::TOO_LARGE,
        "the request body is too large",
    )
    .detail(format!(
        "the limit is {limit} bytes (server option --max-body-bytes)"
    ))
}

/// The body's length as the request declares it (`Content-Length`), if it does.
fn declared_length(req: &Request) -> Option<u64> {
    req.headers()
        .get(header::CONTENT_LENGTH)?
        .to_str()
        .ok()?
        .trim()
        .parse()
        .ok()
}

/// Read and drop what a client sends of a body refused by its declared length, up to
/// [`DRAIN_BEYOND_LIMIT`] bytes and `within`, so the answer (already on its way) is
/// not lost to a connection reset. A client that waits for `100 Continue` sends
/// nothing: its body is not asked for.
fn drain_in_background(req: Request, within: std::time::Duration) {
    use futures_util::StreamExt;
    if req.headers().contains_key(header::EXPECT) {
        return;
    }
    let mut stream = req.into_body().into_data_stream();
    tokio::spawn(async move {
        let drain = async {
            let mut total = 0usize;
            while let Some(Ok(chunk)) = stream.next().await {
                total += chunk.len();
                if total > DRAIN_BEYOND_LIMIT {
                    break;
                }
            }
        };
        let _ = tokio::time::timeout(within, drain).await;
    });
}

/// A route's text path parameter (`{id}`, `{name}`), read as axum's `Path<String>`
/// but refused as a problem+json 400 naming the parameter and what it should be —
/// `/v1/jobs/%ff` decodes to no UTF-8 text, which axum answers in text/plain.
macro_rules! path_param {
    ($(#[$doc:meta])* $ty:ident, $name:literal, $expected:literal, $normal:expr) => {
        $(#[$doc])*
        pub struct $ty(pub String);

        impl<S: Send + Sync> FromRequestParts<S> for $ty {
            type Rejection = Problem;

            async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, Problem> {
                path_param(parts, state, $name, $expected).await.map($normal).map($ty)
            }
        }
    };
}

/// An id (a UUID) as this server writes it, hyphenated and lower-case, whatever the
/// case it was given in (RFC 9562 §4: UUID text is case-insensitive); any other text
/// as it is (a 404 then).
pub fn canonical_id(text: String) -> String {
    match uuid::Uuid::parse_str(&text) {
        Ok(u) => u.hyphenated().to_string(),
        Err(_) => text,
    }
}

path_param!(
    /// `{id}` of `/v1/jobs/{id}…`.
    JobId,
    "id",
    "a job id, as POST /v1/jobs returned it",
    canonical_id
);
path_param!(
    /// `{id}` of `/v1/models/{id}`.
    ModelId,
    "id",
    "a model id, as POST /v1/models returned it",
    canonical_id
);
path_param!(
    /// `{name}` of `/v1/presets/{name}`.
    PresetName,
    "name",
    "a preset name (GET /v1/presets lists them)",
    |name| name
);

async fn path_param<S: Send + Sync>(
    parts: &mut Parts,
    state: &S,
    name: &str,
    expected: &str,
) -> Result<String, Problem> {
    match Path::<String>::from_request_parts(parts, state).await {
        Ok(Path(value)) => Ok(value),
        Err(PathRejection::FailedToDeserializePathParams(e)) => {
            let got = match e.kind() {
                ErrorKind::InvalidUtf8InPathParam { .. } => {
                    "bytes that are not UTF-8 text once percent-decoded".to_string()
                }
                other => other.to_string(),
            };
            let mut p = Problem::invalid(vec![FieldError::new(
                name,
                format!("expected {expected}; got {got}"),
            )]);
            p.status = StatusCode::BAD_REQUEST;
            p.title = "invalid path parameter".into();
            Err(p)
        }
        // The route table and the handler disagree: the server's fault.
        Err(e) => Err(Problem::internal(e)),
    }
}

/// The body as a JSON object, or a 422 at the root.
pub fn object(body: Value) -> Result<Map<String, Value>, Problem> {
    match body {
        Value::Object(m) => Ok(m),
        other => Err(Problem::invalid(vec![FieldError::new(
            "",
            format!("expected a JSON object, got {}", json_kind(&other)),
        )])),
    }
}

/// Query parameters of the list routes: `limit` (1..=1000, default 50), `cursor` (the
/// `next_cursor` of the previous page), and the route's `extra` ones; each at most once.
pub struct ListQuery {
    pub limit: usize,
    pub cursor: Option<String>,
    pub rest: BTreeMap<String, String>,
}

pub const DEFAULT_PAGE: usize = 50;
pub const MAX_PAGE: usize = 1000;

/// Read a list route's query string. Unknown, repeated or invalid parameters are a
/// 400 problem naming each: a cursor is an id a page returned (`next_cursor`), never
/// empty, so a mistyped or truncated one is refused rather than read as "from the
/// start".
pub fn list_query(raw: Option<String>, extra: &[&str]) -> Result<ListQuery, Problem> {
    let mut limit = DEFAULT_PAGE;
    let mut cursor = None;
    let mut rest = BTreeMap::new();
    let mut errors = Vec::new();
    let mut known = vec!["limit", "cursor"];
    known.extend_from_slice(extra);
    let pairs = query_pairs(raw.as_deref(), &known, &mut errors);
    for (k, v) in pairs {
        match k.as_str() {
            // (Digits only: `parse` would also take "+5".)
            "limit" => match v.parse::<usize>() {
                Ok(n) if (1..=MAX_PAGE).contains(&n) && v.bytes().all(|b| b.is_ascii_digit()) => {
                    limit = n
                }
                _ => errors.push(FieldError::new(
                    "limit",
                    format!("expected an integer from 1 to {MAX_PAGE}, got `{v}`"),
                )),
            },
            "cursor" => match check_cursor(&v) {
                Ok(canonical) => cursor = Some(canonical),
                Err(message) => errors.push(FieldError::new("cursor", message)),
            },
            _ => {
                rest.insert(k, v);
            }
        }
    }
    if !errors.is_empty() {
        return Err(query_problem(errors));
    }
    Ok(ListQuery {
        limit,
        cursor,
        rest,
    })
}

/// Refuse any query parameter (routes that take none).
pub fn no_query(raw: Option<String>) -> Result<(), Problem> {
    let mut errors = Vec::new();
    query_pairs(raw.as_deref(), &[], &mut errors);
    if errors.is_empty() {
        Ok(())
    } else {
        Err(query_problem(errors))
    }
}

/// A query of at most the one boolean parameter `name` (`true` or `false`; absent:
/// false); anything else is a 400 naming it.
pub fn flag_query(raw: Option<String>, name: &str) -> Result<bool, Problem> {
    let mut errors = Vec::new();
    let mut on = false;
    for (_, v) in query_pairs(raw.as_deref(), &[name], &mut errors) {
        match v.as_str() {
            "true" => on = true,
            "false" => on = false,
            _ => errors.push(FieldError::new(
                name,
                format!("expected `true` or `false`, got `{v}`"),
            )),
        }
    }
    if errors.is_empty() {
        Ok(on)
    } else {
        Err(query_problem(errors))
    }
}

/// The decoded pairs of a query string whose names are in `known` and appear once;
/// one error for each unknown name and each repeated one.
fn query_pairs(
    raw: Option<&str>,
    known: &[&str],
    errors: &mut Vec<FieldError>,
) -> Vec<(String, String)> {
    let pairs = raw.map(serde_urlencoded_pairs).unwrap_or_default();
    let mut out = Vec::new();
    for (i, (k, v)) in pairs.iter().enumerate() {
        let first = pairs.iter().position(|(name, _)| name == k) == Some(i);
        let count = pairs.iter().filter(|(name, _)| name == k).count();
        if !known.contains(&k.as_str()) {
            if first {
                let message = if known.is_empty() {
                    "unknown query parameter; this route takes none".to_string()
                } else {
                    format!("unknown query parameter; known: {}", known.join(", "))
                };
                errors.push(FieldError::new(k.clone(), message));
            }
        } else if count > 1 {
            if first {
                errors.push(FieldError::new(
                    k.clone(),
                    format!("given {count} times; give it once"),
                ));
            }
        } else {
            out.push((k.clone(), v.clone()));
        }
    }
    out
}

/// A cursor is the id of the last item of a page: a UUID, as `next_cursor` gives it
/// (hyphenated, lower-case; any case is read). The canonical form, or why not.
fn check_cursor(v: &str) -> Result<String, String> {
    if v.is_empty() {
        return Err(
            "empty; omit `cursor` for the first page, or pass the `next_cursor` of the \
             previous page"
                .into(),
        );
    }
    match uuid::Uuid::parse_str(v) {
        Ok(u) if u.hyphenated().to_string() == v.to_ascii_lowercase() => {
            Ok(u.hyphenated().to_string())
        }
        _ => Err(format!(
            "`{v}` is not a cursor of this server; pass the `next_cursor` of the previous \
             page (an id such as 0190b2a4-7c1e-7d3a-9f00-2b6c1d8e4f10), or omit it for \
             the first page"
        )),
    }
}

pub fn query_problem(errors: Vec<FieldError>) -> Problem {
    let mut p = Problem::invalid(errors);
    p.status = StatusCode::BAD_REQUEST;
    p.title = "invalid query parameters".into();
    p
}

/// Split `a=1&b=x%20y` into decoded pairs.
fn serde_urlencoded_pairs(q: &str) -> Vec<(String, String)> {
    q.split('&')
        .filter(|s| !s.is_empty())
        .map(|kv| {
            let (k, v) = kv.split_once('=').unwrap_or((kv, ""));
            (percent_decode(k), percent_decode(v))
        })
        .collect()
}

fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let hex = |b: u8| (b as char).to_digit(16).map(|d| d as u8);
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'+' => out.push(b' '),
            b'%' if i + 2 < bytes.len() => match (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                (Some(h), Some(l)) => {
                    out.push(h * 16 + l);
                    i += 2;
                }
                _ => out.push(b'%'),
            },
            b => out.push(b),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn query_strings_decode() {
        assert_eq!(
            serde_urlencoded_pairs("status=queued&cursor=a%2Db&x"),
            vec![
                ("status".to_string(), "queued".to_string()),
                ("cursor".to_string(), "a-b".to_string()),
                ("x".to_string(), String::new())
            ]
        );
        assert_eq!(percent_decode("%zz%4"), "%zz%4");
    }
}
