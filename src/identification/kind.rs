//! The identification as a kind of run ([`crate::kind`]): `{model, set?, data,
//! estimate, method?, max_iterations?, starts?, expected_information?}` → the maximum-likelihood params with their
//! standard errors (METHOD §3).

use super::fit::identify;
use super::request::{IdentificationRequest, read};
use super::result::IdentificationResult;
use crate::error::Error;
use crate::exec::{Executor, Memo};
use crate::kind::{Kind, Timing};
use crate::progress::Progress;
use crate::request;
use crate::work::Work;
use serde_json::{Map, Value};

/// The identification kind.
pub struct Identification;

impl Kind for Identification {
    const NAME: &'static str = "identification";
    const ALIASES: &'static [&'static str] = &[];
    const MEMBERS: &'static [&'static str] = &[
        "model",
        "model_id",
        "set",
        "data",
        "estimate",
        "method",
        "max_iterations",
        "starts",
        "expected_information",
    ];
    type Request = IdentificationRequest;
    type Outcome = IdentificationResult;

    fn prepare(obj: Map<String, Value>) -> Result<IdentificationRequest, Error> {
        let errors = request::unknown_members(&obj, Self::MEMBERS);
        if !errors.is_empty() {
            return Err(Error::Invalid(errors));
        }
        read(&obj)
    }

    fn work(r: &IdentificationRequest) -> Work {
        super::work::identification_work(r)
    }

    fn run<E: Executor>(
        r: &IdentificationRequest,
        _exec: &E,
        progress: &mut dyn Progress,
        _memo: &dyn Memo,
    ) -> Result<IdentificationResult, Error> {
        identify(r, progress).map_err(request::locate)
    }

    fn timing(o: &mut IdentificationResult) -> &mut Timing {
        &mut o.timing
    }

    fn text(o: &IdentificationResult) -> String {
        super::report::text(o)
    }

    /// The innovations at θ̂, every step: `t,nis,innovation:NAME…`.
    fn csv(o: &IdentificationResult) -> Option<String> {
        o.series.as_ref().map(super::report::innovations_csv)
    }
}
