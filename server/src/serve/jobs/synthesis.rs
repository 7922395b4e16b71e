//! The `synthesis` job kind: `{model, set?, target, mode}` → the error levels that
//! reach a desired filtering effect (METHOD §1.7), its points on every core.

use super::{JobKind, JobOutput, PreparedJob, Work};
use crate::parallel::Rayon;
use crate::serve::request as req;
use kea_core::synthesis::{self, SynthesisRequest};
use kea_core::{Error, FieldError, Progress};
use serde_json::Value;
use std::time::Instant;

pub struct Synthesis;

/// The members a synthesis request may have (`model_id` is resolved to `model`).
pub const MEMBERS: &[&str] = &["model", "model_id", "set", "target", "mode"];

/// The modes, the members of `mode` (exactly one).
pub const MODES: &[&str] = &["seed_search", "bisect", "grid"];

impl JobKind for Synthesis {
    fn name(&self) -> &'static str {
        "synthesis"
    }

    fn prepare(&self, request: &Value) -> Result<Box<dyn PreparedJob>, Error> {
        let Value::Object(obj) = request else {
            return Err(Error::invalid("", "expected a JSON object"));
        };
        // The request's shape first, every problem at its member's path; then the
        // core reads it (its serde messages put plainly).
        let mut errors = req::unknown_members(obj, MEMBERS);
        req::model_and_set(obj, &mut errors);
        match obj.get("target") {
            None => errors.push(missing("target")),
            Some(Value::Object(_)) => {}
            Some(other) => errors.push(FieldError::new(
                "target",
                format!(
                    "expected an object such as {{\"criterion\": \"yx\", \"threshold\": 14}}, got {}",
                    req::got(other)
                ),
            )),
        }
        errors.extend(mode_errors(obj.get("mode")));
        if !errors.is_empty() {
            return Err(Error::Invalid(errors));
        }
        let request = synthesis::request_from_value(request.clone())?;
        synthesis::validate(&request)?;
        let work = work(&request).map_err(req::locate)?;
        Ok(Box::new(Prepared { work, request }))
    }
}

fn missing(member: &str) -> FieldError {
    kea_core::error::plain_serde_error(
        FieldError::new("", format!("missing field `{member}`")),
        synthesis::HINTS,
    )
}

/// `mode` must be an object with exactly one member, a mode's name.
fn mode_errors(mode: Option<&Value>) -> Vec<FieldError> {
    let one_of = format!(
        "exactly one of `{}` (docs/synthesis.md), e.g. {{\"bisect\": {{\"param\": \"psi\", \"low\": 1e-6, \"high\": 1e-3}}}}",
        MODES.join("`, `")
    );
    let m = match mode {
        None => {
            return vec![FieldError::new(
                "mode",
                format!("missing: how to search, an object with {one_of}"),
            )];
        }
        Some(Value::Object(m)) => m,
        Some(other) => {
            return vec![FieldError::new(
                "mode",
                format!("expected an object with {one_of}, got {}", req::got(other)),
            )];
        }
    };
    let unknown: Vec<FieldError> = m
        .keys()
        .filter(|k| !MODES.contains(&k.as_str()))
        .map(|k| {
            FieldError::new(
                kea_core::error::member_path("mode", k),
                format!("unknown mode; expected one of: {}", MODES.join(", ")),
            )
        })
        .collect();
    if !unknown.is_empty() {
        return unknown;
    }
    let given: Vec<&str> = m.keys().map(String::as_str).collect();
    match given.len() {
        1 => Vec::new(),
        0 => vec![FieldError::new(
            "mode",
            format!("expected {one_of}; got an empty object"),
        )],
        n => vec![FieldError::new(
            "mode",
            format!(
                "expected exactly one mode of `{}`; got {n}: {} (one synthesis searches one way: submit one job per mode)",
                MODES.join("`, `"),
                given.join(", ")
            ),
        )],
    }
}

/// The work of a synthesis: at most its planned analyses, each the analysis'
/// estimate (the core's, [`kea_core::cost::synthesis_work`]).
pub fn work(request: &SynthesisRequest) -> Result<Work, Error> {
    kea_core::cost::synthesis_work(request)
}

struct Prepared {
    request: SynthesisRequest,
    work: Work,
}

impl PreparedJob for Prepared {
    fn work(&self) -> Work {
        self.work.clone()
    }

    fn run(
        self: Box<Self>,
        progress: &mut dyn Progress,
        stop: &(dyn Fn() -> bool + Sync),
        memo: &dyn kea_core::exec::Memo,
    ) -> Result<JobOutput, Error> {
        let exec = Rayon::new(None)
            .map_err(|e| Error::invalid("", e))?
            .stopping_when(stop);
        let start = Instant::now();
        let mut result = synthesis::synthesize_resuming(&self.request, &exec, progress, memo)?;
        result.timing.wall_ms = start.elapsed().as_secs_f64() * 1e3;
        let result_json = serde_json::to_string(&result)
            .map_err(|e| Error::invalid("", format!("result not serialisable: {e}")))?;
        Ok(JobOutput {
            result_json,
            traces_csv: None,
        })
    }
}
