//! Errors as `application/problem+json` (RFC 9457), with `errors: [{path, message}]`
//! pointing into the submitted JSON. 4xx for anything the client did wrong; 5xx only
//! for the server's own failures (storage).

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use kea_core::FieldError;
use serde::Serialize;

/// Problem types (the `type` member): stable identifiers clients can match on.
pub mod kind {
    pub const INVALID: &str = "urn:kea:problem:invalid-request";
    pub const MALFORMED: &str = "urn:kea:problem:malformed-json";
    pub const NUMERICAL: &str = "urn:kea:problem:numerical";
    pub const USE_A_JOB: &str = "urn:kea:problem:use-a-job";
    pub const TOO_MUCH_WORK: &str = "urn:kea:problem:too-much-work";
    pub const NOT_FOUND: &str = "urn:kea:problem:not-found";
    pub const METHOD: &str = "urn:kea:problem:method-not-allowed";
    pub const CONFLICT: &str = "urn:kea:problem:conflict";
    pub const UNAUTHORIZED: &str = "urn:kea:problem:unauthorized";
    pub const FORBIDDEN_HOST: &str = "urn:kea:problem:forbidden-host";
    pub const TOO_LARGE: &str = "urn:kea:problem:body-too-large";
    pub const BODY_TIMEOUT: &str = "urn:kea:problem:body-timeout";
    pub const MEDIA_TYPE: &str = "urn:kea:problem:unsupported-media-type";
    pub const QUEUE_FULL: &str = "urn:kea:problem:queue-full";
    pub const INTERNAL: &str = "urn:kea:problem:internal";
    /// A job the server stopped while running too many times (`worker::MAX_INTERRUPTIONS`).
    pub const INTERRUPTED: &str = "urn:kea:problem:interrupted";
}

#[derive(Clone, Debug, Serialize)]
pub struct Problem {
    #[serde(rename = "type")]
    pub type_: &'static str,
    pub title: String,
    #[serde(serialize_with = "ser_status")]
    pub status: StatusCode,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail: Option<String>,
    pub errors: Vec<FieldError>,
    #[serde(skip)]
    pub headers: Vec<(header::HeaderName, HeaderValue)>,
}

fn ser_status<S: serde::Serializer>(s: &StatusCode, ser: S) -> Result<S::Ok, S::Error> {
    ser.serialize_u16(s.as_u16())
}

impl Problem {
    pub fn new(status: StatusCode, type_: &'static str, title: impl Into<String>) -> Self {
        Problem {
            type_,
            title: title.into(),
            status,
            detail: None,
            errors: Vec::new(),
            headers: Vec::new(),
        }
    }

    pub fn detail(mut self, detail: impl Into<String>) -> Self {
        self.detail = Some(detail.into());
        self
    }

    pub fn error(mut self, path: impl Into<String>, message: impl Into<String>) -> Self {
        self.errors.push(FieldError::new(path, message));
        self
    }

    pub fn header(mut self, name: header::HeaderName, value: &str) -> Self {
        if let Ok(v) = HeaderValue::from_str(value) {
            self.headers.push((name, v));
        }
        self
    }

    /// 422 with the given field errors, at most [`MAX_ERRORS`] of them (see [`capped`]).
    pub fn invalid(errors: Vec<FieldError>) -> Self {
        let mut p = Problem::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            kind::INVALID,
            "the request is invalid",
        );
        let (errors, omitted) = capped(errors);
        p.detail = Some(summary(&errors, omitted));
        p.errors = errors;
        p
    }

    pub fn not_found(what: &str, id: &str) -> Self {
        Problem::new(
            StatusCode::NOT_FOUND,
            kind::NOT_FOUND,
            format!("{what} not found"),
        )
        .detail(format!("there is no {what} with id `{id}`"))
    }

    pub fn conflict(title: impl Into<String>, detail: impl Into<String>) -> Self {
        Problem::new(StatusCode::CONFLICT, kind::CONFLICT, title).detail(detail)
    }

    /// The server's own failure (never the client's input).
    pub fn internal(err: impl std::fmt::Display) -> Self {
        tracing::error!(error = %err, "internal error");
        Problem::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            kind::INTERNAL,
            "internal server error",
        )
        .detail("the server failed; the error is in its log")
    }

    /// Map a core error whose paths already point into the request body.
    pub fn from_core(err: kea_core::Error) -> Self {
        match err {
            kea_core::Error::Invalid(errors) => Problem::invalid(errors),
            e @ kea_core::Error::Numerical { .. } => {
                let errors = e.field_errors();
                let mut p = Problem::new(
                    StatusCode::UNPROCESSABLE_ENTITY,
                    kind::NUMERICAL,
                    "the model cannot be computed",
                );
                p.detail = Some(summary(&errors, 0));
                p.errors = errors;
                p
            }
            kea_core::Error::Cancelled => {
                Problem::conflict("cancelled", "the computation was cancelled")
            }
        }
    }
}

/// The most errors a problem lists: the core's cap, so every error list reads alike.
pub const MAX_ERRORS: usize = kea_core::error::MAX_REPORTED_ERRORS;

pub use kea_core::error::{omitted_count, omitted_entry};

/// Errors from several sources (the server's own checks, the core's already-cut
/// list) as one list of at most [`MAX_ERRORS`], with one entry at the top level for
/// all that were left out; and how many were.
pub fn capped(errors: Vec<FieldError>) -> (Vec<FieldError>, usize) {
    let mut omitted = 0;
    let mut listed = Vec::with_capacity(errors.len().min(MAX_ERRORS + 1));
    for e in errors {
        match omitted_count(&e) {
            Some(n) => omitted += n,
            None if listed.len() < MAX_ERRORS => listed.push(e),
            None => omitted += 1,
        }
    }
    if omitted > 0 {
        listed.push(omitted_entry(omitted));
    }
    (listed, omitted)
}

/// The `detail` of a list of errors: the first, and how many more there are in all
/// (`errors` may end with the [`omitted_entry`] for `omitted` of them).
fn summary(errors: &[FieldError], omitted: usize) -> String {
    let listed = errors.len() - usize::from(omitted > 0);
    match errors {
        [] => "the request is invalid".into(),
        [one] => one.to_string(),
        [first, ..] => match listed - 1 + omitted {
            0 => first.to_string(),
            more => format!("{first} (and {more} more)"),
        },
    }
}

impl From<super::store::StoreError> for Problem {
    fn from(e: super::store::StoreError) -> Self {
        Problem::internal(e)
    }
}

impl IntoResponse for Problem {
    fn into_response(self) -> Response {
        let body = serde_json::to_vec(&self).expect("problem serialises");
        let mut res = (self.status, body).into_response();
        let h = res.headers_mut();
        h.insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/problem+json"),
        );
        for (name, value) in self.headers {
            h.insert(name, value);
        }
        res
    }
}
