//! The synthesis as a kind of run ([`crate::kind`]): `{model, set?, target, mode}` →
//! the error levels that reach a desired filtering effect (METHOD §1.7).

use super::{HINTS, SynthesisRequest, SynthesisResult};
use crate::analysis::result::Timing;
use crate::error::{Error, FieldError, got, member_path, plain_serde_error};
use crate::exec::{Executor, Memo};
use crate::kind::Kind;
use crate::progress::Progress;
use crate::request;
use crate::work::Work;
use serde_json::{Map, Value};

/// The synthesis kind.
pub struct Synthesis;

/// The modes, the members of `mode` (exactly one).
pub const MODES: &[&str] = &["seed_search", "bisect", "grid"];

/// A synthesis request, validated, with its work estimate and its one analysis's.
pub struct Request {
    pub synthesis: SynthesisRequest,
    work: Work,
    analysis_work: f64,
}

impl Kind for Synthesis {
    const NAME: &'static str = "synthesis";
    const ALIASES: &'static [&'static str] = &[];
    const MEMBERS: &'static [&'static str] = &["model", "model_id", "set", "target", "mode"];
    type Request = Request;
    type Outcome = SynthesisResult;

    fn prepare(obj: Map<String, Value>) -> Result<Request, Error> {
        // The request's shape first, every problem at its member's path; then the
        // synthesis reads it (its serde messages put plainly).
        let mut errors = request::unknown_members(&obj, Self::MEMBERS);
        request::model_and_set(&obj, &mut errors);
        match obj.get("target") {
            None => errors.push(missing("target")),
            Some(Value::Object(_)) => {}
            Some(other) => errors.push(FieldError::new(
                "target",
                format!(
                    "expected an object such as {{\"criterion\": \"yx\", \"threshold\": 14}}, got {}",
                    got(other)
                ),
            )),
        }
        errors.extend(mode_errors(obj.get("mode")));
        if !errors.is_empty() {
            return Err(Error::Invalid(errors));
        }
        let synthesis = super::request_from_value(Value::Object(obj))?;
        let compiled = super::validated(&synthesis)?;
        let one = crate::analysis::work::analysis_work(&compiled, Some(&synthesis.model));
        Ok(Request {
            work: super::work::synthesis_work_of(&synthesis, &one),
            analysis_work: one.units,
            synthesis,
        })
    }

    fn work(r: &Request) -> Work {
        r.work.clone()
    }

    fn run<E: Executor>(
        r: &Request,
        exec: &E,
        progress: &mut dyn Progress,
        memo: &dyn Memo,
    ) -> Result<SynthesisResult, Error> {
        // Each analysis is kept in the memo: a run after a restart takes them.
        super::synthesize_validated(&r.synthesis, r.analysis_work, exec, progress, memo)
    }

    fn timing(o: &mut SynthesisResult) -> &mut Timing {
        &mut o.timing
    }

    fn text(o: &SynthesisResult) -> String {
        super::render_text(o)
    }

    fn csv(_: &SynthesisResult) -> Option<String> {
        None
    }
}

fn missing(member: &str) -> FieldError {
    plain_serde_error(
        FieldError::new("", format!("missing field `{member}`")),
        HINTS,
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
                format!("expected an object with {one_of}, got {}", got(other)),
            )];
        }
    };
    let unknown: Vec<FieldError> = m
        .keys()
        .filter(|k| !MODES.contains(&k.as_str()))
        .map(|k| {
            FieldError::new(
                member_path("mode", k),
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
