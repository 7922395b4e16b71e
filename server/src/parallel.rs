//! The native [`Executor`]: a batch of independent computations (synthesis points)
//! on every core with rayon. Order is preserved and each item's result depends only on
//! the item, so answers are identical whatever the thread count.

use kea_core::exec::Executor;
use rayon::prelude::*;

/// Runs batches on a rayon pool: the global one (every core) or one of `threads`.
pub struct Rayon<'s> {
    pool: Option<rayon::ThreadPool>,
    /// Asked by the batch's computations whether to stop ([`Executor::stop_requested`]).
    stop: Option<&'s (dyn Fn() -> bool + Sync)>,
}

impl<'s> Rayon<'s> {
    /// `None` or `Some(0)`: every core (rayon's global pool); `Some(n)`: n threads.
    pub fn new(threads: Option<usize>) -> Result<Rayon<'s>, String> {
        match threads {
            None | Some(0) => Ok(Rayon {
                pool: None,
                stop: None,
            }),
            Some(n) => rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map(|pool| Rayon {
                    pool: Some(pool),
                    stop: None,
                })
                .map_err(|e| format!("cannot start {n} threads: {e}")),
        }
    }

    /// The same executor, whose computations stop when `stop` says so.
    pub fn stopping_when(self, stop: &'s (dyn Fn() -> bool + Sync)) -> Rayon<'s> {
        Rayon {
            stop: Some(stop),
            ..self
        }
    }
}

impl Executor for Rayon<'_> {
    fn map<T: Send, R: Send, F: Fn(T) -> R + Sync>(&self, items: Vec<T>, f: F) -> Vec<R> {
        let run = || items.into_par_iter().map(&f).collect();
        match &self.pool {
            Some(pool) => pool.install(run),
            None => run(),
        }
    }

    fn threads(&self) -> usize {
        match &self.pool {
            Some(pool) => pool.current_num_threads(),
            None => rayon::current_num_threads(),
        }
    }

    fn stop_requested(&self) -> bool {
        self.stop.is_some_and(|stop| stop())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_is_preserved_for_any_thread_count() {
        let items: Vec<u64> = (0..1000).collect();
        let expect: Vec<u64> = items.iter().map(|x| x * x).collect();
        for t in [None, Some(1), Some(3)] {
            let r = Rayon::new(t).unwrap();
            assert_eq!(r.map(items.clone(), |x| x * x), expect);
        }
        assert_eq!(Rayon::new(Some(3)).unwrap().threads(), 3);
    }
}
