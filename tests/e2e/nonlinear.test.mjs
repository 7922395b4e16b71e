// The Nonlinear tab in a real browser against the real server: the seed-002 preset
// loaded as shipped (presets/nonlinear/, through the wasm module); a small case on a
// simulated truth (another f, an unmodelled thrust) run in the browser and as a server
// job, the page's i*, γ table and filters' δ against the result, and the result's bits
// against the server's for the same request built here; the core's errors at their
// field paths (a field, or under the model's text for a member without one, the α list,
// a local decimal comma); the CSV path on the seed's reference data
// (tests/data/nonlinear/), to the reference's i* and RMS; a script's job opened from the
// Server tab; the fields kept over a reload.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import path from 'node:path';
import { ROOT, client, openApp, relDiff, screenshot } from './lib.mjs';

const PRESET = readFileSync(path.join(ROOT, 'presets', 'nonlinear', 'seed-002.json'), 'utf8');
const REFERENCE = path.join(ROOT, 'tests', 'data', 'nonlinear');
const ALPHA = [1, 0.8, 0.6, 0.5, 0.4, 0.3];

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

/** A result without its wall-clock time (the one member a run's clock fills in). */
const bits = ({ timing, ...rest }) => {
  assert.equal(typeof timing?.wall_ms, 'number', 'a result has its timing');
  return rest;
};

/** The request run as a server job through the API, to its result. */
async function serverResult(request) {
  const submitted = await call('POST', '/v1/jobs', { kind: 'nonlinear', ...request });
  assert.equal(submitted.status, 202, JSON.stringify(submitted.json));
  const id = submitted.json.id;
  for (let i = 0; i < 600; i++) {
    const job = (await call('GET', `/v1/jobs/${id}`)).json;
    if (job.status === 'succeeded') return { id, result: (await call('GET', `/v1/jobs/${id}/result`)).json };
    assert.ok(['queued', 'running'].includes(job.status), JSON.stringify(job));
    await new Promise((r) => setTimeout(r, 100));
  }
  throw new Error(`job ${id} did not end`);
}

/** The tab shown, its preset loaded (a fresh start: the preset's text and α, the truth of the model). */
async function freshTab() {
  await page.click('#tab-nonlinear');
  await page.waitForSelector('#nonlinear-panel[data-ready=true]', { timeout: 30000 });
  await page.click('#nl-preset');
  await page.waitForFunction((t) => document.getElementById('nl-model').value === t, PRESET, { timeout: 30000 });
  await page.click('#nl-alpha-model');
  await page.check('input[name=nl-data-mode][value=truth]');
  await page.fill('#nl-truth-seed', '1');
  for (const id of await page.$$eval('#nl-truth-table input', (is) => is.map((i) => i.id))) await page.fill(`#${id}`, '');
  await page.check('#nl-q-on');
  await page.fill('#nl-q-scales', '');
}

/** Run the tab's request in `where` to its result; returns the downloaded result JSON. */
async function runNonlinear(where) {
  await page.evaluate(() => delete document.getElementById('nl-result').dataset.where);
  await page.check(`input[name=nl-where][value=${where}]`);
  await page.click('#nl-run');
  await page.waitForFunction(
    (w) => document.getElementById('nl-result').dataset.where === w && !document.getElementById('nl-run').disabled,
    where,
    { timeout: 120000 },
  );
  assert.match(await page.textContent('#nl-status'), where === 'browser' ? /browser, wasm/ : /server job/);
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#nl-download')]);
  return JSON.parse(readFileSync(await download.path(), 'utf8'));
}

/** Run in the browser until the status says an error; returns it. */
async function refusedRun() {
  await page.evaluate(() => {
    document.getElementById('nl-status').classList.remove('error');
    delete document.getElementById('nl-result').dataset.where;
  });
  await page.check('input[name=nl-where][value=browser]');
  await page.click('#nl-run');
  await page.waitForFunction(() => document.getElementById('nl-status').classList.contains('error'), null, { timeout: 30000 });
  return page.textContent('#nl-status');
}

/** What the page shows of a result: i*, the γ table, the filters' rows. */
async function shown() {
  return page.evaluate(() => {
    const value = (td) => (td.dataset.value === '' ? null : Number(td.dataset.value));
    const choice = document.getElementById('nl-choice');
    return {
      iStar: Number(choice.dataset.iStar),
      iStop: Number(choice.dataset.iStop),
      text: choice.textContent,
      gamma: [...document.querySelectorAll('#nl-gamma tbody tr')].map((tr) => [...tr.querySelectorAll('td[data-i]')].map(value)),
      alpha: [...document.querySelectorAll('#nl-gamma tbody td[data-key=alpha]')].map(value),
      rows: [...document.querySelectorAll('#nl-iterates tbody tr')].map((tr) => ({
        row: tr.dataset.row,
        star: tr.classList.contains('i-star'),
        stop: tr.classList.contains('stop-first'),
        delta: value(tr.querySelector('[data-key=delta]')),
        deltaPosterior: value(tr.querySelector('[data-key=delta_posterior]')),
        rms: [...tr.querySelectorAll('[data-key=rms]')].map(value),
        marks: tr.querySelector('[data-key=marks]').textContent,
      })),
    };
  });
}

/** The page's figures against the result's, exactly (the cells keep the JSON's digits). */
function assertShows(view, r) {
  assert.equal(view.iStar, r.i_star);
  assert.equal(view.iStop, r.i_stop_first_increase);
  assert.match(view.text, new RegExp(`^i\\* = ${r.i_star} \\(least δ`));
  assert.deepStrictEqual(view.gamma, r.gamma, 'the γ table');
  assert.deepStrictEqual(view.alpha, r.alpha);
  const filters = [...r.iterates, r.ekf, ...(r.q_scale.chosen === null ? [] : [r.q_scale.grid[r.q_scale.chosen]])];
  assert.deepEqual(
    view.rows.map((x) => x.row),
    [...r.iterates.map((s) => `iterate-${s.i}`), 'ekf', ...(r.q_scale.chosen === null ? [] : ['q-scale'])],
  );
  filters.forEach((s, k) => {
    assert.equal(view.rows[k].delta, s.delta, `row ${k}: δ`);
    assert.equal(view.rows[k].deltaPosterior, s.delta_posterior, `row ${k}: δ posterior`);
    assert.deepStrictEqual(view.rows[k].rms, s.rms ?? [], `row ${k}: RMS`);
  });
  view.rows.slice(0, r.iterates.length).forEach((x, k) => {
    assert.equal(x.star, k + 1 === r.i_star, `iterate ${k + 1}: i* marked`);
    assert.equal(x.stop, k + 1 === r.i_stop_first_increase, `iterate ${k + 1}: the stop marked`);
    assert.equal(x.marks.includes('i* (least δ)'), k + 1 === r.i_star);
    assert.equal(x.marks.includes('stop at the first increase'), k + 1 === r.i_stop_first_increase);
  });
}

test('the tab loads the seed-002 preset as shipped, with its fields', async () => {
  await page.click('#tab-nonlinear');
  await page.waitForSelector('#nonlinear-panel[data-ready=true]', { timeout: 30000 });
  await page.waitForFunction((t) => document.getElementById('nl-model').value === t, PRESET, { timeout: 30000 });
  assert.equal(await page.inputValue('#nl-f-0'), 'x2');
  assert.equal(await page.inputValue('#nl-f-1'), '-b*abs(x2)*x2/abs(x1)');
  assert.equal(await page.inputValue('#nl-h-0'), 'x1');
  assert.deepEqual(await page.$$eval('#nl-f tbody th, #nl-h tbody th', (ths) => ths.map((t) => t.textContent)), ['x1', 'x2', 'y']);
  assert.deepEqual(await page.$$eval('#nl-alpha input', (is) => is.map((i) => i.value)), ALPHA.map(String));
  assert.equal(await page.inputValue('#nl-residuals'), 'posterior');
  assert.equal(await page.inputValue('#nl-time-steps'), '2000');
  // A field's edit is written into the text, in the presets' layout: only that member changes.
  await page.fill('#nl-time-steps', '200');
  assert.equal(await page.inputValue('#nl-model'), PRESET.replace('"steps": 2000', '"steps": 200'));
  await page.fill('#nl-time-steps', '2000');
  assert.equal(await page.inputValue('#nl-model'), PRESET);
  // The text's edit is shown in the fields.
  await page.fill('#nl-model', PRESET.replace('"h": ["x1"]', '"h": ["x1 + 0"]'));
  assert.equal(await page.inputValue('#nl-h-0'), 'x1 + 0');
  // Nothing marked: the core reads the preset.
  await page.waitForTimeout(800);
  assert.deepEqual(await page.$$eval('#nonlinear-panel .control-error', (es) => es.map((e) => e.textContent)), []);
  await page.waitForFunction(() => /&tab=nonlinear$/.test(location.hash));
  assert.deepEqual(consoleErrors, []);
});

test('a small simulated case runs in the browser and on the server, the same bits as the API', async () => {
  await freshTab();
  await page.fill('#nl-time-t-end', '2');
  await page.fill('#nl-time-steps', '200');
  await page.fill('#nl-truth-seed', '7');
  // The truth: linear drag and a constant thrust, where the filter keeps its quadratic law.
  await page.fill('#nl-truth-f-1', '-0.05*x2');
  await page.fill('#nl-truth-u-1', '3');
  await page.fill('#nl-q-scales', '0.1, 1, 10');
  const inBrowser = await runNonlinear('browser');
  await screenshot(page, '40-nonlinear-browser');
  assert.equal(inBrowser.steps, 200);
  assert.equal(inBrowser.iterates.length, 6);
  assert.equal(inBrowser.q_scale.grid.length, 3);
  assert.ok(inBrowser.traces.truth, 'a truth: the true errors');
  assertShows(await shown(), inBrowser);
  // The charts: over time (with the errors: a truth) and against i; filter 1's band only.
  for (const id of ['states', 'errors', 'delta', 'rms']) assert.ok(await page.$(`#nl-chart-${id} canvas`), `chart ${id}`);
  assert.match(await page.textContent('#nl-band-note'), /No band is drawn for the iterates k ≥ 2/);
  const legend = await page.$$eval('#nl-chart-states .u-legend .u-series .u-label', (ls) => ls.map((l) => l.textContent));
  assert.deepEqual(legend.filter((l) => /2σ/.test(l)), ['filter 1 +2σ', 'filter 1 −2σ'], 'one band: filter 1’s');
  assert.ok(legend.includes('y (measured)'), 'the measurements of x1 drawn with it');

  // The same request, built here from the preset, as a script would send it.
  const model = JSON.parse(PRESET);
  model.time.t_end = 2;
  model.time.steps = 200;
  const request = {
    model,
    data: { truth: { seed: 7, f: ['x2', '-0.05*x2'], input: [0, 3] } },
    procedure: { alpha: ALPHA, earlier_residuals: 'posterior' },
    q_scale: [0.1, 1, 10],
  };
  const api = await serverResult(request);
  assert.deepStrictEqual(bits(inBrowser), bits(api.result), 'browser and server: the same bits');
  // And the tab's server job.
  const onServer = await runNonlinear('server');
  assert.deepStrictEqual(bits(onServer), bits(api.result), 'the tab’s server job: the same bits');
  assertShows(await shown(), onServer);
  // The residuals of the earlier filters' predictions: another result, still the server's.
  await page.selectOption('#nl-residuals', 'prior');
  const prior = await runNonlinear('browser');
  assert.equal(prior.earlier_residuals, 'prior');
  assert.deepStrictEqual(bits(prior), bits((await serverResult({ ...request, procedure: { alpha: ALPHA, earlier_residuals: 'prior' } })).result));
  assert.deepEqual(consoleErrors, []);
});

test("the core's errors are shown at their field paths", async () => {
  await freshTab();
  await page.fill('#nl-time-steps', '200');
  await page.fill('#nl-time-t-end', '2');
  // An expression the core cannot read: marked at its field as typed, and by Run.
  await page.fill('#nl-f-1', '-b*abs(x2)*x2/abs(x1');
  await page.waitForSelector('#nl-f-1 ~ .control-error[data-error-path="model.system.f[1]"]', { timeout: 10000 });
  assert.match(await refusedRun(), /Invalid request — see the marked fields of this tab/);
  assert.equal(await page.getAttribute('#nl-f-1', 'aria-invalid'), 'true');
  assert.equal(await page.$$eval('#nl-f-1 ~ .control-error', (es) => es.length), 1);
  assert.equal(await page.evaluate(() => document.getElementById('nl-result').dataset.where ?? null), null, 'no result');
  await page.fill('#nl-f-1', '-b*abs(x2)*x2/abs(x1)');
  await page.waitForSelector('#nl-f-1 ~ .control-error', { state: 'detached', timeout: 10000 });
  // A member without a field of its own: listed under the model's text, with its path.
  const text = await page.inputValue('#nl-model');
  await page.fill('#nl-model', text.replace('"P0": [[100, 0], [0, 25]]', '"P0": [[100, 0]]'));
  await page.waitForSelector('.nl-text-errors li[data-error-path^="model.system.P0"]', { timeout: 10000 });
  assert.match(await refusedRun(), /see the marked fields/);
  const listed = await page.$$eval('.nl-text-errors li', (ls) => ls.map((l) => [l.dataset.errorPath, l.textContent]));
  assert.ok(listed.length >= 1 && listed.every(([p, t]) => p.startsWith('model.system.P0') && t.startsWith(`${p}: `)), JSON.stringify(listed));
  assert.equal(await page.getAttribute('#nl-model', 'aria-invalid'), 'true');
  await page.fill('#nl-model', text);
  await page.waitForSelector('.nl-text-errors', { state: 'detached', timeout: 10000 });
  // Text that is not JSON: said under it, the fields disabled until it reads.
  await page.fill('#nl-model', text.slice(0, 40));
  assert.match(await page.textContent('#nl-model-note'), /^The text is not JSON/);
  assert.equal(await page.isDisabled('#nl-f-0'), true);
  await page.fill('#nl-model', text);
  assert.equal(await page.isDisabled('#nl-f-0'), false);
  // The α list: the core's range at the entry, a decimal comma at once.
  await page.fill('#nl-alpha-1', '1.5');
  await refusedRun();
  assert.deepEqual(await page.$$eval('#nl-alpha-1 ~ .control-error', (es) => es.map((e) => [e.dataset.errorPath, e.textContent])), [
    ['procedure.alpha[1]', 'expected 0 < α_j < 1 for j ≥ 1 (else the weights γ change sign or vanish), got 1.5'],
  ]);
  await page.fill('#nl-alpha-1', '0,8');
  assert.deepEqual(await page.$$eval('#nl-alpha-1 ~ .control-error', (es) => es.map((e) => e.textContent)), ['“0,8” — use a decimal point: 0.8']);
  await page.fill('#nl-alpha-1', '0.8');
  assert.equal(await page.$('#nl-alpha-1 ~ .control-error'), null);
  // A truth's expression: at its cell of the truth's table.
  await page.fill('#nl-truth-u-0', '3*');
  await refusedRun();
  assert.ok(await page.$('#nl-truth-u-0 ~ .control-error[data-error-path="data.truth.input[0]"]'));
  await page.fill('#nl-truth-u-0', '');
  await screenshot(page, '41-nonlinear-errors');
  assert.deepEqual(consoleErrors, []);
});

test('measured data from a CSV: the seed reference, to its i* and RMS', async () => {
  await freshTab();
  await page.check('input[name=nl-data-mode][value=csv]');
  const name = 'b_wrong_model_manoeuvre.data.csv';
  await page.setInputFiles('#nl-data-file', path.join(REFERENCE, name));
  await page.waitForFunction(() => /read on the model’s grid/.test(document.getElementById('nl-data-summary').textContent), null, { timeout: 30000 });
  assert.equal(await page.textContent('#nl-data-summary'), `${name}: 2,001 data rows × 5 columns (n, t, x1_true, x2_true, y) — read on the model’s grid.`);
  await page.uncheck('#nl-q-on');
  const result = await runNonlinear('browser');
  await screenshot(page, '42-nonlinear-csv');
  // The reference (computed outside kea): i*, the stop, γ, each iterate's RMS and δ.
  const expected = JSON.parse(readFileSync(path.join(REFERENCE, 'b_wrong_model_manoeuvre.expected.json'), 'utf8')).outputs.procedure;
  assert.equal(result.i_star, expected.i_star);
  assert.equal(result.i_stop_first_increase, expected.i_stop_first_increase);
  result.gamma.forEach((row, k) => row.forEach((g, i) => assert.ok(relDiff(g, expected.gamma[k][i]) <= 1e-12, `γ_${i + 1}^${k + 1}`)));
  expected.iterates.forEach((e, k) => {
    const s = result.iterates[k];
    assert.ok(relDiff(s.delta, e.delta_prior) <= 1e-9, `iterate ${k + 1}: δ ${s.delta} against ${e.delta_prior}`);
    assert.ok(relDiff(s.rms[0], e.rms_pos) <= 1e-9, `iterate ${k + 1}: RMS x1`);
    assert.ok(relDiff(s.rms[1], e.rms_vel) <= 1e-9, `iterate ${k + 1}: RMS x2`);
  });
  assert.deepEqual(result.ignored_columns, ['n']);
  assert.deepEqual(result.q_scale.grid, []);
  assertShows(await shown(), result);
  assert.equal(await page.textContent('#nl-ignored'), 'Columns not used: n.');
  assert.ok(await page.$('#nl-chart-errors canvas'), 'the truth of the CSV: the errors drawn');
  // The server's, for the same CSV text.
  const csv = readFileSync(path.join(REFERENCE, name), 'utf8');
  const api = await serverResult({ model: JSON.parse(PRESET), data: { csv_text: csv }, procedure: { alpha: ALPHA, earlier_residuals: 'posterior' }, q_scale: [] });
  assert.deepStrictEqual(bits(result), bits(api.result));
  // A cell that is not a number: named by its line, row and column under the box.
  await page.setInputFiles('#nl-data-file', { name: 'bad.csv', mimeType: 'text/csv', buffer: Buffer.from(csv.replace('\n1,0.01,', '\n1,abc,')) });
  await page.waitForFunction(() => document.getElementById('nl-data-summary').classList.contains('error'), null, { timeout: 30000 });
  assert.match(await page.textContent('#nl-data-summary'), /^bad\.csv: 2,001 data rows × 5 columns \(n, t, x1_true, x2_true, y\)\. The core’s reading: line 3 \(data row 2\), column "t": "abc" is not a number/);
  await page.fill('#nl-data', '');
  assert.deepEqual(consoleErrors, []);
});

test("a script's nonlinear job opens in the tab from the Server tab", async () => {
  const request = { model: 'preset:seed-002', set: { b: 0.8 }, data: { truth: { seed: 3, y0: [1000, 50] } }, procedure: { alpha: [1, 0.7, 0.5] }, q_scale: [], trace_points: 50 };
  const { id, result } = await serverResult(request);
  await page.click('#tab-jobs');
  await page.click('#jobs-refresh');
  await page.waitForSelector(`#jobs-table tr[data-job="${id}"]`);
  assert.equal(await page.textContent(`#jobs-table tr[data-job="${id}"] td:nth-child(2)`), 'Nonlinear');
  await page.click(`#jobs-table tr[data-job="${id}"] .job-open`);
  await page.waitForFunction(() => /opened from the Server tab/.test(document.getElementById('nl-status').textContent), null, { timeout: 60000 });
  assert.equal(await page.isVisible('#nonlinear-panel'), true);
  // Its request in the fields: the preset's model with the job's b, its truth, its α.
  const model = JSON.parse(await page.inputValue('#nl-model'));
  assert.deepEqual(model.params, { b: 0.8, sigma: 2 });
  assert.deepEqual(await page.$$eval('#nl-alpha input', (is) => is.map((i) => i.value)), ['1', '0.7', '0.5']);
  assert.equal(await page.inputValue('#nl-truth-seed'), '3');
  assert.deepEqual([await page.inputValue('#nl-truth-y0-0'), await page.inputValue('#nl-truth-y0-1')], ['1000', '50']);
  assert.equal(await page.isChecked('#nl-q-on'), false);
  assert.equal(await page.inputValue('#nl-trace-points'), '50');
  // Its result, as the server has it.
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#nl-download')]);
  assert.deepStrictEqual(JSON.parse(readFileSync(await download.path(), 'utf8')), result);
  assertShows(await shown(), result);
  assert.deepEqual(consoleErrors, []);
});

test("the tab's fields are kept over a reload", async () => {
  await freshTab();
  await page.fill('#nl-time-steps', '300');
  await page.click('#nl-alpha-add');
  await page.fill('#nl-alpha-6', '0.2');
  await page.fill('#nl-truth-seed', '11');
  const csv = 't,y\n0.0666,1001\n0.1333,1002\n';
  await page.check('input[name=nl-data-mode][value=csv]');
  await page.setInputFiles('#nl-data-file', { name: 'short.csv', mimeType: 'text/csv', buffer: Buffer.from(csv) });
  await page.waitForFunction(() => /^short\.csv: 2 data rows/.test(document.getElementById('nl-data-summary').textContent));
  const text = await page.inputValue('#nl-model');
  await page.reload();
  await page.waitForSelector('body[data-ready=true]', { timeout: 30000 });
  await page.waitForSelector('#nonlinear-panel[data-ready=true]', { timeout: 30000 });
  assert.equal(await page.isVisible('#nonlinear-panel'), true);
  assert.equal(await page.inputValue('#nl-model'), text);
  assert.equal(await page.inputValue('#nl-time-steps'), '300');
  assert.deepEqual(await page.$$eval('#nl-alpha input', (is) => is.map((i) => i.value)), [...ALPHA.map(String), '0.2']);
  assert.equal(await page.inputValue('#nl-truth-seed'), '11');
  assert.equal(await page.isChecked('input[name=nl-data-mode][value=csv]'), true);
  assert.equal(await page.inputValue('#nl-data'), csv);
  assert.deepEqual(consoleErrors, []);
});
