//! The nonlinear procedure as a kind of run ([`crate::kind`]): `{model, set?, data,
//! procedure?, q_scale?, checkpoints?, trace_points?}` → the EKF, the K regularised
//! filters and the chosen iterate (METHOD §4).

use super::request::{NonlinearRequest, read};
use super::result::NonlinearResult;
use crate::error::Error;
use crate::exec::{Executor, Memo};
use crate::kind::{Kind, Timing};
use crate::progress::Progress;
use crate::request;
use crate::work::Work;
use serde_json::{Map, Value};

/// The nonlinear kind.
pub struct Nonlinear;

impl Kind for Nonlinear {
    const NAME: &'static str = "nonlinear";
    const ALIASES: &'static [&'static str] = &[];
    const MEMBERS: &'static [&'static str] = &[
        "model",
        "set",
        "data",
        "procedure",
        "q_scale",
        "checkpoints",
        "trace_points",
    ];
    type Request = NonlinearRequest;
    type Outcome = NonlinearResult;

    fn prepare(obj: Map<String, Value>) -> Result<NonlinearRequest, Error> {
        let errors = request::unknown_members(&obj, Self::MEMBERS);
        if !errors.is_empty() {
            return Err(Error::Invalid(errors));
        }
        read(&obj)
    }

    fn work(r: &NonlinearRequest) -> Work {
        super::work::nonlinear_work(r)
    }

    fn run<E: Executor>(
        r: &NonlinearRequest,
        _exec: &E,
        progress: &mut dyn Progress,
        _memo: &dyn Memo,
    ) -> Result<NonlinearResult, Error> {
        super::run::run(r, progress)
    }

    fn timing(o: &mut NonlinearResult) -> &mut Timing {
        &mut o.timing
    }

    fn text(o: &NonlinearResult) -> String {
        super::report::text(o)
    }

    /// The decimated traces: `n,t`, the measurements, the truth, the EKF and its SKO,
    /// each iterate, filter 1's SKO, the Q-scaled EKF.
    fn csv(o: &NonlinearResult) -> Option<String> {
        Some(super::report::traces_csv(o))
    }
}
