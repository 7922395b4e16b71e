//! Executors: how a batch of independent computations (e.g. the points of a synthesis
//! grid) is run. The core only knows [`Sequential`]; adapters that may use threads
//! (the server's rayon pool) implement [`Executor`] themselves, so the core stays free
//! of threads and still builds for wasm.
//!
//! Contract: `map` returns the results in the order of `items`, and each result
//! depends only on its item, so a computation gives identical answers whatever the
//! number of threads.

/// Runs a function over a batch of items, preserving order.
pub trait Executor: Sync {
    /// `f` applied to every item; `result[i] = f(items[i])`.
    fn map<T: Send, R: Send, F: Fn(T) -> R + Sync>(&self, items: Vec<T>, f: F) -> Vec<R>;

    /// How many items run at once (a batching hint only: it never changes a result).
    fn threads(&self) -> usize {
        1
    }

    /// Whether the computations running in a batch should stop now (a cancel, a time
    /// limit, a shutdown): asked by each of them at its progress points, where the
    /// caller's own [`crate::progress::Progress`] cannot be (it is not shared between threads).
    /// Never true for [`Sequential`], whose items report to the caller in turn.
    fn stop_requested(&self) -> bool {
        false
    }
}

/// One item after another on the calling thread (the core's default, and the browser's).
#[derive(Clone, Copy, Debug, Default)]
pub struct Sequential;

impl Executor for Sequential {
    fn map<T: Send, R: Send, F: Fn(T) -> R + Sync>(&self, items: Vec<T>, f: F) -> Vec<R> {
        items.into_iter().map(f).collect()
    }
}

/// Where a computation keeps the parts it has finished, so that a run of the same
/// request after an interruption takes them instead of computing them again: the
/// computation visits the same parts in the same order (every answer is bit-identical
/// whatever the executor), so an interrupted run is resumed by its own replay. Keys
/// and values are text (the core has no storage). A synthesis keeps its analyses: a
/// key names a point's params exactly (their bits), a value is the analysis's outcome
/// as JSON; a value that does not read back is ignored, and the analysis is run.
pub trait Memo: Sync {
    fn recall(&self, key: &str) -> Option<String>;
    fn keep(&self, key: &str, value: &str);
    /// Keep a long computation's state under `key`, replacing the one kept before, and
    /// write it through now: it is kept seldom ([`Memo::state_due`]), and a restart
    /// goes on from it. Like [`Memo::keep`], by default.
    fn keep_state(&self, key: &str, value: &str) {
        self.keep(key, value);
    }
    /// Whether a long computation should keep its state now (an analysis's step loop
    /// asks at its progress reports, a Monte Carlo between its chunks:
    /// [`crate::resume`]): the keeper's clock says, as the core has none. Never, by
    /// default.
    fn state_due(&self) -> bool {
        false
    }
}

/// No memory: every part is computed (the CLI, the browser; a server job keeps its
/// parts in its store).
pub struct Forgetful;

impl Memo for Forgetful {
    fn recall(&self, _: &str) -> Option<String> {
        None
    }
    fn keep(&self, _: &str, _: &str) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sequential_preserves_order() {
        assert_eq!(Sequential.map(vec![3, 1, 2], |x| x * 10), vec![30, 10, 20]);
        assert_eq!(Sequential.threads(), 1);
    }
}
