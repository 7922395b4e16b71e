//! kea's dev tasks (`cargo xtask …`, see `.cargo/config.toml`), std only.
//!
//! - `cargo xtask serve [-- <kea serve args>]`: build the wasm module and start
//!   `kea serve` with the web UI — the README's one run command.
//! - `cargo xtask test`: every test — Rust (release, so the builds are shared with
//!   `serve`), then the browser end-to-end tests against the real server, then the
//!   lints (`cargo fmt --check`, clippy with warnings denied).
//! - `cargo xtask lint`: only the lints.
//! - `cargo xtask e2e`: only the browser end-to-end tests.
//! - `cargo xtask wasm`: only build the wasm module into `web/pkg`.
//! - `cargo xtask bench-web`: the wasm-in-browser vs native benchmark.
//!
//! Missing tools are installed on the way: rustfmt and clippy, the `wasm32-unknown-unknown` target, the
//! `wasm-bindgen` CLI of exactly the version pinned in `wasm/Cargo.toml`, Chromium (apt) and the
//! e2e tests' npm packages (`npm ci`).

use std::env;
use std::ffi::OsStr;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

type Result<T> = std::result::Result<T, String>;

const WASM_TARGET: &str = "wasm32-unknown-unknown";
const USAGE: &str = "usage: cargo xtask <command>

commands:
  serve [-- <kea serve args>]   build the wasm module, then run `kea serve` (web UI at /)
  test                          run every test: Rust (release), the browser e2e tests, the lints
  lint                          only the lints: rustfmt --check, clippy (warnings denied)
  e2e                           only the browser e2e tests (tests/e2e, Chromium + kea serve)
  wasm                          build the wasm module into web/pkg
  bench-web                     benchmark the analysis in the browser (wasm) against native
";

fn main() -> ExitCode {
    let args: Vec<String> = env::args().skip(1).collect();
    let (cmd, rest) = match args.split_first() {
        Some((c, r)) => (c.as_str(), r),
        None => {
            eprint!("{USAGE}");
            return ExitCode::FAILURE;
        }
    };
    // Arguments after `--` go to `kea serve`; a leading `--` is optional.
    let rest: Vec<String> = match rest.first().map(String::as_str) {
        Some("--") => rest[1..].to_vec(),
        _ => rest.to_vec(),
    };
    let outcome = match cmd {
        "serve" => serve(&rest),
        "test" => test(),
        "e2e" => build_wasm().and_then(|()| e2e_tests()),
        "wasm" => build_wasm(),
        "lint" => lint(),
        "bench-web" => bench_web(),
        "-h" | "--help" | "help" => {
            print!("{USAGE}");
            Ok(())
        }
        other => Err(format!("unknown command `{other}`\n\n{USAGE}")),
    };
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The workspace root (the parent of this crate's folder).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

/// Cargo's target folder: `$CARGO_TARGET_DIR` or `<root>/target`.
fn target_dir() -> PathBuf {
    match env::var_os("CARGO_TARGET_DIR") {
        Some(dir) => {
            let dir = PathBuf::from(dir);
            if dir.is_absolute() {
                dir
            } else {
                root().join(dir)
            }
        }
        None => root().join("target"),
    }
}

fn cargo() -> Command {
    let mut c = Command::new(env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    c.current_dir(root());
    c
}

/// Run a command to completion; an error names it if it fails or cannot start.
fn run(cmd: &mut Command) -> Result<()> {
    eprintln!("xtask: $ {}", describe(cmd));
    let status = cmd
        .status()
        .map_err(|e| format!("cannot start `{}`: {e}", describe(cmd)))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{}` failed ({status})", describe(cmd)))
    }
}

/// Run a command and return its stdout, or None if it cannot start or fails.
fn output(cmd: &mut Command) -> Option<String> {
    let out = cmd.output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

fn describe(cmd: &Command) -> String {
    let mut s = cmd.get_program().to_string_lossy().into_owned();
    for a in cmd.get_args() {
        s.push(' ');
        s.push_str(&a.to_string_lossy());
    }
    s
}

// ---------------------------------------------------------------- toolchain

/// The wasm-bindgen version pinned (`"=X.Y.Z"`) in `wasm/Cargo.toml`: the CLI must
/// match it exactly.
fn pinned_wasm_bindgen() -> Result<String> {
    let path = root().join("wasm").join("Cargo.toml");
    let manifest =
        fs::read_to_string(&path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    exact_pin(&manifest, "wasm-bindgen").ok_or_else(|| {
        format!(
            "{} must pin wasm-bindgen exactly (`wasm-bindgen = \"=X.Y.Z\"`)",
            path.display()
        )
    })
}

/// The version of dependency `name` pinned as `name = "=X.Y.Z"` in a manifest.
fn exact_pin(manifest: &str, name: &str) -> Option<String> {
    manifest.lines().find_map(|line| {
        let (key, value) = line.split_once('=')?;
        if key.trim() != name {
            return None;
        }
        let v = value.trim().strip_prefix("\"=")?.strip_suffix('"')?;
        Some(v.to_string())
    })
}

/// The `wasm-bindgen` executable: on PATH, else in `$CARGO_HOME/bin`.
fn wasm_bindgen_exe() -> PathBuf {
    let cargo_home = env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| env::var_os("HOME").map(|h| PathBuf::from(h).join(".cargo")));
    if output(Command::new("wasm-bindgen").arg("--version")).is_none()
        && let Some(home) = cargo_home
    {
        let exe = home.join("bin").join("wasm-bindgen");
        if exe.exists() {
            return exe;
        }
    }
    PathBuf::from("wasm-bindgen")
}

/// Make sure the wasm target is installed.
fn ensure_wasm_target() -> Result<()> {
    let installed = output(Command::new("rustup").args(["target", "list", "--installed"]));
    match installed {
        Some(list) if list.lines().any(|l| l.trim() == WASM_TARGET) => {}
        Some(_) => run(Command::new("rustup").args(["target", "add", WASM_TARGET]))?,
        None => {
            eprintln!("xtask: rustup not found; assuming the {WASM_TARGET} target is installed")
        }
    }
    Ok(())
}

/// Make sure the wasm target and the matching wasm-bindgen CLI are installed.
fn ensure_wasm_toolchain() -> Result<PathBuf> {
    ensure_wasm_target()?;

    let version = pinned_wasm_bindgen()?;
    let exe = wasm_bindgen_exe();
    let found = output(Command::new(&exe).arg("--version"));
    let want = format!("wasm-bindgen {version}");
    if found.as_deref().map(str::trim) != Some(want.as_str()) {
        eprintln!(
            "xtask: need wasm-bindgen-cli {version} (found: {}); installing (a few minutes)",
            found.as_deref().map(str::trim).unwrap_or("none")
        );
        // No `--locked`: the CLI's own lock file names a version the package index
        // here lacks; the exact `--version` pin is what matters.
        run(cargo().args(["install", "wasm-bindgen-cli", "--version", &version]))?;
        let exe = wasm_bindgen_exe();
        let found = output(Command::new(&exe).arg("--version"));
        if found.as_deref().map(str::trim) != Some(want.as_str()) {
            return Err(format!(
                "installed wasm-bindgen-cli {version} but `{}` reports {:?}; is ~/.cargo/bin on PATH?",
                exe.display(),
                found
            ));
        }
        return Ok(exe);
    }
    Ok(exe)
}

/// Build `kea-wasm` for the browser into `web/pkg` (release).
fn build_wasm() -> Result<()> {
    let wasm_bindgen = ensure_wasm_toolchain()?;
    run(cargo().args([
        "build",
        "--release",
        "-p",
        "kea-wasm",
        "--target",
        WASM_TARGET,
    ]))?;
    let wasm = target_dir()
        .join(WASM_TARGET)
        .join("release")
        .join("kea_wasm.wasm");
    run(Command::new(wasm_bindgen)
        .current_dir(root())
        .args(["--target", "web", "--no-typescript", "--out-dir"])
        .arg(root().join("web").join("pkg"))
        .arg(&wasm))
}

// ---------------------------------------------------------------- commands

fn serve(args: &[String]) -> Result<()> {
    build_wasm()?;
    let mut cmd = cargo();
    cmd.args([
        "run",
        "--release",
        "-p",
        "kea-server",
        "--bin",
        "kea",
        "--",
        "serve",
    ]);
    cmd.args(args);
    run(&mut cmd)
}

/// Every test. A failing stage does not stop the next (CI shows every failure);
/// the command fails if any stage failed.
fn test() -> Result<()> {
    build_wasm()?;
    let mut failed = Vec::new();
    if let Err(e) = run(cargo().args(["test", "--workspace", "--release"])) {
        eprintln!("xtask: {e}; going on with the browser tests");
        failed.push("Rust tests");
    }
    if let Err(e) = e2e_tests() {
        eprintln!("xtask: {e}");
        failed.push("browser e2e tests");
    }
    if let Err(e) = lint() {
        eprintln!("xtask: {e}");
        failed.push("lints");
    }
    if failed.is_empty() {
        eprintln!("xtask: all tests passed");
        Ok(())
    } else {
        Err(format!("failed: {}", failed.join(", ")))
    }
}

/// Formatting and clippy (warnings denied; the exceptions are `[workspace.lints]` in
/// Cargo.toml), for the host and for the wasm adapter's own target.
fn lint() -> Result<()> {
    ensure_components(&["rustfmt", "clippy"])?;
    ensure_wasm_target()?;
    run(cargo().args(["fmt", "--all", "--check"]))?;
    let clippy = ["clippy", "--release", "--quiet"];
    run(cargo()
        .args(clippy)
        .args(["--workspace", "--all-targets", "--", "-D", "warnings"]))?;
    run(cargo().args(clippy).args([
        "-p",
        "kea-wasm",
        "--target",
        WASM_TARGET,
        "--",
        "-D",
        "warnings",
    ]))
}

/// Make sure the rustup components are installed (a toolchain without rustup is
/// assumed to have them).
fn ensure_components(names: &[&str]) -> Result<()> {
    let Some(list) = output(Command::new("rustup").args(["component", "list", "--installed"]))
    else {
        eprintln!(
            "xtask: rustup not found; assuming {} are installed",
            names.join(", ")
        );
        return Ok(());
    };
    let missing: Vec<&str> = names
        .iter()
        .copied()
        .filter(|n| !list.lines().any(|l| l.trim().starts_with(&format!("{n}-"))))
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    run(Command::new("rustup")
        .args(["component", "add"])
        .args(missing))
}

/// The browser end-to-end tests only (builds what they need).
fn e2e_tests() -> Result<()> {
    run(cargo().args(["build", "--release", "-p", "kea-server", "--bin", "kea"]))?;
    e2e(&["--test"], &e2e_test_files()?)
}

fn bench_web() -> Result<()> {
    build_wasm()?;
    run(cargo().args(["build", "--release", "-p", "kea-server", "--bin", "kea"]))?;
    e2e(&[], &[PathBuf::from("bench.mjs")])
}

/// The browser test files: `tests/e2e/*.test.mjs`, sorted.
fn e2e_test_files() -> Result<Vec<PathBuf>> {
    let dir = root().join("tests").join("e2e");
    let mut files: Vec<PathBuf> = fs::read_dir(&dir)
        .map_err(|e| format!("cannot list {}: {e}", dir.display()))?
        .filter_map(|e| e.ok())
        .map(|e| PathBuf::from(e.file_name()))
        .filter(|p| p.to_string_lossy().ends_with(".test.mjs"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(format!("no *.test.mjs files in {}", dir.display()));
    }
    Ok(files)
}

/// Run node scripts in `tests/e2e` against the built `kea` binary and Chromium.
fn e2e(node_args: &[&str], files: &[PathBuf]) -> Result<()> {
    let chromium = ensure_chromium()?;
    ensure_node()?;
    let dir = root().join("tests").join("e2e");
    run(Command::new("npm")
        .current_dir(&dir)
        .args(["ci", "--no-audit", "--no-fund"]))?;
    let kea = target_dir().join("release").join(exe_name("kea"));
    let mut cmd = Command::new("node");
    cmd.current_dir(&dir)
        .args(node_args)
        .args(files)
        .env("KEA_BIN", &kea)
        .env("KEA_ROOT", root())
        .env("KEA_CHROMIUM", &chromium);
    run(&mut cmd)
}

fn exe_name(name: &str) -> String {
    format!("{name}{}", env::consts::EXE_SUFFIX)
}

/// Chromium for the browser tests: `$KEA_CHROMIUM`, else Debian's, installed if missing.
fn ensure_chromium() -> Result<PathBuf> {
    if let Some(p) = env::var_os("KEA_CHROMIUM") {
        return Ok(PathBuf::from(p));
    }
    let debian = PathBuf::from("/usr/bin/chromium");
    if !debian.exists() {
        eprintln!("xtask: Chromium missing; installing it with apt-get");
        apt_install(&["chromium"])?;
    }
    if debian.exists() {
        Ok(debian)
    } else {
        Err("Chromium is still missing after apt-get; set KEA_CHROMIUM to a browser".into())
    }
}

/// The oldest Node.js the e2e tests' `playwright-core` supports.
const NODE_MAJOR: u32 = 20;

fn ensure_node() -> Result<()> {
    let npm = output(Command::new("npm").arg("--version")).is_some();
    let node = output(Command::new("node").arg("--version"));
    if node.is_none() || !npm {
        eprintln!("xtask: node/npm missing; installing them with apt-get");
        apt_install(&["nodejs", "npm"])?;
    }
    let version = output(Command::new("node").arg("--version")).unwrap_or_default();
    match node_major(&version) {
        Some(major) if major >= NODE_MAJOR => Ok(()),
        _ => Err(format!(
            "the browser tests need Node.js {NODE_MAJOR} or newer, found `{}`",
            version.trim()
        )),
    }
}

/// The major version of `node --version` output (`v20.20.2` → 20).
fn node_major(version: &str) -> Option<u32> {
    version
        .trim()
        .strip_prefix('v')?
        .split('.')
        .next()?
        .parse()
        .ok()
}

fn apt_install(packages: &[&str]) -> Result<()> {
    let as_root = output(Command::new("id").arg("-u")).is_some_and(|u| u.trim() == "0");
    let apt = |args: &[&str]| {
        let mut c = if as_root {
            Command::new("apt-get")
        } else {
            let mut c = Command::new("sudo");
            c.arg("apt-get");
            c
        };
        c.args(args).env("DEBIAN_FRONTEND", "noninteractive");
        c
    };
    run(&mut apt(&["update"]))?;
    let mut install = apt(&["install", "-y", "--no-install-recommends"]);
    install.args(packages.iter().map(OsStr::new));
    run(&mut install)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_an_exact_pin_from_a_manifest() {
        let manifest = "[dependencies]\nwasm-bindgen-futures = \"=9.9.9\"\n\
                        wasm-bindgen = \"=0.2.130\"\njs-sys = \"0.3\"\n";
        assert_eq!(
            exact_pin(manifest, "wasm-bindgen").as_deref(),
            Some("0.2.130")
        );
        assert_eq!(
            exact_pin(manifest, "wasm-bindgen-futures").as_deref(),
            Some("9.9.9")
        );
        assert_eq!(exact_pin(manifest, "js-sys"), None, "not an exact pin");
        assert_eq!(exact_pin(manifest, "serde"), None);
    }

    #[test]
    fn reads_the_node_major_version() {
        assert_eq!(node_major("v20.20.2\n"), Some(20));
        assert_eq!(node_major("v18.19.0"), Some(18));
        assert_eq!(node_major("20.1"), None);
    }

    #[test]
    fn the_workspace_pins_wasm_bindgen() {
        let v = pinned_wasm_bindgen().unwrap();
        assert_eq!(v.split('.').count(), 3, "{v}");
    }
}
