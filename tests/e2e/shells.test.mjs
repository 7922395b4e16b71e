// One request of each kind of run through every shell — the command line, the HTTP
// API (a job) and the wasm module (loaded in Node, as the page's worker loads it) —
// gives the same result bits: every shell goes through the core's one way in
// (kea_core::registry), and the core is deterministic on every target.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { pathToFileURL } from 'node:url';
import { ROOT, client, kea, startServer } from './lib.mjs';

let server;
let call;
let wasm;
let dir;

before(async () => {
  server = await startServer();
  call = client(server.url);
  wasm = await import(pathToFileURL(path.join(ROOT, 'web', 'pkg', 'kea_wasm.js')).href);
  await wasm.default({ module_or_path: readFileSync(path.join(ROOT, 'web', 'pkg', 'kea_wasm_bg.wasm')) });
  dir = mkdtempSync(path.join(tmpdir(), 'kea-shells-'));
});

after(async () => {
  await server?.stop();
  if (dir) rmSync(dir, { recursive: true, force: true });
});

/** A result without its wall-clock time (the one member a run's clock fills in). */
function bits(result) {
  const { timing, ...rest } = result;
  assert.equal(typeof timing?.wall_ms, 'number', 'a result has its timing');
  return JSON.stringify(rest);
}

async function viaJob(kind, request) {
  const submitted = await call('POST', '/v1/jobs', { kind, ...request });
  assert.equal(submitted.status, 202, JSON.stringify(submitted.json));
  const id = submitted.json.id;
  for (let i = 0; i < 600; i++) {
    const job = (await call('GET', `/v1/jobs/${id}`)).json;
    if (job.status === 'succeeded') return (await call('GET', `/v1/jobs/${id}/result`)).json;
    assert.ok(['queued', 'running'].includes(job.status), JSON.stringify(job));
    await new Promise((r) => setTimeout(r, 100));
  }
  throw new Error(`job ${id} did not finish`);
}

function viaWasm(kind, request) {
  return JSON.parse(wasm.run(kind, JSON.stringify(request), () => true));
}

function file(name, value) {
  const p = path.join(dir, name);
  writeFileSync(p, JSON.stringify(value));
  return p;
}

const model = () => JSON.parse(kea('preset', 'cv-tracker'));

test('an analysis gives the same bits through the CLI, a job and wasm', async () => {
  const request = { model: model(), set: { q: 2 } };
  const cli = JSON.parse(kea('analyze', file('model.json', request.model), '--set', 'q=2', '--json'));
  const job = await viaJob('analysis', request);
  const browser = viaWasm('analysis', request);
  assert.equal(bits(job), bits(cli));
  assert.equal(bits(browser), bits(cli));
});

test('an analysis with its error budget gives the same bits through the CLI, a job and wasm', async () => {
  const request = { model: model(), set: { q: 2 }, budget: true };
  const cli = JSON.parse(kea('analyze', file('model.json', request.model), '--set', 'q=2', '--budget', '--json'));
  assert.equal(cli.budget.sources.length, 4, 'η0 ×2, one model error, one measurement error');
  const job = await viaJob('analysis', request);
  const browser = viaWasm('analysis', request);
  // The page's own call: the worker's analyze(model, set, budget, progress).
  const page = JSON.parse(wasm.analyze(JSON.stringify(request.model), '{"q": 2}', '{"budget": true}', () => true));
  assert.equal(bits(job), bits(cli));
  assert.equal(bits(browser), bits(cli));
  assert.equal(bits(page), bits(cli));
});

test('a sensitivity gives the same bits through the CLI, a job and wasm', async () => {
  const request = { model: model(), set: { q: 2 }, params: ['q', 'r'], relative_step: 0.01 };
  const cli = JSON.parse(kea('sensitivity', file('sens-model.json', request.model), '--set', 'q=2', '--param', 'q', '--param', 'r', '--relative-step', '0.01', '--json'));
  assert.equal(cli.analyses, 5);
  const job = await viaJob('sensitivity', request);
  const browser = viaWasm('sensitivity', request);
  assert.equal(bits(job), bits(cli));
  assert.equal(bits(browser), bits(cli));
});

test('a Monte Carlo gives the same bits through the CLI, a job and wasm', async () => {
  const request = { model: model(), runs: 40, seed: 11, truth: 'mean', model_error: 'constant', trace_points: 12 };
  const cli = JSON.parse(
    kea('monte-carlo', file('mc-model.json', request.model), '--runs', '40', '--seed', '11', '--truth', 'mean', '--model-error', 'constant', '--trace-points', '12', '--json'),
  );
  const job = await viaJob('monte_carlo', request);
  const browser = viaWasm('monte_carlo', request);
  assert.equal(bits(job), bits(cli));
  assert.equal(bits(browser), bits(cli));
  // `simulation` and `kea simulate`, the former names, are the same kind.
  assert.equal(bits(await viaJob('simulation', request)), bits(cli));
  assert.equal(bits(viaWasm('simulation', request)), bits(cli));
  const aliased = kea('simulate', file('mc-model.json', request.model), '--runs', '40', '--seed', '11', '--truth', 'mean', '--model-error', 'constant', '--trace-points', '12', '--json');
  assert.equal(bits(JSON.parse(aliased)), bits(cli));
});

test('a synthesis gives the same bits through the CLI, a job and wasm', async () => {
  const request = { model: model(), ...JSON.parse(kea('preset', 'cv-tracker', '--synthesis')) };
  const cli = JSON.parse(kea('synthesize', file('request.json', request), '--json'));
  const job = await viaJob('synthesis', request);
  const browser = viaWasm('synthesis', request);
  assert.equal(bits(job), bits(cli));
  assert.equal(bits(browser), bits(cli));
});

test('an identification gives the same bits through the CLI, a job and wasm', async () => {
  const dir = path.join(ROOT, 'examples', 'identification');
  const example = JSON.parse(readFileSync(path.join(dir, 'oscillator.json'), 'utf8'));
  // The CLI reads the CSV file the request names; a job and the browser send its text.
  const request = { ...example, data: { csv_text: readFileSync(path.join(dir, example.data.csv), 'utf8') } };
  const cli = JSON.parse(kea('identify', path.join(dir, 'oscillator.json'), '--json'));
  const job = await viaJob('identification', request);
  const browser = viaWasm('identification', request);
  assert.equal(bits(job), bits(cli));
  assert.equal(bits(browser), bits(cli));
  assert.equal(cli.converged, true);
});
