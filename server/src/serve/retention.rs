//! `--keep-finished`: finished jobs (succeeded, failed, cancelled), with their results,
//! deleted once they have been finished that long. Off by default: nothing the user
//! submitted or computed goes unless asked for (this option, or `DELETE ?purge=true`).
//! A sweep that deleted jobs gives their space back to the file system.

use super::store::Store;
use std::sync::Arc;
use std::time::Duration;

/// How often the sweep runs: a tenth of the retention, from 1 s to 1 h, so a job
/// outlives its retention by at most that.
pub fn interval(keep: Duration) -> Duration {
    (keep / 10).clamp(Duration::from_secs(1), Duration::from_secs(3600))
}

/// The finish time before which a job is deleted, `keep` before now (RFC 3339, UTC).
pub fn cutoff(keep: Duration) -> String {
    let at = time::OffsetDateTime::now_utc() - keep;
    at.format(&time::format_description::well_known::Rfc3339)
        .expect("RFC 3339 formatting of a time")
}

/// Delete the jobs finished more than `keep` ago, then give the space they took back
/// to the file system, now and every [`interval`], for as long as the server runs. A
/// failed sweep is logged and tried again at the next.
pub async fn sweep(store: Arc<dyn Store>, keep: Duration) {
    let mut tick = tokio::time::interval(interval(keep));
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tick.tick().await;
        let store = store.clone();
        let before = cutoff(keep);
        let swept = tokio::task::spawn_blocking(move || {
            let deleted = store.purge_finished_before(&before)?;
            let reclaimed = if deleted > 0 {
                store.reclaim_free_space()?
            } else {
                0
            };
            Ok::<_, super::store::StoreError>((deleted, reclaimed))
        });
        match swept.await {
            Ok(Ok((0, _))) => {}
            Ok(Ok((deleted, reclaimed))) => tracing::info!(
                deleted,
                reclaimed_bytes = reclaimed,
                keep_s = keep.as_secs(),
                "deleted finished jobs past their retention"
            ),
            Ok(Err(e)) => tracing::warn!(error = %e, "retention sweep failed"),
            Err(e) => tracing::warn!(error = %e, "retention sweep failed"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sweep_runs_at_a_tenth_of_the_retention_within_1_s_and_1_h() {
        assert_eq!(interval(Duration::from_secs(2)), Duration::from_secs(1));
        assert_eq!(interval(Duration::from_secs(600)), Duration::from_secs(60));
        assert_eq!(
            interval(Duration::from_secs(30 * 86400)),
            Duration::from_secs(3600)
        );
    }
}
