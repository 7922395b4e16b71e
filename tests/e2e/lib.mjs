// Shared helpers of the browser tests: the real `kea serve` on a free port with a
// temporary data dir, Debian's Chromium driven by playwright-core, and the CLI.
//
// Environment (set by `cargo xtask test`): KEA_BIN (the release `kea` binary),
// KEA_ROOT (the repository), KEA_CHROMIUM (the browser).

import { spawn, execFileSync } from 'node:child_process';
import { mkdtempSync, mkdirSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = path.dirname(fileURLToPath(import.meta.url));
export const ROOT = process.env.KEA_ROOT ?? path.resolve(here, '..', '..');
export const KEA_BIN = process.env.KEA_BIN ?? path.join(ROOT, 'target', 'release', 'kea');
export const CHROMIUM = process.env.KEA_CHROMIUM ?? '/usr/bin/chromium';
export const ARTIFACTS = path.join(here, 'artifacts');
mkdirSync(ARTIFACTS, { recursive: true });

/** Start `kea serve` on a free port (with extra `args`); resolves to {url, stop()} once it listens. */
export function startServer(args = []) {
  const dataDir = mkdtempSync(path.join(tmpdir(), 'kea-e2e-'));
  const child = spawn(
    KEA_BIN,
    ['serve', '--addr', '127.0.0.1:0', '--data-dir', dataDir, '--web-dir', path.join(ROOT, 'web'), ...args],
    { stdio: ['ignore', 'pipe', 'pipe'], env: { ...process.env, RUST_LOG: process.env.RUST_LOG ?? 'warn' } },
  );
  let log = '';
  child.stderr.on('data', (d) => (log += d));
  return new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`kea serve did not start in 20 s:\n${log}`)), 20000);
    let out = '';
    child.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/listening on (http:\/\/\S+)/);
      if (m) {
        clearTimeout(timer);
        resolve({
          url: m[1].replace(/\/$/, ''),
          log: () => log,
          stop: async () => {
            const exited = new Promise((r) => child.once('exit', r));
            child.kill('SIGTERM');
            await Promise.race([exited, new Promise((r) => setTimeout(r, 5000))]);
            if (child.exitCode === null) child.kill('SIGKILL');
            rmSync(dataDir, { recursive: true, force: true });
          },
        });
      }
    });
    child.once('exit', (code) => {
      clearTimeout(timer);
      reject(new Error(`kea serve exited with ${code}:\n${log}`));
    });
  });
}

/**
 * The web UI ready in a fresh browser: `kea serve` (with `args`), Chromium and a page on
 * `/` (console errors collected into `consoleErrors`). `close()` ends both.
 */
export async function openApp(consoleErrors, args = []) {
  const server = await startServer(args);
  const browser = await launchBrowser();
  const page = await newPage(browser, consoleErrors);
  await page.goto(`${server.url}/`);
  await page.waitForSelector('body[data-ready=true]', { timeout: 30000 });
  return { server, browser, page, close: async () => { await browser.close(); await server.stop(); } };
}

/** Headless Chromium with a fresh profile. */
export function launchBrowser() {
  return chromium.launch({
    executablePath: CHROMIUM,
    args: [
      '--headless',
      '--no-sandbox',
      '--disable-gpu',
      '--no-first-run',
      '--disable-background-networking',
      '--disable-component-update',
      '--disable-sync',
      '--disable-quic',
    ],
  });
}

/** A page that records console errors and uncaught exceptions into `errors`. */
export async function newPage(browser, errors) {
  const context = await browser.newContext({ viewport: { width: 1440, height: 900 }, acceptDownloads: true });
  const page = await context.newPage();
  page.on('console', (m) => {
    if (m.type() === 'error') errors.push(`console: ${m.text()}`);
  });
  page.on('pageerror', (e) => errors.push(`page error: ${e.message}`));
  return page;
}

/** Run the page's model in the browser until the status says an error; returns it. */
export async function refusedRun(page) {
  await page.check('input[name=mode][value=browser]');
  await page.evaluate(() => document.getElementById('status').classList.remove('error'));
  await page.click('#run');
  await page.waitForFunction(() => document.querySelector('#status').classList.contains('error'), null, { timeout: 30000 });
  return page.textContent('#status');
}

/**
 * Hold back the page's creation of server jobs (POST /v1/jobs) until `release()`, so that
 * something can happen while a run is under way; `reached` resolves when one is held.
 */
export async function holdJobs(page) {
  let reach;
  let release;
  let sent;
  const reached = new Promise((r) => (reach = r));
  const held = new Promise((r) => (release = r));
  const continued = new Promise((r) => (sent = r));
  await page.route('**/v1/jobs', async (route) => {
    if (route.request().method() !== 'POST') return route.continue();
    reach();
    await held;
    await route.continue();
    sent();
  });
  return {
    reached,
    release: async () => {
      release();
      await continued;
      await page.unroute('**/v1/jobs');
    },
  };
}

/** Run the `kea` CLI and return its stdout. */
export function kea(...args) {
  return execFileSync(KEA_BIN, args, { cwd: ROOT, encoding: 'utf8', maxBuffer: 256 * 1024 * 1024 });
}

/**
 * A script's client of the server at `base`: `call(method, path, body?)` resolves to
 * {status, json} (json null for a 204).
 */
export function client(base) {
  return async (method, path, body) => {
    const r = await fetch(`${base}${path}`, {
      method,
      headers: body ? { 'content-type': 'application/json' } : {},
      body: body ? JSON.stringify(body) : undefined,
    });
    return { status: r.status, json: r.status === 204 ? null : await r.json() };
  };
}

export function screenshot(page, name) {
  return page.screenshot({ path: path.join(ARTIFACTS, `${name}.png`), fullPage: true });
}

/** |a − b| / max(|a|, |b|), 0 when both are 0. */
export function relDiff(a, b) {
  const scale = Math.max(Math.abs(a), Math.abs(b));
  return scale === 0 ? 0 : Math.abs(a - b) / scale;
}

/** An N-state chain (a_ii = −0.5, a_i,i+1 = 1) measured in its first n states, L = 1, M = n. */
export function chainModel(N, n) {
  const eye = (r, c) => Array.from({ length: r }, (_, i) => Array.from({ length: c }, (_, j) => (i === j ? 1 : 0)));
  return {
    kea_model: 1,
    name: `chain of ${N}`,
    params: { q: 0.1 },
    time: { t0: 0, t_end: 1, steps: 100 },
    system: {
      states: Array.from({ length: N }, (_, i) => `y${i + 1}`),
      a: Array.from({ length: N }, (_, i) => Array.from({ length: N }, (_, j) => (i === j ? -0.5 : j === i + 1 ? 1 : 0))),
      b: Array.from({ length: N }, () => [1]),
      y0: Array(N).fill(0),
      eta0: Array(N).fill(1),
      phi: ['q'],
    },
    measurement: {
      names: Array.from({ length: n }, (_, j) => `z${j + 1}`),
      c: eye(n, N),
      gamma: eye(n, n),
      psi: Array(n).fill(0.5),
    },
    criteria: { confidence: 0.95 },
    options: { trace_points: 1000, steady_state_shortcut: true },
  };
}

/**
 * Choose the preset `name` in the page's picker: waits for the address to name it, and
 * `settle` ms more (the core's check of the model shown answers within about that).
 */
export async function choosePreset(page, name, settle = 300) {
  await page.selectOption('#preset', name);
  await page.waitForFunction((n) => location.hash.startsWith(`#preset=${n}`), name);
  if (settle) await page.waitForTimeout(settle);
}

/** Import `model` as the JSON file `name`: waits for the page to say so, and `settle` ms more. */
export async function importModel(page, model, name, settle = 300) {
  await page.setInputFiles('#import-model', { name, mimeType: 'application/json', buffer: Buffer.from(JSON.stringify(model)) });
  await page.waitForFunction((n) => document.getElementById('page-status').textContent.includes(n), name, { timeout: 60000 });
  if (settle) await page.waitForTimeout(settle);
}

/** The model as the page's "Export JSON" saves it (parsed). */
export async function exportedModel(page) {
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#export-model')]);
  return JSON.parse(readFileSync(await download.path(), 'utf8'));
}

/** Run the Analysis tab's analysis in `where` (browser or server) and wait for its result. */
export async function runAnalysis(page, where) {
  await page.check(`input[name=mode][value=${where}]`);
  const before = await page.evaluate(() => document.querySelector('#summary').textContent);
  await page.click('#run');
  await page.waitForFunction(
    (b) => !document.querySelector('#results').hidden && document.querySelector('#summary').textContent !== b && !document.querySelector('#run').disabled,
    before,
    { timeout: 30000 },
  );
}

/** Run the Monte Carlo tab's runs in `where` (browser or server) and wait for its result. */
export async function runMonteCarlo(page, where) {
  await page.evaluate(() => delete document.getElementById('mc-result').dataset.where);
  await page.check(`input[name=mc-where][value=${where}]`);
  await page.click('#mc-run');
  await page.waitForFunction((w) => document.getElementById('mc-result').dataset.where === w && !document.getElementById('mc-run').disabled, where, { timeout: 60000 });
}
