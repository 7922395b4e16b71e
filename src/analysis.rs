//! The analysis engine (METHOD §1.2–§1.6). Under construction.
use crate::error::Error;
use crate::result::AnalysisResult;
use crate::validate::CompiledModel;
use crate::Progress;

pub fn run(_m: &CompiledModel, _progress: &mut dyn Progress) -> Result<AnalysisResult, Error> {
    Err(Error::invalid("", "not implemented yet"))
}
