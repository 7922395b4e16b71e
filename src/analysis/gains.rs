//! The filter's covariance step for a pass that runs beside an analysis (the error
//! budget, the mismatched filter), which needs its gains p_k and h_k step by step: the
//! measurements available at each step ([`Available`]) and the filter itself
//! ([`Filter`]: the measurements prepared again where Rv or the availability changed,
//! then [`SequentialJoseph`]'s step, the one Riccati). The analysis's engine does the
//! same inline, in its hot loop.

use crate::analysis::inputs::{Inputs, time_err};
use crate::error::Error;
use crate::model::compile::CompiledModel;
use crate::model::schedule::Schedules;
use crate::numerics::lanes::Lanes;
use crate::numerics::riccati::{Prepared, SequentialJoseph};

/// The measurements available at each step (all, unless scheduled).
pub(crate) struct Available {
    schedule: Option<Schedules>,
    avail: Vec<bool>,
    prev: Vec<bool>,
    all: bool,
    /// The availability changed at the last [`Available::at`] (true at the first).
    pub(crate) changed: bool,
}

impl Available {
    pub(crate) fn new(m: &CompiledModel) -> Self {
        let nm = m.n_measurements();
        Available {
            schedule: m.schedule.clone(),
            avail: vec![true; nm],
            prev: vec![true; nm],
            all: true,
            changed: true,
        }
    }

    /// The availability at step k (time t); a schedule's error at `model.…`.
    pub(crate) fn at(&mut self, k: u64, t: f64) -> Result<(), Error> {
        if let Some(sc) = self.schedule.as_mut() {
            self.all = sc
                .mask(k, t, &mut self.avail)
                .map_err(|p| crate::request::locate(time_err(&p, k, t)))?;
        }
        self.changed = k == 1 || self.avail != self.prev;
        self.prev.copy_from_slice(&self.avail);
        Ok(())
    }

    /// The mask of available measurements, None for all.
    pub(crate) fn mask(&self) -> Option<&[bool]> {
        (!self.all).then_some(&self.avail[..])
    }

    /// Each measurement's availability at the last step.
    pub(crate) fn each(&self) -> &[bool] {
        &self.avail
    }
}

/// A filter's covariance recursion, from R_0 = diag(η0²).
pub(crate) struct Filter {
    prep: Prepared,
    pub(crate) joseph: SequentialJoseph,
    /// R_k.
    pub(crate) big_r: Vec<f64>,
}

impl Filter {
    pub(crate) fn new(m: &CompiledModel) -> Self {
        let (n, nm) = (m.n_states(), m.n_measurements());
        let mut big_r = vec![0.0; n * n];
        for i in 0..n {
            big_r[i * n + i] = m.eta0[i] * m.eta0[i];
        }
        Filter {
            prep: Prepared::new(n, nm),
            joseph: SequentialJoseph::new(n, nm),
            big_r,
        }
    }

    /// One step of `m`'s filter on its inputs `inp` of this step: the measurements
    /// prepared again where Rv or `avail` changed, then (2.1)–(2.7). False where Rv is
    /// not semi-definite or an innovation variance not positive (the analysis's run of
    /// the same step has said so first).
    #[inline(always)]
    pub(crate) fn step<const N: usize, L: Lanes>(
        &mut self,
        m: &CompiledModel,
        inp: &Inputs,
        avail: &Available,
    ) -> bool {
        let (n, nm) = (m.n_states(), m.n_measurements());
        if (inp.rv_changed || avail.changed)
            && self
                .prep
                .prepare(&m.c, &inp.rv, avail.mask(), n, nm)
                .is_err()
        {
            return false;
        }
        self.joseph
            .step::<N, L>(n, &mut self.big_r, &inp.e, &inp.big_b, &self.prep)
    }
}
