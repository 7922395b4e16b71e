//! The sensitivity as a kind of run ([`crate::kind`]): `{model, set?, params?,
//! relative_step?, rank_by?}` → d ln F / d ln p for every weighted criterion and param.

use super::{
    CRITERIA, DEFAULT_RELATIVE_STEP, MAX_PARAMS, RELATIVE_STEP_RANGE, SensitivityRequest,
    SensitivityResult,
};
use crate::error::{Error, FieldError, got};
use crate::exec::{Executor, Memo};
use crate::kind::{Kind, Timing};
use crate::progress::Progress;
use crate::request;
use crate::work::Work;
use serde_json::{Map, Value};

/// The sensitivity kind.
pub struct Sensitivity;

/// A sensitivity request, read, with its work estimate and its one analysis's.
pub struct Request {
    pub sensitivity: SensitivityRequest,
    work: Work,
    analysis_work: f64,
}

impl Kind for Sensitivity {
    const NAME: &'static str = "sensitivity";
    const ALIASES: &'static [&'static str] = &[];
    const MEMBERS: &'static [&'static str] = &[
        "model",
        "model_id",
        "set",
        "params",
        "relative_step",
        "rank_by",
    ];
    type Request = Request;
    type Outcome = SensitivityResult;

    fn prepare(obj: Map<String, Value>) -> Result<Request, Error> {
        let mut errors = request::unknown_members(&obj, Self::MEMBERS);
        let (model, set) = request::model_and_set(&obj, &mut errors);
        let relative_step = match obj.get("relative_step") {
            None => DEFAULT_RELATIVE_STEP,
            Some(v) => {
                let (lo, hi) = RELATIVE_STEP_RANGE;
                match v.as_f64().filter(|h| (lo..=hi).contains(h)) {
                    Some(h) => h,
                    None => {
                        errors.push(FieldError::new(
                            "relative_step",
                            format!("expected a number from {lo:e} to {hi}, got {}", got(v)),
                        ));
                        DEFAULT_RELATIVE_STEP
                    }
                }
            }
        };
        let choices: Vec<(&str, &str)> = CRITERIA
            .iter()
            .map(|c| (*c, "a weighted criterion"))
            .collect();
        let rank_by = request::choice(&obj, "rank_by", &choices, &mut errors).unwrap_or(0);
        let Some(model) = model.filter(|_| errors.is_empty()) else {
            return Err(Error::Invalid(errors));
        };
        let params = params(obj.get("params"), &model)?;
        let compiled = request::compile(&model, &set).map_err(request::locate)?;
        let one = crate::analysis::work::analysis_work(&compiled, Some(&model));
        let analyses = 1 + 2 * params.len();
        let work = Work {
            units: analyses as f64 * one.units,
            explain: format!("{analyses} analyses × {:.3e} ({})", one.units, one.explain),
            path: "params".into(),
        };
        Ok(Request {
            sensitivity: SensitivityRequest {
                model,
                set,
                params,
                relative_step,
                rank_by,
            },
            work,
            analysis_work: one.units,
        })
    }

    fn work(r: &Request) -> Work {
        r.work.clone()
    }

    fn run<E: Executor>(
        r: &Request,
        exec: &E,
        progress: &mut dyn Progress,
        _memo: &dyn Memo,
    ) -> Result<SensitivityResult, Error> {
        super::run(&r.sensitivity, r.analysis_work, exec, progress)
    }

    fn timing(o: &mut SensitivityResult) -> &mut Timing {
        &mut o.timing
    }

    fn text(o: &SensitivityResult) -> String {
        super::render_text(o)
    }

    fn csv(_o: &SensitivityResult) -> Option<String> {
        None
    }
}

/// `params`: names of the model's params, each once (default: all of them, in
/// alphabetical order); at most [`MAX_PARAMS`].
fn params(v: Option<&Value>, model: &crate::model::Model) -> Result<Vec<String>, Error> {
    let Some(v) = v else {
        if model.params.is_empty() {
            return Err(Error::invalid(
                "model.params",
                "the model has no params: a sensitivity is taken with respect to params",
            ));
        }
        if model.params.len() > MAX_PARAMS {
            return Err(Error::invalid(
                "params",
                format!(
                    "the model has {} params, more than {MAX_PARAMS}: name the ones to vary",
                    model.params.len()
                ),
            ));
        }
        return Ok(model.params.keys().cloned().collect());
    };
    let Some(list) = v.as_array().filter(|l| !l.is_empty()) else {
        return Err(Error::invalid(
            "params",
            format!(
                "expected a list of param names such as [\"q\", \"r\"], got {}",
                got(v)
            ),
        ));
    };
    if list.len() > MAX_PARAMS {
        return Err(Error::invalid(
            "params",
            format!("{} params, more than {MAX_PARAMS}", list.len()),
        ));
    }
    let mut errors = Vec::new();
    let mut names: Vec<String> = Vec::new();
    for (i, item) in list.iter().enumerate() {
        let path = format!("params[{i}]");
        match item.as_str() {
            None => errors.push(FieldError::new(
                &path,
                format!("expected a param name, got {}", got(item)),
            )),
            Some(name) if !model.params.contains_key(name) => {
                let known: Vec<&str> = model.params.keys().map(String::as_str).collect();
                errors.push(FieldError::new(
                    &path,
                    format!(
                        "\"{name}\" is not a param of the model (its params: {})",
                        known.join(", ")
                    ),
                ));
            }
            Some(name) if names.iter().any(|n| n == name) => {
                errors.push(FieldError::new(&path, format!("\"{name}\" is named twice")));
            }
            Some(name) => names.push(name.to_string()),
        }
    }
    if errors.is_empty() {
        Ok(names)
    } else {
        Err(Error::Invalid(errors))
    }
}
