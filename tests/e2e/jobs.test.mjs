// The Server tab in a real browser against the real server: jobs submitted by a
// script (not by the page) are listed with their model's name; opened, each shows its
// model (with the values its `set` gave), its request in its tab's fields and the very
// result the API returns; a running one is followed and cancelled; a finished one is
// deleted with its result.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { client, kea, openApp, screenshot } from './lib.mjs';

let app;
let page;
let call;
const consoleErrors = [];

before(async () => {
  app = await openApp(consoleErrors);
  ({ page } = app);
  call = client(app.server.url);
});

after(async () => {
  await app?.close();
});


async function finished(id) {
  for (let i = 0; i < 600; i++) {
    const { json } = await call('GET', `/v1/jobs/${id}`);
    if (!['queued', 'running'].includes(json.status)) return json;
    await new Promise((r) => setTimeout(r, 100));
  }
  throw new Error(`job ${id} did not finish`);
}

async function submit(body) {
  const r = await call('POST', '/v1/jobs', body);
  assert.equal(r.status, 202, JSON.stringify(r.json));
  return r.json.id;
}

const tracker = () => {
  const m = JSON.parse(kea('preset', 'cv-tracker'));
  m.name = 'Tracker for the jobs tab';
  m.time.steps = 400;
  m.options.trace_points = 50;
  return m;
};

const row = (id) => `#jobs-table tr[data-job="${id}"]`;

/** Job `id` opened from the Server tab: its result (`#result`) shown, its run button (`#run`) ready. */
async function showJob(id, { result, run }) {
  await page.click('#tab-jobs');
  await page.click(`${row(id)} .job-open`);
  await page.waitForFunction(
    ([r, b]) => document.getElementById(r).offsetParent !== null && !document.getElementById(b).disabled && document.getElementById(b).closest('.run-controls').querySelector('[role=status]').textContent.includes('opened from the Server tab'),
    [result, run],
    { timeout: 30000 },
  );
}

/** Open the job's row and wait for its tab's result; returns the downloaded result JSON. */
async function openJob(id, { result, run, download }) {
  await showJob(id, { result, run });
  const [file] = await Promise.all([page.waitForEvent('download'), page.click(`#${download}`)]);
  return JSON.parse(readFileSync(await file.path(), 'utf8'));
}

test('jobs of every kind are listed, opened with their model, request and result, and deleted', async () => {
  const model = tracker();
  const analysis = await submit({ kind: 'analysis', model, set: { q: 2 } });
  // (`simulation`: the Monte Carlo kind's former name, still read as it)
  const simulation = await submit({ kind: 'simulation', model, runs: 20, seed: 7, truth: 'mean', model_error: 'constant', trace_points: 10 });
  const synthesis = await submit({
    kind: 'synthesis',
    model,
    // (`set`: the criteria set's former name, still read as `criteria`)
    target: { criterion: 'yx', set: 'covariance', threshold: 1.5 },
    mode: { grid: { params: [{ name: 'q', values: [0.5, 2] }], cost_order: [{ name: 'q', cheaper: 'higher' }] } },
  });
  const expected = {};
  for (const id of [analysis, simulation, synthesis]) {
    assert.equal((await finished(id)).status, 'succeeded');
    expected[id] = (await call('GET', `/v1/jobs/${id}/result`)).json;
  }

  await page.click('#tab-jobs');
  await page.waitForSelector(row(synthesis));
  // Newest first, named by their model, with their kind and status.
  const rows = await page.$$eval('#jobs-table tbody tr', (trs) => trs.map((tr) => [tr.dataset.job, ...[...tr.cells].slice(1, 4).map((c) => c.textContent)]));
  assert.deepEqual(rows, [
    [synthesis, 'Synthesis', model.name, 'succeeded'],
    [simulation, 'Monte Carlo', model.name, 'succeeded'],
    [analysis, 'Analysis', model.name, 'succeeded'],
  ]);
  assert.equal(await page.isVisible('#run'), false, "the analysis's Run bar is hidden on the jobs tab");
  await screenshot(page, 'jobs-tab');

  // The analysis: its model with q = 2 (its `set`), its result as the API gives it, current.
  const got = await openJob(analysis, { result: 'results', run: 'run', download: 'download-result' });
  assert.equal(await page.getAttribute('#tab-analysis', 'aria-selected'), 'true');
  assert.deepEqual(got, expected[analysis]);
  assert.equal(await page.inputValue('input[data-path="params.q"]'), '2');
  assert.equal(await page.inputValue('input[data-path="name"]'), model.name);
  assert.equal(await page.evaluate(() => document.getElementById('results').classList.contains('stale')), false);
  assert.match(await page.textContent('#page-status'), /Undo|Back/);

  // The Monte Carlo: its settings in the fields, its result.
  const mc = await openJob(simulation, { result: 'mc-result', run: 'mc-run', download: 'mc-download' });
  assert.equal(await page.getAttribute('#tab-monte-carlo', 'aria-selected'), 'true');
  assert.deepEqual(mc, expected[simulation]);
  assert.deepEqual(
    await page.evaluate(() => ['mc-runs', 'mc-seed', 'mc-truth', 'mc-model-error', 'mc-trace-points'].map((id) => document.getElementById(id).value)),
    ['20', '7', 'mean', 'constant', '10'],
  );
  assert.equal(await page.inputValue('input[data-path="params.q"]'), '1', 'this job ran the model without `set`');

  // The synthesis: its target and grid in the fields, its result.
  const syn = await openJob(synthesis, { result: 'syn-result', run: 'syn-run', download: 'syn-download' });
  assert.deepEqual(syn, expected[synthesis]);
  assert.equal(await page.inputValue('#syn-mode'), 'grid');
  assert.equal(await page.inputValue('#syn-criteria'), 'covariance');
  assert.equal(await page.evaluate(() => document.getElementById('syn-result').classList.contains('stale')), false);

  // Run again: the Monte Carlo's stored request submitted as a new job and opened in
  // its tab; seeded, it gives the same result but for the time taken.
  await page.click('#tab-jobs');
  await page.click(`${row(simulation)} .job-again`);
  await page.waitForFunction(
    (old) => {
      const status = document.querySelector('#mc-run').closest('.run-controls').querySelector('[role=status]').textContent;
      return document.getElementById('mc-result').offsetParent !== null && !document.getElementById('mc-run').disabled && status.includes('opened from the Server tab') && !status.includes(old);
    },
    simulation,
    { timeout: 30000 },
  );
  const newest = (await call('GET', '/v1/jobs?limit=1')).json.items[0];
  assert.notEqual(newest.id, simulation);
  assert.equal(newest.kind, 'monte_carlo');
  assert.deepEqual((await call('GET', `/v1/jobs/${newest.id}/request`)).json, (await call('GET', `/v1/jobs/${simulation}/request`)).json);
  const [file] = await Promise.all([page.waitForEvent('download'), page.click('#mc-download')]);
  const rerun = JSON.parse(readFileSync(await file.path(), 'utf8'));
  const untimed = ({ timing, ...rest }) => rest;
  assert.deepEqual(untimed(rerun), untimed(expected[simulation]));

  // Delete (confirmed): gone from the list and from the server; dismissed: kept.
  await page.click('#tab-jobs');
  page.once('dialog', (d) => d.dismiss());
  await page.click(`${row(analysis)} .job-delete`);
  assert.ok(await page.$(row(analysis)), 'a dismissed delete keeps the job');
  page.once('dialog', (d) => d.accept());
  await page.click(`${row(analysis)} .job-delete`);
  await page.waitForSelector(row(analysis), { state: 'detached' });
  assert.equal((await call('GET', `/v1/jobs/${analysis}`)).status, 404);
  assert.equal((await call('GET', `/v1/jobs/${simulation}`)).status, 200);
  assert.deepEqual(consoleErrors, []);
});

test('a running job is followed in the list and cancelled from it', async () => {
  const model = tracker();
  model.time.steps = 50_000_000;
  model.options.steady_state_shortcut = false;
  const id = await submit({ kind: 'analysis', model });
  await page.click('#tab-jobs');
  await page.click('#jobs-refresh');
  await page.waitForFunction((sel) => /running/.test(document.querySelector(sel)?.cells[3].textContent ?? ''), `${row(id)}`, { timeout: 30000 });
  await page.click(`${row(id)} .job-cancel`);
  // The list follows the job to its end without a refresh.
  await page.waitForFunction((sel) => document.querySelector(sel)?.cells[3].textContent === 'cancelled', `${row(id)}`, { timeout: 30000 });
  assert.equal((await call('GET', `/v1/jobs/${id}`)).json.status, 'cancelled');
  // Filtered by status.
  await page.selectOption('#jobs-filter', 'cancelled');
  await page.waitForFunction(() => [...document.querySelectorAll('#jobs-table tbody tr')].every((tr) => tr.cells[3].textContent === 'cancelled'));
  assert.ok(await page.$(row(id)));
  await page.selectOption('#jobs-filter', 'failed');
  await page.waitForFunction(() => document.getElementById('jobs-status').textContent === 'No failed jobs.');
  assert.deepEqual(consoleErrors, []);
});

test('a server that deletes finished jobs itself says when, in the help', async () => {
  const errors = [];
  const kept = await openApp(errors, ['--keep-finished', '86400']);
  try {
    await kept.page.click('#tab-jobs');
    await kept.page.waitForFunction(() => /deletes a finished job 24 h after it finished/.test(document.querySelector('#jobs-section .help').textContent));
  } finally {
    await kept.close();
  }
  assert.match(await page.textContent('#jobs-section .help'), /A finished job is kept until it is deleted here\./, 'the default server keeps them');
  assert.deepEqual(errors, []);
});

test('a result a server restart interrupted says from which step it went on', async () => {
  await page.click('#tab-jobs');
  await page.selectOption('#jobs-filter', ''); // (all: a test before chose one status)
  for (const [request, where, summary] of [
    [{ kind: 'analysis', model: tracker() }, { result: 'results', run: 'run' }, '#summary'],
    [{ kind: 'monte_carlo', model: tracker(), runs: 20 }, { result: 'mc-result', run: 'mc-run' }, '#mc-summary'],
  ]) {
    const id = await submit(request);
    assert.equal((await finished(id)).status, 'succeeded');
    // (A restart's result, as the server gives it: the same but for its timing.)
    await page.route(`**/v1/jobs/${id}/result`, async (route) => {
      const r = await route.fetch();
      const body = await r.json();
      body.timing.resumed_from_step = 123456;
      await route.fulfill({ response: r, json: body });
    });
    await showJob(id, where);
    assert.match(await page.textContent(summary), / on the server · resumed from step 123,456 after a server restart/, request.kind);
    await page.unroute(`**/v1/jobs/${id}/result`);
  }
  assert.deepEqual(consoleErrors, []);
});
