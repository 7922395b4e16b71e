//! `kea serve`: the HTTP service (axum + tokio) with a persistent job queue.
//!
//! Map: [`routes`] is the route table and [`routes::app`]; [`handlers`] and
//! [`jobs_api`] answer requests; [`jobs`] holds the job kinds; [`worker`] runs them on
//! dedicated threads; [`store`] persists models, jobs and results; [`request`] and
//! [`problem`] read requests and write RFC 9457 errors.

pub mod auth;
pub mod handlers;
pub mod jobs;
pub mod jobs_api;
pub mod problem;
pub mod request;
pub mod retention;
pub mod routes;
pub mod state;
pub mod store;
pub mod worker;

use crate::Run;
use state::{AppState, Config, Limits};
use std::io::Write;
use std::net::{SocketAddr, ToSocketAddrs};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::{Semaphore, watch};

#[derive(Debug, Clone, clap::Args)]
#[command(about = "Run the HTTP service: API, job queue and web UI")]
pub struct Args {
    /// Address to listen on. Binding beyond loopback needs --token (or --allow-no-token).
    #[arg(long, env = "KEA_ADDR", default_value = "127.0.0.1:8080")]
    pub addr: String,
    /// Directory for the database (created if missing).
    #[arg(long, env = "KEA_DATA_DIR", default_value = "kea-data")]
    pub data_dir: PathBuf,
    /// Bearer token protecting /v1 (prefer the environment variable over the flag).
    #[arg(long, env = "KEA_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Allow binding to a non-loopback address without a token (anyone can use it).
    #[arg(long, env = "KEA_ALLOW_NO_TOKEN")]
    pub allow_no_token: bool,
    /// Without a token, /v1 answers only requests addressed to this machine (Host
    /// localhost, 127.x.x.x or [::1]); a further name it may be called by, e.g. behind a
    /// reverse proxy that keeps the Host (repeatable, or comma-separated).
    #[arg(
        long = "allowed-host",
        env = "KEA_ALLOWED_HOSTS",
        value_delimiter = ','
    )]
    pub allowed_hosts: Vec<String>,
    /// The static web UI [default: ./web, else the source tree's web/].
    #[arg(long, env = "KEA_WEB_DIR")]
    pub web_dir: Option<PathBuf>,
    /// Allowed CORS origin (repeatable, or comma-separated); CORS is off without one.
    #[arg(long = "cors-origin", env = "KEA_CORS_ORIGINS", value_delimiter = ',')]
    pub cors_origins: Vec<String>,
    /// Worker threads for jobs [default or 0: one per core; at most 256].
    #[arg(long, env = "KEA_WORKERS", value_parser = crate::cli::parse_threads)]
    pub workers: Option<usize>,
    /// Largest request body, bytes [default 8 MiB: an identification's data of 10⁵ rows,
    /// t and two measurements at 17 digits, as CSV or inline rows].
    #[arg(long, env = "KEA_MAX_BODY_BYTES", default_value_t = 8 * 1024 * 1024,
          value_parser = at_least_one::<usize>)]
    pub max_body_bytes: usize,
    /// Seconds a request's line and headers may take to arrive (then the connection is
    /// closed), and then its body, whole (then 408): 8 MiB at 300 kB/s is 28 s.
    #[arg(long, env = "KEA_READ_TIMEOUT", default_value_t = 30, value_parser = at_least_one::<u64>)]
    pub read_timeout: u64,
    /// Largest estimated work (about 1 ns of one core a unit; openapi.yaml, "Work") that
    /// POST /v1/analyze answers synchronously: ≈ half a second.
    #[arg(long, env = "KEA_SYNC_WORK_LIMIT", default_value_t = 5e8,
          value_parser = crate::cli::parse_limit)]
    pub sync_work_limit: f64,
    /// Largest work accepted at all; above it a request is refused.
    #[arg(long, env = "KEA_MAX_WORK", default_value_t = 1e12, value_parser = crate::cli::parse_limit)]
    pub max_work: f64,
    /// Wall-clock limit of one job, seconds.
    #[arg(long, env = "KEA_JOB_TIME_LIMIT", default_value_t = 3600, value_parser = at_least_one::<u64>)]
    pub job_time_limit: u64,
    /// Most queued jobs; further submissions get 429.
    #[arg(long, env = "KEA_QUEUE_LIMIT", default_value_t = 10_000, value_parser = at_least_one::<u64>)]
    pub queue_limit: u64,
    /// On shutdown, seconds running jobs may take to finish before being re-queued.
    #[arg(long, env = "KEA_SHUTDOWN_GRACE", default_value_t = 10)]
    pub shutdown_grace: u64,
    /// Delete a finished job, with its result, this many seconds after it finished
    /// (2592000: 30 days) [default: kept until deleted with DELETE ?purge=true].
    #[arg(long, env = "KEA_KEEP_FINISHED", value_parser = at_least_one::<u64>)]
    pub keep_finished: Option<u64>,
    /// Seconds between the states an analysis or Monte Carlo job keeps as it runs: a
    /// restart (a crash, a shutdown) goes on from the last one, so it loses at most
    /// this much of the job's work.
    #[arg(long, env = "KEA_STATE_EVERY", default_value_t = 10, value_parser = at_least_one::<u64>)]
    pub state_every: u64,
    /// Log format: text or json (level via KEA_LOG, e.g. `info`, `debug`).
    #[arg(long, env = "KEA_LOG_FORMAT", default_value = "text", value_parser = ["text", "json"])]
    pub log_format: String,
}

impl Run for Args {
    fn run(self) -> ExitCode {
        init_logging(&self.log_format);
        match serve(self) {
            Ok(()) => ExitCode::SUCCESS,
            Err((code, msg)) => {
                eprintln!("kea serve: {msg}");
                ExitCode::from(code)
            }
        }
    }
}

/// A count or a number of seconds that must be at least 1: 0 would make the server
/// refuse (or time out) every request it exists to serve.
fn at_least_one<T: std::str::FromStr + PartialOrd + From<u8>>(arg: &str) -> Result<T, String> {
    match arg.trim().parse::<T>() {
        Ok(x) if x >= T::from(1) => Ok(x),
        _ => Err(format!(
            "expected a whole number of at least 1, got `{arg}`"
        )),
    }
}

fn init_logging(format: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_env("KEA_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()));
    let _ = if format == "json" {
        builder.json().try_init()
    } else {
        builder.try_init()
    };
}

/// The web UI directory: the flag, else `./web`, else the source tree's `web/`.
fn web_dir(flag: Option<PathBuf>) -> Option<PathBuf> {
    if flag.is_some() {
        return flag;
    }
    let candidates = [
        PathBuf::from("web"),
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../web")),
    ];
    candidates.into_iter().find(|p| p.is_dir())
}

fn resolve_addr(addr: &str) -> Result<SocketAddr, String> {
    addr.to_socket_addrs()
        .map_err(|e| format!("cannot use address `{addr}`: {e} (expected HOST:PORT)"))?
        .next()
        .ok_or_else(|| format!("address `{addr}` resolves to nothing"))
}

type Failure = (u8, String);

fn serve(args: Args) -> Result<(), Failure> {
    let invalid = |m: String| (crate::cli::EXIT_INVALID, m);
    let failure = |m: String| (crate::cli::EXIT_FAILURE, m);
    let addr = resolve_addr(&args.addr).map_err(invalid)?;
    let token = args.token.filter(|t| !t.is_empty());
    if !addr.ip().is_loopback() && token.is_none() && !args.allow_no_token {
        return Err(invalid(format!(
            "refusing to listen on {addr} (beyond this machine) without a token: set \
             --token / KEA_TOKEN, or pass --allow-no-token to accept anyone"
        )));
    }
    let workers = args
        .workers
        .filter(|&w| w > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    // A server without a token on loopback trusts whoever reaches it, so it checks that
    // a request was addressed to this machine: a web page whose name an attacker points
    // at 127.0.0.1 (DNS rebinding) is same-origin with kea, and would otherwise read and
    // submit through the user's browser. --allow-no-token accepts anyone, by name too.
    let host_check = (token.is_none() && !args.allow_no_token).then(|| {
        args.allowed_hosts
            .iter()
            .map(|h| h.trim().to_ascii_lowercase())
            .filter(|h| !h.is_empty())
            .collect()
    });
    let config = Config {
        token,
        host_check,
        web_dir: web_dir(args.web_dir),
        cors_origins: args.cors_origins,
        workers,
        limits: Limits {
            max_body_bytes: args.max_body_bytes,
            read_timeout: Duration::from_secs(args.read_timeout.max(1)),
            sync_work: args.sync_work_limit,
            max_work: args.max_work,
            job_time: Duration::from_secs(args.job_time_limit),
            queue: args.queue_limit,
            shutdown_grace: Duration::from_secs(args.shutdown_grace),
            keep_finished: args.keep_finished.map(Duration::from_secs),
            state_every: Duration::from_secs(args.state_every),
        },
    };
    let store: Arc<dyn store::Store> = Arc::new(
        store::sqlite::SqliteStore::open(&args.data_dir).map_err(|e| failure(e.to_string()))?,
    );
    let pool = worker::Pool::start(
        store.clone(),
        workers,
        config.limits.job_time,
        config.limits.state_every,
    )
    .map_err(|e| failure(e.to_string()))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| failure(format!("cannot start the runtime: {e}")))?;
    let (shutdown_tx, shutdown_rx) = watch::channel(false);
    let state = AppState {
        config: Arc::new(config.clone()),
        store,
        pool: pool.clone(),
        sync_permits: Arc::new(Semaphore::new(workers)),
        shutdown: shutdown_rx,
    };
    let served = runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .map_err(|e| failure(format!("cannot listen on {addr}: {e}")))?;
        let local = listener.local_addr().map_err(|e| failure(e.to_string()))?;
        tracing::info!(
            %local,
            data_dir = %args.data_dir.display(),
            workers,
            auth = config.token.is_some(),
            web = ?config.web_dir,
            "kea serve listening"
        );
        // The one line on stdout: scripts and tests read the bound address here.
        println!("kea: listening on http://{local}");
        let _ = std::io::stdout().flush();
        if let Some(keep) = config.limits.keep_finished {
            tokio::spawn(retention::sweep(state.store.clone(), keep));
        }
        let header_timeout = config.limits.read_timeout;
        serve_connections(listener, routes::app(state), header_timeout, async move {
            shutdown_signal().await;
            tracing::info!("shutting down: no new requests; finishing running jobs");
            let _ = shutdown_tx.send(true);
        })
        .await;
        Ok(())
    });
    // Workers run on their own threads: let them finish or re-queue their jobs.
    pool.shutdown(config.limits.shutdown_grace);
    runtime.shutdown_timeout(Duration::from_secs(1));
    tracing::info!("stopped");
    served
}

/// Accept connections and serve `app` on each (HTTP/1.1, hyper) until `shutdown`
/// completes; then stop accepting and wait for the open connections to finish, each
/// told to close after its current request. What `axum::serve` does, plus a timeout
/// on reading a request's line and headers (`header_timeout`), which it does not set.
async fn serve_connections(
    listener: tokio::net::TcpListener,
    app: axum::Router,
    header_timeout: Duration,
    shutdown: impl std::future::Future<Output = ()>,
) {
    use hyper_util::rt::{TokioIo, TokioTimer};
    use hyper_util::service::TowerToHyperService;
    let graceful = hyper_util::server::graceful::GracefulShutdown::new();
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(header_timeout);
    tokio::pin!(shutdown);
    loop {
        let stream = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, _)) => stream,
                Err(e) => {
                    // A connection that failed before it was accepted is the client's
                    // matter; anything else (out of file descriptors) is waited out.
                    use std::io::ErrorKind::*;
                    if !matches!(e.kind(), ConnectionRefused | ConnectionAborted | ConnectionReset) {
                        tracing::error!(error = %e, "accept failed; retrying in 1 s");
                        tokio::time::sleep(Duration::from_secs(1)).await;
                    }
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let conn =
            http.serve_connection(TokioIo::new(stream), TowerToHyperService::new(app.clone()));
        let conn = graceful.watch(conn);
        tokio::spawn(async move {
            if let Err(e) = conn.await {
                tracing::debug!(error = %e, "connection ended with an error");
            }
        });
    }
    drop(listener);
    graceful.shutdown().await;
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = terminate => {},
    }
}
