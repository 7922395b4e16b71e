//! The embedded store: one SQLite file (`kea.sqlite`) in the data directory, WAL mode,
//! schema versioned by `PRAGMA user_version` and migrated forward on open, and
//! `auto_vacuum = INCREMENTAL`, so that what is deleted goes back to the file system
//! (`reclaim_step` after each delete, [`Store::reclaim_free_space`] after a batch).

use super::{
    Deleted, Enqueued, GiveUp, JobRecord, JobStatus, ModelRecord, ModelSummary, Outcome, Page,
    Requeued, Result, Store, StoreError,
};
use rusqlite::{Connection, OptionalExtension, Row, TransactionBehavior, params};
use std::collections::HashMap;
use std::path::Path;
use std::sync::Mutex;

/// Migrations, in order; `user_version` = how many have been applied. Never edit a
/// shipped migration: append a new one.
const MIGRATIONS: &[&str] = &[
    // 1: models, jobs, job results.
    "CREATE TABLE models (
        id TEXT PRIMARY KEY,
        name TEXT,
        created_at TEXT NOT NULL,
        model_json TEXT NOT NULL
     );
     CREATE TABLE jobs (
        id TEXT PRIMARY KEY,
        kind TEXT NOT NULL,
        status TEXT NOT NULL,
        progress REAL NOT NULL DEFAULT 0,
        request_json TEXT NOT NULL,
        work REAL NOT NULL,
        created_at TEXT NOT NULL,
        started_at TEXT,
        finished_at TEXT,
        error_json TEXT,
        attempts INTEGER NOT NULL DEFAULT 0
     );
     CREATE INDEX jobs_by_status ON jobs (status, id);
     CREATE TABLE job_results (
        job_id TEXT PRIMARY KEY REFERENCES jobs (id) ON DELETE CASCADE,
        result_json TEXT NOT NULL,
        traces_csv TEXT
     );",
    // 2: a cancel asked for while the job runs, so that it is not lost with the process.
    "ALTER TABLE jobs ADD COLUMN cancel_requested INTEGER NOT NULL DEFAULT 0;",
    // 3: what a running job has finished (a synthesis's analyses), so that a run after a
    // restart resumes; dropped when the job ends.
    "CREATE TABLE job_checkpoints (
        job_id TEXT NOT NULL REFERENCES jobs (id) ON DELETE CASCADE,
        key TEXT NOT NULL,
        value TEXT NOT NULL,
        PRIMARY KEY (job_id, key)
     );",
    // 4: how many times a process ended (a crash, a kill) while it ran this job, so
    // that a job that brings the server down is not run on every start.
    "ALTER TABLE jobs ADD COLUMN interruptions INTEGER NOT NULL DEFAULT 0;",
    // 5: the submitted model's name, for a list of jobs (read from the stored requests).
    "ALTER TABLE jobs ADD COLUMN model_name TEXT;
     UPDATE jobs SET model_name = json_extract(request_json, '$.model.name')
      WHERE json_valid(request_json) AND json_type(request_json, '$.model.name') = 'text';",
];

/// How much free space one delete gives back at once (`PRAGMA incremental_vacuum`
/// moves pages from the file's end into the holes, then truncates): a bound on what a
/// `DELETE` request waits for. [`Store::reclaim_free_space`] gives back the rest, in
/// steps of this size with the store unlocked between them.
const RECLAIM_STEP_BYTES: i64 = 16 << 20;

/// The `-wal` file is cut back to this size when a checkpoint has emptied it: without
/// a limit it keeps the size of the largest transaction it ever held.
const WAL_SIZE_LIMIT_BYTES: i64 = 8 << 20;

/// `PRAGMA auto_vacuum` of a database that keeps free pages for `incremental_vacuum`.
const AUTO_VACUUM_INCREMENTAL: i64 = 2;

pub struct SqliteStore {
    conn: Mutex<Connection>,
    /// `kea.lock`, locked exclusively while the store lives (the OS releases it when
    /// the process ends, however it ends): a second `kea serve` on the same directory
    /// would re-queue, and run again, the jobs the first one is running.
    _lock: std::fs::File,
}

/// Lock `dir/kea.lock` for this process, or say which directory is in use.
fn lock_dir(dir: &Path) -> Result<std::fs::File> {
    let path = dir.join("kea.lock");
    let file = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(|e| StoreError(format!("cannot open {}: {e}", path.display())))?;
    match file.try_lock() {
        Ok(()) => Ok(file),
        Err(std::fs::TryLockError::WouldBlock) => Err(StoreError(format!(
            "the data directory {} is in use by another kea process (it holds {}): \
             stop that one, or give this one another --data-dir",
            dir.display(),
            path.display()
        ))),
        Err(std::fs::TryLockError::Error(e)) => {
            Err(StoreError(format!("cannot lock {}: {e}", path.display())))
        }
    }
}

fn db_err(e: rusqlite::Error) -> StoreError {
    StoreError(e.to_string())
}

const JOB_COLUMNS: &str = "id, kind, status, progress, request_json, work, created_at, \
                           started_at, finished_at, error_json, attempts, cancel_requested, \
                           model_name";

fn job_from_row(row: &Row<'_>) -> rusqlite::Result<JobRecord> {
    let status: String = row.get(2)?;
    Ok(JobRecord {
        id: row.get(0)?,
        kind: row.get(1)?,
        status: JobStatus::parse(&status).unwrap_or(JobStatus::Failed),
        progress: row.get(3)?,
        request_json: row.get(4)?,
        work: row.get(5)?,
        created_at: row.get(6)?,
        started_at: row.get(7)?,
        finished_at: row.get(8)?,
        error_json: row.get(9)?,
        attempts: row.get(10)?,
        cancel_requested: row.get::<_, i64>(11)? != 0,
        model_name: row.get(12)?,
    })
}

impl SqliteStore {
    /// Lock `dir` for this process, open (creating if needed) `kea.sqlite` in it and
    /// migrate it.
    pub fn open(dir: &Path) -> Result<SqliteStore> {
        std::fs::create_dir_all(dir).map_err(|e| {
            StoreError(format!(
                "cannot create data directory {}: {e}",
                dir.display()
            ))
        })?;
        let lock = lock_dir(dir)?;
        let conn = Connection::open(dir.join("kea.sqlite")).map_err(db_err)?;
        conn.busy_timeout(std::time::Duration::from_secs(10))
            .map_err(db_err)?;
        // First, before anything writes the file: a new database has no table yet, so
        // it takes the setting at once (an existing one, see `use_incremental_vacuum`).
        conn.pragma_update(None, "auto_vacuum", "INCREMENTAL")
            .map_err(db_err)?;
        conn.execute_batch(&format!(
            "PRAGMA journal_mode = WAL; PRAGMA synchronous = NORMAL; PRAGMA foreign_keys = ON;
             PRAGMA journal_size_limit = {WAL_SIZE_LIMIT_BYTES};"
        ))
        .map_err(db_err)?;
        let store = SqliteStore {
            conn: Mutex::new(conn),
            _lock: lock,
        };
        store.migrate()?;
        store.use_incremental_vacuum();
        // What a process that ended in the middle of giving space back had left (a
        // failure here leaves free pages for reuse; it does not keep the store shut).
        if let Err(e) = store.reclaim_free_space() {
            tracing::warn!(error = %e, "could not give the store's free space back to the file system");
        }
        Ok(store)
    }

    /// Switch a store created before kea set `auto_vacuum` (none: SQLite keeps freed
    /// pages in the file for reuse and never shrinks it) to incremental, once. The
    /// setting changes only with a `VACUUM`, which rewrites the whole file; it is not a
    /// migration, since `VACUUM` cannot run in a migration's transaction and a new
    /// store needs none. It takes time in proportion to the file (seconds a GB) and
    /// free disk of about the file's size twice over: SQLite's copy in the temporary
    /// directory, then the rewritten pages in the `-wal` (emptied by the checkpoint
    /// after it). If it fails (a full disk, say), the store works as before, reusing
    /// its free pages, and the next start tries again. `VACUUM` may renumber rows but
    /// copies them in their order, so the queue's order (`claim_next`, by rowid) holds.
    fn use_incremental_vacuum(&self) {
        let converted = self.with(|c| {
            let mode: i64 = c.query_row("PRAGMA auto_vacuum", [], |r| r.get(0))?;
            if mode == AUTO_VACUUM_INCREMENTAL {
                return Ok(None);
            }
            let before = file_bytes(c)?;
            tracing::info!(
                size_bytes = before,
                "switching the store to incremental auto-vacuum, once: a VACUUM rewrites the \
                 file (it needs free disk of its size in the temporary directory and as \
                 much again in the data directory)"
            );
            let started = std::time::Instant::now();
            c.pragma_update(None, "auto_vacuum", "INCREMENTAL")?;
            c.execute_batch("VACUUM")?;
            checkpoint(c)?;
            Ok(Some((before, file_bytes(c)?, started.elapsed())))
        });
        match converted {
            Ok(None) => {}
            Ok(Some((before, after, took))) => tracing::info!(
                size_bytes_before = before,
                size_bytes = after,
                took_ms = took.as_millis() as u64,
                "the store now gives deleted space back to the file system"
            ),
            Err(e) => tracing::warn!(
                error = %e,
                "could not switch the store to incremental auto-vacuum (tried again at the \
                 next start); deleted space is reused but not given back"
            ),
        }
    }

    /// Give back what a delete freed, up to [`RECLAIM_STEP_BYTES`]; a failure is
    /// logged, not returned: the delete itself is done.
    fn reclaim_after_delete(&self) {
        if let Err(e) = self.with(|c| reclaim_step(c).map(|_| ())) {
            tracing::warn!(error = %e, "could not give deleted space back to the file system");
        }
    }

    fn migrate(&self) -> Result<()> {
        let mut conn = self.conn.lock().expect("store lock");
        let version: i64 = conn
            .query_row("PRAGMA user_version", [], |r| r.get(0))
            .map_err(db_err)?;
        let version = version.max(0) as usize;
        if version > MIGRATIONS.len() {
            return Err(StoreError(format!(
                "the data directory's schema version {version} is newer than this kea \
                 build ({}); upgrade kea",
                MIGRATIONS.len()
            )));
        }
        for (i, sql) in MIGRATIONS.iter().enumerate().skip(version) {
            let tx = conn.transaction().map_err(db_err)?;
            tx.execute_batch(sql).map_err(db_err)?;
            tx.pragma_update(None, "user_version", (i + 1) as i64)
                .map_err(db_err)?;
            tx.commit().map_err(db_err)?;
            tracing::info!(version = i + 1, "applied schema migration");
        }
        Ok(())
    }

    fn with<T>(&self, f: impl FnOnce(&mut Connection) -> rusqlite::Result<T>) -> Result<T> {
        let mut conn = self
            .conn
            .lock()
            .map_err(|_| StoreError("lock poisoned".into()))?;
        f(&mut conn).map_err(db_err)
    }

    /// Running jobs (the one `id`, or all where `id` is None) asked to stop become
    /// cancelled; the count of them.
    fn cancel_asked(
        tx: &rusqlite::Transaction,
        id: Option<&str>,
        finished_at: &str,
    ) -> rusqlite::Result<usize> {
        tx.execute(
            "UPDATE jobs SET status = 'cancelled', finished_at = ?1
             WHERE status = 'running' AND cancel_requested = 1 AND (?2 IS NULL OR id = ?2)",
            params![finished_at, id],
        )
    }

    /// The running job `id` back to the queue, or to cancelled where a cancel was
    /// asked for.
    fn requeue_running(&self, id: &str) -> Result<()> {
        let finished_at = super::now_rfc3339();
        self.with(|c| {
            let tx = c.transaction()?;
            Self::cancel_asked(&tx, Some(id), &finished_at)?;
            tx.execute(
                "UPDATE jobs SET status = 'queued', started_at = NULL
                 WHERE status = 'running' AND id = ?1",
                params![id],
            )?;
            tx.commit()
        })
    }

    /// The schema version of the open database.
    pub fn schema_version(&self) -> Result<usize> {
        self.with(|c| c.query_row("PRAGMA user_version", [], |r| r.get::<_, i64>(0)))
            .map(|v| v.max(0) as usize)
    }
}

impl Store for SqliteStore {
    fn insert_model(&self, m: &ModelRecord) -> Result<()> {
        self.with(|c| {
            c.execute(
                "INSERT INTO models (id, name, created_at, model_json) VALUES (?1, ?2, ?3, ?4)",
                params![m.id, m.name, m.created_at, m.model_json],
            )
            .map(|_| ())
        })
    }

    fn get_model(&self, id: &str) -> Result<Option<ModelRecord>> {
        self.with(|c| {
            c.query_row(
                "SELECT id, name, created_at, model_json FROM models WHERE id = ?1",
                [id],
                |r| {
                    Ok(ModelRecord {
                        id: r.get(0)?,
                        name: r.get(1)?,
                        created_at: r.get(2)?,
                        model_json: r.get(3)?,
                    })
                },
            )
            .optional()
        })
    }

    fn list_models(&self, cursor: Option<&str>, limit: usize) -> Result<Page<ModelSummary>> {
        let mut items = self.with(|c| {
            let mut st = c.prepare_cached(
                "SELECT id, name, created_at FROM models WHERE (?1 IS NULL OR id < ?1)
                 ORDER BY id DESC LIMIT ?2",
            )?;
            st.query_map(params![cursor, limit as i64 + 1], |r| {
                Ok(ModelSummary {
                    id: r.get(0)?,
                    name: r.get(1)?,
                    created_at: r.get(2)?,
                })
            })?
            .collect::<rusqlite::Result<Vec<_>>>()
        })?;
        let next_cursor = page_cursor(&mut items, limit, |m| m.id.clone());
        Ok(Page { items, next_cursor })
    }

    fn delete_model(&self, id: &str) -> Result<bool> {
        let deleted = self.with(|c| {
            c.execute("DELETE FROM models WHERE id = ?1", [id])
                .map(|n| n > 0)
        })?;
        if deleted {
            self.reclaim_after_delete();
        }
        Ok(deleted)
    }

    fn insert_job(&self, j: &JobRecord) -> Result<()> {
        self.with(|c| {
            c.execute(
                "INSERT INTO jobs (id, kind, status, progress, request_json, work, created_at,
                                   model_name)
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)",
                params![
                    j.id,
                    j.kind,
                    j.status.as_str(),
                    j.progress,
                    j.request_json,
                    j.work,
                    j.created_at,
                    j.model_name
                ],
            )
            .map(|_| ())
        })
    }

    fn enqueue_job(&self, j: &JobRecord, queue_limit: u64) -> Result<Enqueued> {
        self.with(|c| {
            // IMMEDIATE: the write lock before the count, so another process sharing
            // the file cannot insert between the two either.
            let tx = c.transaction_with_behavior(TransactionBehavior::Immediate)?;
            let queued = tx
                .query_row(
                    "SELECT count(*) FROM jobs WHERE status = 'queued'",
                    [],
                    |r| r.get::<_, i64>(0),
                )?
                .max(0) as u64;
            if queued >= queue_limit {
                return Ok(Enqueued::Full { queued });
            }
            tx.execute(
                "INSERT INTO jobs (id, kind, status, progress, request_json, work, created_at,
                                   model_name)
                 VALUES (?1, ?2, 'queued', ?3, ?4, ?5, ?6, ?7)",
                params![
                    j.id,
                    j.kind,
                    j.progress,
                    j.request_json,
                    j.work,
                    j.created_at,
                    j.model_name
                ],
            )?;
            tx.commit()?;
            Ok(Enqueued::Queued)
        })
    }

    fn get_job(&self, id: &str) -> Result<Option<JobRecord>> {
        self.with(|c| {
            c.query_row(
                &format!("SELECT {JOB_COLUMNS} FROM jobs WHERE id = ?1"),
                [id],
                job_from_row,
            )
            .optional()
        })
    }

    fn list_jobs(
        &self,
        status: Option<JobStatus>,
        cursor: Option<&str>,
        limit: usize,
    ) -> Result<Page<JobRecord>> {
        let mut items = self.with(|c| {
            let columns = JOB_COLUMNS.replace("request_json", "'' AS request_json");
            let mut st = c.prepare_cached(&format!(
                "SELECT {columns} FROM jobs
                 WHERE (?1 IS NULL OR status = ?1) AND (?2 IS NULL OR id < ?2)
                 ORDER BY id DESC LIMIT ?3"
            ))?;
            st.query_map(
                params![status.map(|s| s.as_str()), cursor, limit as i64 + 1],
                job_from_row,
            )?
            .collect::<rusqlite::Result<Vec<_>>>()
        })?;
        let next_cursor = page_cursor(&mut items, limit, |j| j.id.clone());
        Ok(Page { items, next_cursor })
    }

    fn count_jobs(&self, status: JobStatus) -> Result<u64> {
        self.with(|c| {
            c.query_row(
                "SELECT count(*) FROM jobs WHERE status = ?1",
                [status.as_str()],
                |r| r.get::<_, i64>(0),
            )
            .map(|n| n.max(0) as u64)
        })
    }

    fn claim_next(&self, started_at: &str) -> Result<Option<JobRecord>> {
        self.with(|c| {
            c.query_row(
                &format!(
                    "UPDATE jobs SET status = 'running', started_at = ?1,
                        attempts = attempts + 1
                     WHERE id = (SELECT id FROM jobs WHERE status = 'queued'
                                 ORDER BY rowid LIMIT 1)
                     RETURNING {JOB_COLUMNS}"
                ),
                [started_at],
                job_from_row,
            )
            .optional()
        })
    }

    fn set_progress(&self, id: &str, progress: f64) -> Result<()> {
        self.with(|c| {
            c.execute(
                "UPDATE jobs SET progress = max(progress, ?2)
                 WHERE id = ?1 AND status = 'running'",
                params![id, progress],
            )
            .map(|_| ())
        })
    }

    fn finish_job(
        &self,
        id: &str,
        outcome: &Outcome,
        progress: f64,
        finished_at: &str,
    ) -> Result<()> {
        self.with(|c| {
            let tx = c.transaction()?;
            match outcome {
                Outcome::Succeeded {
                    result_json,
                    traces_csv,
                } => {
                    tx.execute(
                        "INSERT OR REPLACE INTO job_results (job_id, result_json, traces_csv)
                         VALUES (?1, ?2, ?3)",
                        params![id, result_json, traces_csv],
                    )?;
                    tx.execute(
                        "UPDATE jobs SET status = 'succeeded', progress = 1, finished_at = ?2
                         WHERE id = ?1",
                        params![id, finished_at],
                    )?;
                }
                Outcome::Failed { error_json } => {
                    tx.execute(
                        "UPDATE jobs SET status = 'failed', finished_at = ?2, error_json = ?3,
                            progress = max(progress, ?4)
                         WHERE id = ?1",
                        params![id, finished_at, error_json, progress],
                    )?;
                }
                Outcome::Cancelled => {
                    tx.execute(
                        "UPDATE jobs SET status = 'cancelled', finished_at = ?2,
                            progress = max(progress, ?3)
                         WHERE id = ?1",
                        params![id, finished_at, progress],
                    )?;
                }
            }
            tx.execute("DELETE FROM job_checkpoints WHERE job_id = ?1", [id])?;
            tx.commit()
        })
    }

    fn keep_checkpoints(&self, id: &str, entries: &[(String, String)]) -> Result<()> {
        self.with(|c| {
            let tx = c.transaction()?;
            {
                let mut insert = tx.prepare(
                    "INSERT OR REPLACE INTO job_checkpoints (job_id, key, value) VALUES (?1, ?2, ?3)",
                )?;
                for (key, value) in entries {
                    insert.execute(params![id, key, value])?;
                }
            }
            tx.commit()
        })
    }

    fn checkpoints(&self, id: &str) -> Result<HashMap<String, String>> {
        self.with(|c| {
            let mut q = c.prepare("SELECT key, value FROM job_checkpoints WHERE job_id = ?1")?;
            let rows = q.query_map([id], |r| Ok((r.get(0)?, r.get(1)?)))?;
            rows.collect()
        })
    }

    fn request_cancel(&self, id: &str) -> Result<bool> {
        self.with(|c| {
            c.execute(
                "UPDATE jobs SET cancel_requested = 1 WHERE id = ?1 AND status = 'running'",
                [id],
            )
            .map(|n| n > 0)
        })
    }

    fn requeue(&self, id: &str) -> Result<()> {
        self.requeue_running(id)
    }

    fn requeue_all_running(&self, give_up: &GiveUp) -> Result<Requeued> {
        let finished_at = super::now_rfc3339();
        self.with(|c| {
            let tx = c.transaction()?;
            // The cancels first: a job asked to stop is cancelled, not blamed.
            let cancelled = Self::cancel_asked(&tx, None, &finished_at)?;
            tx.execute(
                "UPDATE jobs SET interruptions = interruptions + 1 WHERE status = 'running'",
                [],
            )?;
            let failed = tx.execute(
                "UPDATE jobs SET status = 'failed', finished_at = ?1, error_json = ?2
                 WHERE status = 'running' AND interruptions >= ?3",
                params![finished_at, give_up.error_json, give_up.after],
            )?;
            let requeued = tx.execute(
                "UPDATE jobs SET status = 'queued', started_at = NULL WHERE status = 'running'",
                [],
            )?;
            tx.commit()?;
            Ok(Requeued {
                requeued: requeued as u64,
                cancelled: cancelled as u64,
                failed: failed as u64,
            })
        })
    }

    fn cancel_queued(&self, id: &str, finished_at: &str) -> Result<bool> {
        self.with(|c| {
            c.execute(
                "UPDATE jobs SET status = 'cancelled', finished_at = ?2, cancel_requested = 1
                 WHERE id = ?1 AND status = 'queued'",
                params![id, finished_at],
            )
            .map(|n| n > 0)
        })
    }

    fn delete_finished_job(&self, id: &str) -> Result<Deleted> {
        let out = self.with(|c| {
            let tx = c.transaction()?;
            let status: Option<String> = tx
                .query_row("SELECT status FROM jobs WHERE id = ?1", [id], |r| r.get(0))
                .optional()?;
            let out = match status.as_deref().and_then(JobStatus::parse) {
                None => Deleted::NotFound,
                Some(s) if !s.is_terminal() => Deleted::NotFinished(s),
                Some(_) => {
                    // The result and any checkpoints go with it (ON DELETE CASCADE).
                    tx.execute("DELETE FROM jobs WHERE id = ?1", [id])?;
                    Deleted::Deleted
                }
            };
            tx.commit()?;
            Ok(out)
        })?;
        if out == Deleted::Deleted {
            self.reclaim_after_delete();
        }
        Ok(out)
    }

    fn purge_finished_before(&self, cutoff: &str) -> Result<u64> {
        let terminal: Vec<String> = JobStatus::ALL
            .into_iter()
            .filter(|s| s.is_terminal())
            .map(|s| format!("'{}'", s.as_str()))
            .collect();
        // julianday: the stored times have as many fractional digits as they need, so
        // their text does not sort as their times do.
        let sql = format!(
            "DELETE FROM jobs WHERE status IN ({}) AND finished_at IS NOT NULL
             AND julianday(finished_at) < julianday(?1)",
            terminal.join(", ")
        );
        let deleted = self.with(|c| c.execute(&sql, [cutoff]).map(|n| n as u64))?;
        if deleted > 0 {
            self.reclaim_after_delete();
        }
        Ok(deleted)
    }

    fn reclaim_free_space(&self) -> Result<u64> {
        let mut given_back = 0;
        // One step per lock: requests go on between the steps.
        loop {
            let step = self.with(reclaim_step)?;
            given_back += step.bytes;
            if !step.more {
                return Ok(given_back);
            }
        }
    }

    fn get_result(&self, id: &str) -> Result<Option<(String, Option<String>)>> {
        self.with(|c| {
            c.query_row(
                "SELECT result_json, traces_csv FROM job_results WHERE job_id = ?1",
                [id],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()
        })
    }
}

/// The database file's size as SQLite sees it (`page_count` × `page_size`; the `-wal`
/// not counted).
fn file_bytes(c: &Connection) -> rusqlite::Result<i64> {
    c.query_row(
        "SELECT page_count * page_size FROM pragma_page_count(), pragma_page_size()",
        [],
        |r| r.get(0),
    )
}

/// Copy the `-wal` into the database file and truncate it: only then is the database
/// file cut to its new size, and the `-wal` back to nothing. Busy (not done) is not an
/// error: the next checkpoint does it.
fn checkpoint(c: &Connection) -> rusqlite::Result<()> {
    let busy: i64 = c.query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |r| r.get(0))?;
    if busy != 0 {
        tracing::debug!("the store's checkpoint was busy; the next one finishes it");
    }
    Ok(())
}

/// What one [`reclaim_step`] did.
struct ReclaimStep {
    /// How much smaller the database file is.
    bytes: u64,
    /// Free pages are left (more than one step's worth were free).
    more: bool,
}

/// Give up to [`RECLAIM_STEP_BYTES`] of free pages back to the file system: one
/// `incremental_vacuum` (its own transaction), then a checkpoint so that the file
/// shrinks now. With no free page it costs one read of the header.
fn reclaim_step(c: &mut Connection) -> rusqlite::Result<ReclaimStep> {
    let (free, page_size): (i64, i64) = c.query_row(
        "SELECT freelist_count, page_size FROM pragma_freelist_count(), pragma_page_size()",
        [],
        |r| Ok((r.get(0)?, r.get(1)?)),
    )?;
    let step = (RECLAIM_STEP_BYTES / page_size.max(1)).max(1);
    if free == 0 {
        return Ok(ReclaimStep {
            bytes: 0,
            more: false,
        });
    }
    let before = file_bytes(c)?;
    {
        // One result row per page freed, and each step of the statement frees one: it
        // must be stepped to its end (`execute_batch` would free a single page).
        let mut vacuum = c.prepare(&format!("PRAGMA incremental_vacuum({})", free.min(step)))?;
        let mut rows = vacuum.query([])?;
        while rows.next()?.is_some() {}
    }
    let after = file_bytes(c)?;
    if after < before {
        checkpoint(c)?;
    }
    Ok(ReclaimStep {
        bytes: (before - after).max(0) as u64,
        // Not in incremental mode, nothing moves: no point in going on.
        more: free > step && after < before,
    })
}

/// Trim a `limit + 1` query to `limit` items; the cursor is set when more exist.
fn page_cursor<T>(items: &mut Vec<T>, limit: usize, id: impl Fn(&T) -> String) -> Option<String> {
    if items.len() > limit {
        items.truncate(limit);
        items.last().map(id)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::serve::store::{new_id, now_rfc3339};

    fn job(id: &str) -> JobRecord {
        JobRecord {
            id: id.into(),
            kind: "analysis".into(),
            status: JobStatus::Queued,
            progress: 0.0,
            request_json: "{}".into(),
            work: 1.0,
            created_at: now_rfc3339(),
            started_at: None,
            finished_at: None,
            error_json: None,
            attempts: 0,
            cancel_requested: false,
            model_name: None,
        }
    }

    fn give_up() -> GiveUp {
        GiveUp {
            after: 3,
            error_json: "{\"type\":\"x\"}".into(),
        }
    }

    fn counts(requeued: u64, cancelled: u64, failed: u64) -> Requeued {
        Requeued {
            requeued,
            cancelled,
            failed,
        }
    }

    /// The store's bytes on disk: the database file and its `-wal`.
    fn on_disk(dir: &Path) -> u64 {
        ["kea.sqlite", "kea.sqlite-wal"]
            .iter()
            .map(|f| std::fs::metadata(dir.join(f)).map_or(0, |m| m.len()))
            .sum()
    }

    /// A request of about 1 MB (SQLite stores text as it is: no compression to defeat).
    fn big_request(i: usize) -> String {
        format!(
            "{{\"pad\":\"{}\"}}",
            char::from(b'a' + (i % 26) as u8)
                .to_string()
                .repeat(1 << 20)
        )
    }

    /// A finished job with a ~1 MB request and a result, finished at `finished_at`.
    fn insert_finished(s: &SqliteStore, i: usize, finished_at: &str) -> String {
        let id = new_id();
        s.insert_job(&JobRecord {
            status: JobStatus::Succeeded,
            request_json: big_request(i),
            ..job(&id)
        })
        .unwrap();
        s.with(|c| {
            c.execute(
                "UPDATE jobs SET finished_at = ?2 WHERE id = ?1",
                params![id, finished_at],
            )?;
            c.execute(
                "INSERT INTO job_results (job_id, result_json) VALUES (?1, '{}')",
                [&id],
            )
        })
        .unwrap();
        id
    }

    fn auto_vacuum(s: &SqliteStore) -> i64 {
        s.with(|c| c.query_row("PRAGMA auto_vacuum", [], |r| r.get(0)))
            .unwrap()
    }

    /// Retention's batch (`purge_finished_before`, then `reclaim_free_space`) gives the
    /// space back: the file and its `-wal` end far below their peak, and the jobs kept
    /// (one at the file's end, whose pages move into the holes) are intact.
    #[test]
    fn purged_jobs_give_their_space_back_to_the_file_system() {
        let dir = tempfile::tempdir().unwrap();
        let s = SqliteStore::open(dir.path()).unwrap();
        assert_eq!(auto_vacuum(&s), AUTO_VACUUM_INCREMENTAL);
        let first = insert_finished(&s, 0, "2026-01-02T00:00:00Z");
        for i in 1..=30 {
            insert_finished(&s, i, "2026-01-01T00:00:00Z");
        }
        let last = new_id();
        s.insert_job(&JobRecord {
            request_json: big_request(31),
            ..job(&last)
        })
        .unwrap();
        let peak = on_disk(dir.path());
        assert!(peak > 30 << 20, "{peak}");
        assert_eq!(s.purge_finished_before("2026-01-01T12:00:00Z").unwrap(), 30);
        s.reclaim_free_space().unwrap();
        let after = on_disk(dir.path());
        assert!(
            after * 4 < peak,
            "{after} bytes on disk after the purge, {peak} at the peak"
        );
        assert_eq!(
            s.get_job(&first).unwrap().unwrap().request_json,
            big_request(0)
        );
        assert_eq!(
            s.get_job(&last).unwrap().unwrap().request_json,
            big_request(31)
        );
        assert!(s.get_result(&first).unwrap().is_some());
        let check: String = s
            .with(|c| c.query_row("PRAGMA integrity_check", [], |r| r.get(0)))
            .unwrap();
        assert_eq!(check, "ok");
    }

    /// A delete on its own (`DELETE /v1/jobs/{id}?purge=true`, `DELETE /v1/models/{id}`)
    /// gives its space back at once, with no sweep.
    #[test]
    fn a_deleted_job_or_model_gives_its_space_back_at_once() {
        let dir = tempfile::tempdir().unwrap();
        let s = SqliteStore::open(dir.path()).unwrap();
        let jobs: Vec<String> = (0..20)
            .map(|i| insert_finished(&s, i, "2026-01-01T00:00:00Z"))
            .collect();
        let models: Vec<String> = (0..10)
            .map(|i| {
                let id = new_id();
                s.insert_model(&ModelRecord {
                    id: id.clone(),
                    name: None,
                    created_at: now_rfc3339(),
                    model_json: big_request(i),
                })
                .unwrap();
                id
            })
            .collect();
        let kept = insert_finished(&s, 20, "2026-01-01T00:00:00Z");
        let peak = on_disk(dir.path());
        assert!(peak > 30 << 20, "{peak}");
        for id in &jobs {
            assert_eq!(s.delete_finished_job(id).unwrap(), Deleted::Deleted);
        }
        for id in &models {
            assert!(s.delete_model(id).unwrap());
        }
        let after = on_disk(dir.path());
        assert!(
            after * 4 < peak,
            "{after} bytes on disk after the deletes, {peak} at the peak"
        );
        assert_eq!(
            s.get_job(&kept).unwrap().unwrap().request_json,
            big_request(20)
        );
    }

    /// A data directory of a kea before auto-vacuum (the schema of today, `auto_vacuum`
    /// none, free pages left by deletes) is switched on open, keeps its data and the
    /// queue's order, and from then on gives deleted space back.
    #[test]
    fn a_store_without_auto_vacuum_is_switched_on_open_and_keeps_its_data() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b, done, gone) = (new_id(), new_id(), new_id(), new_id());
        let model = new_id();
        {
            // What the store's open did before: WAL, the migrations, no auto_vacuum.
            let mut c = Connection::open(dir.path().join("kea.sqlite")).unwrap();
            c.execute_batch("PRAGMA journal_mode = WAL; PRAGMA foreign_keys = ON;")
                .unwrap();
            let tx = c.transaction().unwrap();
            for sql in MIGRATIONS {
                tx.execute_batch(sql).unwrap();
            }
            tx.pragma_update(None, "user_version", MIGRATIONS.len() as i64)
                .unwrap();
            tx.commit().unwrap();
            let insert = |id: &str, status: &str, i: usize| {
                c.execute(
                    "INSERT INTO jobs (id, kind, status, request_json, work, created_at)
                     VALUES (?1, 'analysis', ?2, ?3, 1, '2026-01-01T00:00:00Z')",
                    params![id, status, big_request(i)],
                )
                .unwrap();
            };
            insert(&gone, "succeeded", 0);
            insert(&a, "queued", 1);
            insert(&done, "succeeded", 2);
            insert(&b, "queued", 3);
            c.execute(
                "INSERT INTO job_results (job_id, result_json, traces_csv)
                 VALUES (?1, '{\"x\":1}', 't\n0\n')",
                [&done],
            )
            .unwrap();
            c.execute(
                "INSERT INTO models (id, name, created_at, model_json)
                 VALUES (?1, 'm', '2026-01-01T00:00:00Z', '{}')",
                [&model],
            )
            .unwrap();
            c.execute("DELETE FROM jobs WHERE id = ?1", [&gone])
                .unwrap();
            let (mode, free): (i64, i64) = c
                .query_row(
                    "SELECT auto_vacuum, freelist_count
                     FROM pragma_auto_vacuum(), pragma_freelist_count()",
                    [],
                    |r| Ok((r.get(0)?, r.get(1)?)),
                )
                .unwrap();
            assert_eq!(mode, 0);
            assert!(free > 200, "{free}");
        }
        let before = on_disk(dir.path());
        let s = SqliteStore::open(dir.path()).unwrap();
        assert_eq!(auto_vacuum(&s), AUTO_VACUUM_INCREMENTAL);
        assert_eq!(s.schema_version().unwrap(), MIGRATIONS.len());
        let after = on_disk(dir.path());
        assert!(
            after + (1 << 20) / 2 < before,
            "the free pages went with the VACUUM: {before} -> {after} bytes"
        );
        assert!(s.get_job(&gone).unwrap().is_none());
        assert_eq!(s.get_job(&a).unwrap().unwrap().request_json, big_request(1));
        assert_eq!(
            s.get_result(&done).unwrap(),
            Some(("{\"x\":1}".into(), Some("t\n0\n".into())))
        );
        assert_eq!(
            s.get_model(&model).unwrap().unwrap().name.as_deref(),
            Some("m")
        );
        assert_eq!(s.claim_next(&now_rfc3339()).unwrap().unwrap().id, a);
        assert_eq!(s.claim_next(&now_rfc3339()).unwrap().unwrap().id, b);
        // From now on a delete gives its space back.
        let with_done = on_disk(dir.path());
        assert_eq!(s.delete_finished_job(&done).unwrap(), Deleted::Deleted);
        assert!(on_disk(dir.path()) + (1 << 20) / 2 < with_done);
        drop(s);
        // Switched once: a second open finds it done.
        let s = SqliteStore::open(dir.path()).unwrap();
        assert_eq!(auto_vacuum(&s), AUTO_VACUUM_INCREMENTAL);
        assert_eq!(s.get_job(&b).unwrap().unwrap().status, JobStatus::Running);
    }

    /// A job that every process dies running (it brings the server down) fails at its
    /// third interruption; a graceful shutdown's re-queue is not one, and a job
    /// interrupted fewer times runs again.
    #[test]
    fn a_job_interrupted_three_times_fails_instead_of_running_again() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (new_id(), new_id());
        let claim = |s: &SqliteStore, want: &str| {
            assert_eq!(s.claim_next(&now_rfc3339()).unwrap().unwrap().id, want);
        };
        // Each block is one process; it ends ("dies") with the jobs it claimed running.
        {
            let s = SqliteStore::open(dir.path()).unwrap();
            s.insert_job(&job(&a)).unwrap();
            s.insert_job(&job(&b)).unwrap();
            for _ in 0..5 {
                claim(&s, &a);
                s.requeue(&a).unwrap(); // a shutdown: not counted
            }
            claim(&s, &a);
        }
        {
            let s = SqliteStore::open(dir.path()).unwrap();
            assert_eq!(s.requeue_all_running(&give_up()).unwrap(), counts(1, 0, 0));
            claim(&s, &a);
        }
        {
            let s = SqliteStore::open(dir.path()).unwrap();
            assert_eq!(s.requeue_all_running(&give_up()).unwrap(), counts(1, 0, 0));
            claim(&s, &a);
            claim(&s, &b);
        }
        let s = SqliteStore::open(dir.path()).unwrap();
        assert_eq!(s.requeue_all_running(&give_up()).unwrap(), counts(1, 0, 1));
        let failed = s.get_job(&a).unwrap().unwrap();
        assert_eq!(failed.status, JobStatus::Failed);
        assert_eq!(
            failed.error_json.as_deref(),
            Some(give_up().error_json.as_str())
        );
        assert!(failed.finished_at.is_some());
        assert_eq!(s.get_job(&b).unwrap().unwrap().status, JobStatus::Queued);
        claim(&s, &b);
        assert!(s.claim_next(&now_rfc3339()).unwrap().is_none());
    }

    /// Only a finished job is deleted, and its result and checkpoints with it.
    #[test]
    fn a_finished_job_is_deleted_with_its_result() {
        let dir = tempfile::tempdir().unwrap();
        let s = SqliteStore::open(dir.path()).unwrap();
        let (a, b) = (new_id(), new_id());
        s.insert_job(&job(&a)).unwrap();
        s.insert_job(&job(&b)).unwrap();
        assert_eq!(
            s.delete_finished_job(&a).unwrap(),
            Deleted::NotFinished(JobStatus::Queued)
        );
        s.claim_next(&now_rfc3339()).unwrap().unwrap();
        s.keep_checkpoints(&a, &[("k".into(), "v".into())]).unwrap();
        assert_eq!(
            s.delete_finished_job(&a).unwrap(),
            Deleted::NotFinished(JobStatus::Running)
        );
        let result = Outcome::Succeeded {
            result_json: "{}".into(),
            traces_csv: None,
        };
        s.finish_job(&a, &result, 1.0, &now_rfc3339()).unwrap();
        assert!(s.get_result(&a).unwrap().is_some());
        assert_eq!(s.delete_finished_job(&a).unwrap(), Deleted::Deleted);
        assert!(s.get_job(&a).unwrap().is_none());
        assert!(s.get_result(&a).unwrap().is_none());
        let left: i64 = s
            .with(|c| {
                c.query_row(
                    "SELECT (SELECT count(*) FROM job_results) + (SELECT count(*) FROM job_checkpoints)",
                    [],
                    |r| r.get(0),
                )
            })
            .unwrap();
        assert_eq!(left, 0);
        assert_eq!(s.delete_finished_job(&a).unwrap(), Deleted::NotFound);
        assert_eq!(s.get_job(&b).unwrap().unwrap().status, JobStatus::Queued);
    }

    #[test]
    fn jobs_are_claimed_in_order_and_survive_reopen() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (new_id(), new_id());
        {
            let s = SqliteStore::open(dir.path()).unwrap();
            assert_eq!(s.schema_version().unwrap(), MIGRATIONS.len());
            s.insert_job(&job(&a)).unwrap();
            s.insert_job(&job(&b)).unwrap();
            let claimed = s.claim_next(&now_rfc3339()).unwrap().unwrap();
            assert_eq!(claimed.id, a);
            assert_eq!(claimed.status, JobStatus::Running);
            assert_eq!(claimed.attempts, 1);
        }
        // Reopen: the running job is re-queued ahead of the other.
        let s = SqliteStore::open(dir.path()).unwrap();
        assert_eq!(s.requeue_all_running(&give_up()).unwrap(), counts(1, 0, 0));
        assert_eq!(s.count_jobs(JobStatus::Queued).unwrap(), 2);
        let again = s.claim_next(&now_rfc3339()).unwrap().unwrap();
        assert_eq!((again.id.as_str(), again.attempts), (a.as_str(), 2));
        s.finish_job(
            &a,
            &Outcome::Succeeded {
                result_json: "{\"x\":1}".into(),
                traces_csv: Some("t\n0\n".into()),
            },
            1.0,
            &now_rfc3339(),
        )
        .unwrap();
        assert_eq!(s.get_job(&a).unwrap().unwrap().status, JobStatus::Succeeded);
        assert_eq!(
            s.get_result(&a).unwrap(),
            Some(("{\"x\":1}".into(), Some("t\n0\n".into())))
        );
        assert!(s.cancel_queued(&b, &now_rfc3339()).unwrap());
        assert!(!s.cancel_queued(&b, &now_rfc3339()).unwrap());
        assert!(s.claim_next(&now_rfc3339()).unwrap().is_none());
    }

    #[test]
    fn a_cancel_asked_for_while_running_survives_the_process() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b, c) = (new_id(), new_id(), new_id());
        {
            let s = SqliteStore::open(dir.path()).unwrap();
            for id in [&a, &b, &c] {
                s.insert_job(&job(id)).unwrap();
            }
            assert!(
                !s.request_cancel(&a).unwrap(),
                "a queued job is not running"
            );
            for _ in 0..3 {
                s.claim_next(&now_rfc3339()).unwrap().unwrap();
            }
            assert!(s.request_cancel(&a).unwrap());
            assert!(s.request_cancel(&c).unwrap());
            // Shutdown interrupts c: cancelled, not re-queued.
            s.requeue(&c).unwrap();
            let c_now = s.get_job(&c).unwrap().unwrap();
            assert_eq!(c_now.status, JobStatus::Cancelled);
            assert!(c_now.finished_at.is_some());
        }
        // The process died with a and b running: a was asked to cancel, b runs again.
        let s = SqliteStore::open(dir.path()).unwrap();
        assert_eq!(s.requeue_all_running(&give_up()).unwrap(), counts(1, 1, 0));
        assert_eq!(s.get_job(&a).unwrap().unwrap().status, JobStatus::Cancelled);
        assert_eq!(s.get_job(&b).unwrap().unwrap().status, JobStatus::Queued);
        assert_eq!(s.claim_next(&now_rfc3339()).unwrap().unwrap().id, b);
        assert!(s.claim_next(&now_rfc3339()).unwrap().is_none());
    }

    #[test]
    fn progress_never_decreases_and_a_cancel_request_is_kept() {
        let dir = tempfile::tempdir().unwrap();
        let s = SqliteStore::open(dir.path()).unwrap();
        let (a, b) = (new_id(), new_id());
        s.insert_job(&job(&a)).unwrap();
        s.insert_job(&job(&b)).unwrap();
        let progress = |id: &str| s.get_job(id).unwrap().unwrap().progress;
        s.claim_next(&now_rfc3339()).unwrap().unwrap();
        s.set_progress(&a, 0.5).unwrap();
        s.set_progress(&a, 0.3).unwrap();
        assert_eq!(progress(&a), 0.5);
        // Re-queued and run again: it keeps what it had reached.
        s.requeue(&a).unwrap();
        assert_eq!(progress(&a), 0.5);
        let again = s.claim_next(&now_rfc3339()).unwrap().unwrap();
        assert_eq!((again.id.as_str(), again.progress), (a.as_str(), 0.5));
        assert!(!again.cancel_requested);
        assert!(s.request_cancel(&a).unwrap());
        assert!(s.get_job(&a).unwrap().unwrap().cancel_requested);
        s.finish_job(&a, &Outcome::Cancelled, 0.4, &now_rfc3339())
            .unwrap();
        assert_eq!(progress(&a), 0.5);
        let done = s.get_job(&a).unwrap().unwrap();
        assert_eq!(done.status, JobStatus::Cancelled);
        assert!(done.cancel_requested);
        // A queued job cancelled at once records the request too.
        assert!(s.cancel_queued(&b, &now_rfc3339()).unwrap());
        assert!(s.get_job(&b).unwrap().unwrap().cancel_requested);
    }

    /// A job's checkpoints are kept in batches, read back whole, replaced by key, and
    /// dropped when the job ends.
    #[test]
    fn checkpoints_are_kept_until_the_job_ends() {
        let dir = tempfile::tempdir().unwrap();
        let s = SqliteStore::open(dir.path()).unwrap();
        let id = new_id();
        s.insert_job(&JobRecord {
            status: JobStatus::Running,
            ..job(&id)
        })
        .unwrap();
        let kv = |k: &str, v: &str| (k.to_string(), v.to_string());
        s.keep_checkpoints(&id, &[kv("a", "1"), kv("b", "2")])
            .unwrap();
        s.keep_checkpoints(&id, &[kv("b", "3")]).unwrap();
        let kept = s.checkpoints(&id).unwrap();
        assert_eq!(kept.len(), 2);
        assert_eq!((kept["a"].as_str(), kept["b"].as_str()), ("1", "3"));
        assert!(s.checkpoints(&new_id()).unwrap().is_empty());
        s.finish_job(&id, &Outcome::Cancelled, 0.5, &now_rfc3339())
            .unwrap();
        assert!(s.checkpoints(&id).unwrap().is_empty());
    }

    #[test]
    fn a_version_1_data_directory_is_migrated() {
        let dir = tempfile::tempdir().unwrap();
        let id = new_id();
        {
            // What a kea of schema version 1 left: its tables and a running job.
            let c = Connection::open(dir.path().join("kea.sqlite")).unwrap();
            c.execute_batch(MIGRATIONS[0]).unwrap();
            c.pragma_update(None, "user_version", 1).unwrap();
            c.execute(
                "INSERT INTO jobs (id, kind, status, request_json, work, created_at, attempts)
                 VALUES (?1, 'analysis', 'running', '{}', 1, '2026-01-01T00:00:00Z', 1)",
                [&id],
            )
            .unwrap();
        }
        // Finished jobs of every shape of request: migration 5 reads their model's name.
        let named = [
            (
                r#"{"model":{"name":"Tracker \"A\"","time":{}}}"#,
                Some("Tracker \"A\""),
            ),
            (r#"{"model":{"time":{}}}"#, None),
            (r#"{"model":{"name":7}}"#, None),
            ("{}", None),
            ("not json", None),
        ];
        let named: Vec<(String, Option<&str>)> = named
            .into_iter()
            .map(|(request, name)| {
                let id = new_id();
                let c = Connection::open(dir.path().join("kea.sqlite")).unwrap();
                c.execute(
                    "INSERT INTO jobs (id, kind, status, request_json, work, created_at)
                     VALUES (?1, 'analysis', 'succeeded', ?2, 1, '2026-01-01T00:00:00Z')",
                    params![id, request],
                )
                .unwrap();
                (id, name)
            })
            .collect();
        let s = SqliteStore::open(dir.path()).unwrap();
        assert_eq!(s.schema_version().unwrap(), MIGRATIONS.len());
        for (id, name) in &named {
            let job = s.get_job(id).unwrap().unwrap();
            assert_eq!(job.model_name.as_deref(), *name, "{}", job.request_json);
        }
        assert_eq!(s.get_job(&id).unwrap().unwrap().status, JobStatus::Running);
        assert!(s.request_cancel(&id).unwrap());
        assert_eq!(s.requeue_all_running(&give_up()).unwrap(), counts(0, 1, 0));
        assert_eq!(
            s.get_job(&id).unwrap().unwrap().status,
            JobStatus::Cancelled
        );
    }

    /// Retention deletes the finished jobs that finished before the cutoff, by time
    /// (not by the text, whose fractional digits vary), with their results; never a
    /// queued or running job.
    #[test]
    fn finished_jobs_before_the_cutoff_are_deleted() {
        let dir = tempfile::tempdir().unwrap();
        let s = SqliteStore::open(dir.path()).unwrap();
        let cases = [
            (JobStatus::Succeeded, Some("2026-01-01T00:00:00Z"), true),
            (JobStatus::Failed, Some("2026-01-01T00:00:00.5Z"), true),
            (JobStatus::Cancelled, Some("2026-01-01T00:00:00.9Z"), false),
            (JobStatus::Succeeded, Some("2026-01-01T00:00:01Z"), false),
            (JobStatus::Running, None, false),
            (JobStatus::Queued, None, false),
        ];
        let ids: Vec<String> = cases
            .iter()
            .map(|(status, finished, _)| {
                let id = new_id();
                s.insert_job(&JobRecord {
                    status: *status,
                    ..job(&id)
                })
                .unwrap();
                s.with(|c| {
                    c.execute(
                        "UPDATE jobs SET finished_at = ?2 WHERE id = ?1",
                        params![id, finished],
                    )?;
                    c.execute(
                        "INSERT INTO job_results (job_id, result_json) VALUES (?1, '{}')",
                        [&id],
                    )
                })
                .unwrap();
                id
            })
            .collect();
        assert_eq!(
            s.purge_finished_before("2026-01-01T00:00:00.75Z").unwrap(),
            2
        );
        for ((_, _, gone), id) in cases.iter().zip(&ids) {
            assert_eq!(s.get_job(id).unwrap().is_none(), *gone, "{id}");
            assert_eq!(s.get_result(id).unwrap().is_none(), *gone, "{id}");
        }
        assert_eq!(
            s.purge_finished_before("2026-01-01T00:00:00.75Z").unwrap(),
            0
        );
    }

    /// A listing names each job's model but does not read its request.
    #[test]
    fn a_listing_reads_no_requests() {
        let dir = tempfile::tempdir().unwrap();
        let s = SqliteStore::open(dir.path()).unwrap();
        let id = new_id();
        s.insert_job(&JobRecord {
            request_json: r#"{"model":{"name":"m"}}"#.into(),
            model_name: Some("m".into()),
            ..job(&id)
        })
        .unwrap();
        let page = s.list_jobs(None, None, 10).unwrap();
        assert_eq!(page.items.len(), 1);
        assert_eq!(page.items[0].id, id);
        assert_eq!(page.items[0].model_name.as_deref(), Some("m"));
        assert_eq!(page.items[0].request_json, "");
        let got = s.get_job(&id).unwrap().unwrap();
        assert_eq!(got.request_json, r#"{"model":{"name":"m"}}"#);
    }

    #[test]
    fn listing_pages_newest_first() {
        let dir = tempfile::tempdir().unwrap();
        let s = SqliteStore::open(dir.path()).unwrap();
        let ids: Vec<String> = (0..5).map(|_| new_id()).collect();
        for id in &ids {
            s.insert_model(&ModelRecord {
                id: id.clone(),
                name: None,
                created_at: now_rfc3339(),
                model_json: "{}".into(),
            })
            .unwrap();
        }
        let p1 = s.list_models(None, 2).unwrap();
        assert_eq!(
            p1.items.iter().map(|m| &m.id).collect::<Vec<_>>(),
            vec![&ids[4], &ids[3]]
        );
        let p2 = s.list_models(p1.next_cursor.as_deref(), 2).unwrap();
        let p3 = s.list_models(p2.next_cursor.as_deref(), 2).unwrap();
        assert_eq!(p3.items.len(), 1);
        assert_eq!(p3.items[0].id, ids[0]);
        assert_eq!(p3.next_cursor, None);
        assert!(s.delete_model(&ids[0]).unwrap());
        assert!(!s.delete_model(&ids[0]).unwrap());
    }
}
