// The Identification tab in a real browser against the real server: the oscillator
// example (examples/identification, shipped with the page in web/examples) loaded into
// the editor and the tab, run in the browser (wasm) and as a server job; the estimates
// against the reference optimum computed outside kea, and the result's bits against
// `kea identify --json`. A bad CSV cell is named by its line, row and column; Cancel
// stops a run; a discrete model in the editor leaves the other tabs to say the core's
// error. The innovations say whether the model fits; more starts list the optima they
// reach (the mirror w → −w); a malformed start is refused at its field.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { ROOT, client, exportedModel, importModel, kea, openApp, refusedRun, relDiff, screenshot } from './lib.mjs';

// The reference optimum of the example's data (the identification reference's case b,
// tests/data/identification/, computed outside kea) and its standard errors from the
// sample information.
const OPTIMUM = { r: 0.9634378830434038, w: 0.30180822241345795, sv: 0.5323224117654461 };
const STD_ERROR = { r: 0.006262557695822333, w: 0.007310165276882946, sv: 0.015918323695359088 };

let app;
let page;
const consoleErrors = [];

before(async () => {
  app = await openApp(consoleErrors);
  ({ page } = app);
});

after(async () => {
  await app?.close();
});

/** A result without its wall-clock time (the one member a run's clock fills in). */
const bits = ({ timing, ...rest }) => {
  assert.equal(typeof timing?.wall_ms, 'number', 'a result has its timing');
  return rest;
};

/** Run the tab's request in `where` to its result; returns the downloaded result JSON. */
async function runIdentification(where) {
  await page.evaluate(() => delete document.getElementById('id-result').dataset.where);
  await page.check(`input[name=id-where][value=${where}]`);
  await page.click('#id-run');
  await page.waitForFunction(
    (w) => document.getElementById('id-result').dataset.where === w && !document.getElementById('id-run').disabled,
    where,
    { timeout: 120000 },
  );
  assert.match(await page.textContent('#id-status'), where === 'browser' ? /browser, wasm/ : /server job/);
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#id-download')]);
  assert.match(download.suggestedFilename(), /-identification\.json$/);
  return JSON.parse(readFileSync(await download.path(), 'utf8'));
}

async function loadExample() {
  await page.click('#tab-identification');
  await page.click('#id-example');
  await page.waitForFunction(() => /Loaded the example/.test(document.getElementById('id-status').textContent), null, { timeout: 30000 });
  // The core read the data against the model's grid (the data box's summary says so).
  await page.waitForFunction(() => /read on the model’s grid/.test(document.getElementById('id-data-summary').textContent), null, { timeout: 30000 });
}

test('the example ships with the page as it is in examples/identification', () => {
  for (const name of ['oscillator.json', 'oscillator.csv']) {
    const shipped = readFileSync(path.join(ROOT, 'web', 'examples', 'identification', name), 'utf8');
    assert.equal(shipped, readFileSync(path.join(ROOT, 'examples', 'identification', name), 'utf8'), name);
  }
});

test('the example runs in the browser and on the server to the reference optimum, the same bits as the CLI', async () => {
  await loadExample();
  assert.match(await page.textContent('#page-status'), /Loaded the identification example/);
  assert.equal(await page.textContent('#id-data-summary'), 'oscillator.csv: 1,000 data rows × 2 columns (t, position_meas) — read on the model’s grid.');
  // The editor shows the discrete model (Φ in place of a) and checks it as the
  // identification reads it: no message at any field.
  await page.waitForSelector('[data-grid="system.transition"]');
  assert.equal(await page.$('[data-grid="system.a"]'), null);
  assert.equal(await page.inputValue('input[data-path="system.transition[0][1]"]'), 'r*sin(w)');
  assert.equal(await page.inputValue('#form-system-prior'), 'first_measurement');
  await page.waitForTimeout(400);
  assert.deepEqual(await page.$$eval('#editor .cell-error, #editor .general-errors li', (es) => es.map((e) => e.textContent)), []);
  // The params' rows: the example's estimate (sw fixed).
  const rows = await page.$$eval('#id-params tbody tr', (trs) =>
    trs.map((tr) => [tr.dataset.param, tr.querySelector('input[type=checkbox]').checked, ...[...tr.querySelectorAll('input:not([type=checkbox])')].map((i) => i.value)]),
  );
  assert.deepEqual(rows, [
    ['r', true, '0.8', '0', '1'],
    ['w', true, '0.5', '0', ''],
    ['sv', true, '1', '0', ''],
    ['sw', false, '', '', ''],
  ]);
  assert.equal(await page.getAttribute('#id-initial-3', 'placeholder'), '0.3', "an empty initial value is the model's");

  const inBrowser = await runIdentification('browser');
  await screenshot(page, '30-identification-browser');
  assert.deepEqual(inBrowser.parameters, ['r', 'sv', 'w']);
  for (const [name, value] of Object.entries(OPTIMUM)) {
    const e = inBrowser.estimate[name];
    assert.ok(Math.abs(e.value - value) <= 1e-6, `${name} = ${e.value}, the reference ${value}`);
    assert.ok(relDiff(e.std_error, STD_ERROR[name]) <= 1e-5, `${name}: std error ${e.std_error}, the reference ${STD_ERROR[name]}`);
    assert.equal(e.at_bound, false, name);
  }
  assert.equal(inBrowser.converged, true);
  assert.equal(inBrowser.identifiability.identifiable, true);
  // The table shows them, with the 95 % intervals, the initial values and the bounds.
  const shown = await page.$$eval('#id-estimates tbody tr', (trs) =>
    Object.fromEntries(trs.map((tr) => [tr.dataset.param, Object.fromEntries([...tr.querySelectorAll('td')].map((td) => [td.dataset.key, [td.dataset.value, td.textContent]]))])),
  );
  assert.deepEqual(Object.keys(shown), ['r', 'sv', 'w']);
  for (const name of inBrowser.parameters) {
    const e = inBrowser.estimate[name];
    assert.equal(Number(shown[name].value[0]), e.value, `${name}: the value shown`);
    assert.equal(shown[name].value[1], String(Number(e.value.toPrecision(5))), `${name}: the value's text`);
    assert.equal(Number(shown[name].std_error[0]), e.std_error, `${name}: the std error shown`);
    assert.deepEqual(JSON.parse(shown[name].interval[0]), e.interval, `${name}: the interval shown`);
    assert.equal(Number(shown[name].initial[0]), e.initial, `${name}: the initial value shown`);
    assert.equal(shown[name].at_bound[1], 'no', `${name}: at a bound`);
  }
  assert.equal(shown.r.value[1], '0.96344');
  assert.match(await page.textContent('#id-summary'), /^J = 1118\.2 \(−log-likelihood\) · scoring, \d+ iterations, \d+ evaluations of J · D = 1,000 steps, 1,000 measurements · .* on the browser \(wasm\)$/);
  assert.equal(await page.textContent('#id-identifiability'), inBrowser.identifiability.verdict);
  assert.match(await page.textContent('#id-identifiability'), /^identifiable: the information's condition number is 6\.5$/);
  assert.equal(await page.textContent('#id-stop'), `Converged: ${inBrowser.stop_reason}`);
  // Does the model fit? The NIS within its band, the position's innovations white, Q as the result has it.
  const inn = inBrowser.innovations;
  assert.equal(inn.nis_consistent, true);
  assert.equal(await page.getAttribute('#id-nis', 'data-consistent'), 'true');
  assert.match(await page.textContent('#id-nis'), /^NIS mean 1\.0027 within its 95 % band \[0\.91426, 1\.0895\] \(1,000 degrees of freedom\): consistent$/);
  assert.equal(await page.textContent('#id-fit-verdict'), 'Yes: the NIS is consistent and the innovations are white at 95 %.');
  const whiteness = await page.$$eval('#id-whiteness tbody tr', (trs) =>
    trs.map((tr) => [tr.dataset.measurement, Object.fromEntries([...tr.querySelectorAll('td')].map((td) => [td.dataset.key, [td.dataset.value, td.textContent]]))]),
  );
  assert.deepEqual(whiteness.map(([m]) => m), ['position_meas']);
  const [, w0] = whiteness[0];
  const expected = inn.whiteness[0];
  assert.equal(expected.white, true);
  assert.deepEqual(w0.white, ['true', `white: Q ≤ ${Number(expected.critical.toPrecision(5))}`]);
  assert.equal(Number(w0.ljung_box[0]), expected.ljung_box, 'Q: the result JSON’s');
  assert.equal(w0.ljung_box[1], '12.609');
  assert.equal(Number(w0.critical[0]), expected.critical);
  assert.equal(w0.lags[1], '20');
  // The autocorrelations as bars with the band ±1.96/√n.
  assert.ok(await page.$('#id-chart-acf-0 .uplot'), 'the chart of the autocorrelations');
  assert.deepEqual(await page.$$eval('#id-chart-acf-0 .u-legend .u-series th', (ths) => ths.map((t) => t.textContent)), ['lag', 'ρ', '+1.96/√n', '−1.96/√n']);
  // The innovations over time: the example's 1000 steps all drawn (a bucket of 1),
  // with the ±1.96 band; the trace is the CSV's column at those steps.
  assert.equal(inn.trace.bucket, 1);
  assert.equal(inn.trace.t.length, 1000);
  assert.equal(await page.getAttribute('#id-chart-innovations-0', 'data-points'), '1000');
  assert.deepEqual(await page.$$eval('#id-chart-innovations-0 .u-legend .u-series th', (ths) => ths.map((t) => t.textContent)), ['t', 'ν/√S', '+1.96', '−1.96']);
  const csvRows = kea('identify', path.join('examples', 'identification', 'oscillator.json'), '--csv', '-').trim().split('\n').slice(1);
  const [t0, , nu0] = csvRows[0].split(',').map(Number);
  assert.equal(inn.trace.t[0], t0);
  assert.equal(inn.trace.innovations[0][0], nu0);
  assert.equal(await page.$('#id-optima'), null, 'one optimum: no table of optima');
  // J and a param's path over the iterations.
  assert.ok(await page.$('#id-chart-j .uplot'), 'the chart of J');
  assert.ok(await page.$('#id-chart-param .uplot'), "the chart of a param's path");
  const legend = await page.$$eval('#id-chart-param .u-legend .u-series th', (ths) => ths.map((t) => t.textContent));
  assert.deepEqual(legend, ['iteration', 'r', '95 % interval, low', '95 % interval, high']);
  await page.selectOption('#id-param', 'sv');
  await page.waitForFunction(() => /^sv against/.test(document.querySelector('#id-chart-param .u-title')?.textContent ?? ''));

  // The same bits through the CLI (which reads the CSV file beside the request) and a server job.
  const cli = JSON.parse(kea('identify', path.join('examples', 'identification', 'oscillator.json'), '--json'));
  assert.deepStrictEqual(bits(inBrowser), bits(cli), 'browser and CLI: the same bits');
  // The example asks for the expected information: the select shows it, and the
  // table's Cramér–Rao column holds the CLI's bounds.
  assert.equal(await page.inputValue('#id-expected'), 'yes');
  for (const name of cli.parameters) {
    const shown = await page.getAttribute(`#id-estimates tr[data-param="${name}"] td[data-key="cramer_rao_sko"]`, 'data-value');
    assert.equal(Number(shown), cli.estimate[name].cramer_rao_sko, name);
    assert.ok(cli.estimate[name].cramer_rao_sko > 0, name);
  }
  const onServer = await runIdentification('server');
  assert.deepStrictEqual(bits(onServer), bits(cli), 'server job and CLI: the same bits');
  assert.match(await page.textContent('#id-summary'), /on the server$/);

  // The editor's model stays discrete (Φ, where its prior is; no a created by the page).
  const model = await exportedModel(page);
  assert.equal(model.system.a, undefined);
  assert.deepEqual(model.system.transition, [['r*cos(w)', 'r*sin(w)'], ['-r*sin(w)', 'r*cos(w)']]);
  assert.equal(model.system.prior_at, 'first_measurement');
  assert.deepEqual(consoleErrors, []);
});

test('a bad CSV cell is named by its line, data row and column, at the data and in the run', async () => {
  await loadExample();
  const lines = (await page.inputValue('#id-data')).split('\n');
  lines[4] = lines[4].replace(/,.*$/, ',abc'); // line 5: the 4th data row
  await page.fill('#id-data', lines.join('\n'));
  const message = 'line 5 (data row 4), column "position_meas": "abc" is not a number (an empty cell is a missing measurement)';
  await page.waitForFunction((m) => document.getElementById('id-data-summary').textContent.includes(m), message, { timeout: 10000 });
  assert.ok(await page.$eval('#id-data-summary', (e) => e.classList.contains('error')));
  await page.check('input[name=id-where][value=browser]');
  await page.click('#id-run');
  await page.waitForFunction(() => document.getElementById('id-status').classList.contains('error'), null, { timeout: 30000 });
  assert.equal(await page.textContent('#id-data ~ .control-error'), message);
  assert.equal(await page.getAttribute('#id-data', 'aria-invalid'), 'true');
  assert.match(await page.textContent('#id-status'), /see the marked fields/);
  await screenshot(page, '31-identification-bad-cell');
  // The request's own fields are checked before it is sent, at their controls.
  await page.fill('#id-data', lines.join('\n').replace(',abc', ',0.5'));
  await page.fill('#id-min-0', '0,5');
  await page.fill('#id-max-iterations', '0');
  await page.click('#id-run');
  await page.waitForSelector('#id-min-0 + .control-error');
  assert.match(await page.textContent('#id-min-0 + .control-error'), /use a decimal point: 0\.5/);
  assert.match(await page.textContent('#id-max-iterations + .control-error'), /must be ≥ 1, got 0/);
  await page.fill('#id-min-0', '0');
  await page.fill('#id-max-iterations', '');
  assert.equal(await page.$('#id-min-0 + .control-error'), null, 'a fixed field is re-checked as it is typed');
  // The core's check of the request: an initial value outside its bounds.
  await page.fill('#id-initial-0', '2');
  await page.click('#id-run');
  await page.waitForSelector('#id-initial-0 + .control-error', { timeout: 30000 });
  assert.match(await page.textContent('#id-initial-0 + .control-error'), /the initial value 2 is outside \[min, max\] = \[0, 1\]/);
  assert.deepEqual(consoleErrors, []);
});

test('more starts: the mirror optimum of w listed beside the estimate, the same bits as the CLI', async () => {
  await loadExample();
  await page.fill('#id-min-1', ''); // w ≥ 0 no more: w → −w is a mirror optimum
  await page.fill('#id-starts', 'w=-0.5\n\nr=0.9, w=0.2 # a second one');
  const result = await runIdentification('browser');
  assert.equal(result.optima.length, 2, JSON.stringify(result.optima));
  const [a, b] = result.optima;
  assert.ok(Math.abs(a.neg_log_likelihood - b.neg_log_likelihood) <= 1e-9, `J ${a.neg_log_likelihood} and ${b.neg_log_likelihood}`);
  assert.ok(Math.abs(a.params.w + b.params.w) <= 1e-6 && Math.abs(a.params.w) > 0.3, `w ${a.params.w} and ${b.params.w}`);
  assert.equal(a.neg_log_likelihood, result.neg_log_likelihood, 'the first is the estimate');
  assert.deepEqual([...a.starts, ...b.starts].sort(), [0, 1, 2], 'each start reached one of them');
  // The table: the estimate first, J, each param, the starts that reached each.
  const rows = await page.$$eval('#id-optima tbody tr', (trs) =>
    trs.map((tr) => ({
      head: tr.querySelector('th').textContent,
      estimate: tr.classList.contains('estimate'),
      J: Number(tr.querySelector('[data-key=neg_log_likelihood]').dataset.value),
      w: Number(tr.querySelector('[data-param=w]').dataset.value),
      starts: JSON.parse(tr.querySelector('[data-key=starts]').dataset.value),
      from: tr.querySelector('[data-key=starts]').textContent,
    })),
  );
  assert.deepEqual(rows.map((r) => [r.head, r.estimate]), [['the estimate', true], ['optimum 2', false]]);
  result.optima.forEach((o, i) => {
    assert.equal(rows[i].J, o.neg_log_likelihood);
    assert.equal(rows[i].w, o.params.w);
    assert.deepEqual(rows[i].starts, o.starts);
  });
  const names = (starts) => starts.map((i) => (i === 0 ? 'the initial values' : `start ${i}`)).join(', ');
  assert.deepEqual(rows.map((r) => r.from), result.optima.map((o) => names(o.starts)));
  assert.match(await page.textContent('#id-optima caption'), /^The 2 distinct optima/);
  await screenshot(page, '33-identification-optima');
  // The same bits through the CLI, the request's starts in its file (the CSV beside it).
  const dir = mkdtempSync(path.join(os.tmpdir(), 'kea-id-starts-'));
  try {
    const request = JSON.parse(readFileSync(path.join(ROOT, 'examples', 'identification', 'oscillator.json'), 'utf8'));
    request.estimate.w = { initial: 0.5 };
    request.starts = [{ w: -0.5 }, { r: 0.9, w: 0.2 }];
    writeFileSync(path.join(dir, 'starts.json'), JSON.stringify(request));
    writeFileSync(path.join(dir, 'oscillator.csv'), readFileSync(path.join(ROOT, 'examples', 'identification', 'oscillator.csv')));
    const cli = JSON.parse(kea('identify', path.join(dir, 'starts.json'), '--json'));
    assert.deepStrictEqual(bits(result), bits(cli), 'browser and CLI: the same bits');
  } finally {
    rmSync(dir, { recursive: true, force: true });
  }
  assert.deepEqual(consoleErrors, []);
});

test('a malformed start line is refused at its field before anything is sent', async () => {
  await loadExample();
  await page.evaluate(() => delete document.getElementById('id-result').dataset.where);
  await page.fill('#id-starts', 'w=0.4\nw 0.3');
  await page.check('input[name=id-where][value=browser]');
  await page.click('#id-run');
  await page.waitForFunction(() => document.getElementById('id-status').classList.contains('error'), null, { timeout: 30000 });
  assert.match(await page.textContent('#id-status'), /see the marked fields/);
  assert.equal(await page.getAttribute('#id-starts', 'aria-invalid'), 'true');
  assert.deepEqual(await page.$$eval('#id-starts ~ .control-error', (es) => es.map((e) => e.textContent)), ['line 2: “w 0.3” is not NAME=value (one start per line: r=0.5, …)']);
  assert.equal(await page.evaluate(() => document.getElementById('id-result').dataset.where), undefined, 'not run');
  // Re-checked as typed: a param not estimated, a decimal comma, then a good line.
  await page.fill('#id-starts', 'sw=0.3\nr=0,9');
  assert.deepEqual(await page.$$eval('#id-starts ~ .control-error', (es) => es.map((e) => e.textContent)), [
    'line 1: “sw” is not a param estimated here (estimated: r, w, sv)',
    'line 2, r: “0,9” — use a decimal point: 0.9',
  ]);
  await page.fill('#id-starts', 'r=0.9');
  assert.equal(await page.$('#id-starts ~ .control-error'), null);
  assert.equal(await page.getAttribute('#id-starts', 'aria-invalid'), null);
  await page.fill('#id-starts', '');
  assert.deepEqual(consoleErrors, []);
});

/** The example's oscillator, simulated for `steps` steps (a fixed stream: the same data every time), as CSV. */
function simulatedCsv(steps) {
  let seed = 12345;
  const uniform = () => ((seed = (seed * 1103515245 + 12345) % 2147483648) + 0.5) / 2147483648;
  const normal = () => Math.sqrt(-2 * Math.log(uniform())) * Math.cos(2 * Math.PI * uniform());
  const [r, w, sw, sv] = [0.96, 0.3, 0.3, 0.5];
  let [x, v] = [0, 0];
  const out = ['t,position_meas'];
  for (let k = 1; k <= steps; k++) {
    [x, v] = [r * Math.cos(w) * x + r * Math.sin(w) * v + sw * normal(), -r * Math.sin(w) * x + r * Math.cos(w) * v + sw * normal()];
    out.push(`${k},${x + sv * normal()}`);
  }
  return out.join('\n') + '\n';
}

test('Cancel stops a run, in the browser and on the server', async () => {
  const STEPS = 50000;
  const request = JSON.parse(readFileSync(path.join(ROOT, 'examples', 'identification', 'oscillator.json'), 'utf8'));
  const model = { ...request.model, time: { t0: 0, t_end: STEPS, steps: STEPS } };
  await importModel(page, model, 'long-oscillator.json');
  await page.click('#tab-identification');
  // A file chosen: read by the page (FileReader) into the data box.
  await page.setInputFiles('#id-data-file', { name: 'long.csv', mimeType: 'text/csv', buffer: Buffer.from(simulatedCsv(STEPS)) });
  await page.waitForFunction(() => /^long\.csv: 50,000 data rows × 2 columns \(t, position_meas\)/.test(document.getElementById('id-data-summary').textContent), null, { timeout: 30000 });
  for (const [i, initial] of [[0, '0.5'], [1, '0.9'], [2, '2']]) {
    await page.check(`#id-est-${i}`);
    await page.fill(`#id-initial-${i}`, initial);
    await page.fill(`#id-min-${i}`, '0');
  }
  await page.selectOption('#id-method', 'gradient');
  await page.fill('#id-max-iterations', '1000');
  for (const where of ['browser', 'server']) {
    await page.evaluate(() => delete document.getElementById('id-result').dataset.where);
    await page.check(`input[name=id-where][value=${where}]`);
    await page.click('#id-run');
    await page.waitForFunction(() => document.getElementById('id-progress').value > 0, null, { timeout: 60000 });
    await page.waitForTimeout(500);
    assert.equal(await page.isDisabled('#id-cancel'), false, `${where}: still running`);
    await page.click('#id-cancel');
    await page.waitForFunction(() => document.getElementById('id-status').textContent === 'Cancelled.', null, { timeout: 30000 });
    assert.equal(await page.isDisabled('#id-run'), false);
    assert.equal(await page.evaluate(() => document.getElementById('id-result').dataset.where), undefined, `${where}: no result`);
  }
  // The browser's worker was stopped and a new one runs the next request.
  await loadExample();
  const result = await runIdentification('browser');
  assert.ok(Math.abs(result.estimate.r.value - OPTIMUM.r) <= 1e-6);
  assert.deepEqual(consoleErrors, []);
});

test("a discrete model leaves the other tabs to say the core's error, and a continuous one the Identification tab", async () => {
  await loadExample();
  const error = /^Φ: a discrete-time model \(transition, Φ\) is read by the identification only; the analysis, the Monte Carlo and the synthesis need the continuous a/;
  await page.click('#tab-analysis');
  assert.match(await refusedRun(page), error);
  await page.click('#tab-monte-carlo');
  await page.fill('#mc-runs', '20');
  for (const prefix of ['mc', 'syn']) {
    await page.click(prefix === 'mc' ? '#tab-monte-carlo' : '#tab-synthesis');
    await page.check(`input[name=${prefix}-where][value=browser]`);
    await page.evaluate((p) => document.getElementById(`${p}-status`).classList.remove('error'), prefix);
    await page.click(`#${prefix}-run`);
    await page.waitForFunction((p) => document.getElementById(`${p}-status`).classList.contains('error'), prefix, { timeout: 30000 });
    assert.match(await page.textContent(`#${prefix}-status`), error, prefix);
    assert.match(await page.textContent(`#${prefix}-status`), /see the marked model fields$/, prefix);
  }
  // The editor shows it at Φ.
  const atPhi = await page.$$eval('[data-grid="system.transition"] .cell-error', (es) => es.map((e) => e.textContent));
  assert.ok(atPhi.some((t) => /identification only/.test(t)), JSON.stringify(atPhi));
  await screenshot(page, '32-identification-discrete-elsewhere');
  // A continuous model: the Identification tab says how it reads it, and its run the core's words.
  await page.selectOption('#preset', 'seed-example');
  await page.waitForFunction(() => /^#preset=seed-example(&|$)/.test(location.hash));
  await page.click('#tab-identification');
  assert.equal(await page.isVisible('#id-form-note'), true);
  assert.match(await page.textContent('#id-form-note'), /continuous/);
  await page.check('#id-est-0');
  await page.check('input[name=id-where][value=browser]');
  await page.click('#id-run');
  await page.waitForFunction(() => document.getElementById('id-status').classList.contains('error'), null, { timeout: 30000 });
  // (discretised, it fails the identification's need of entries constant in t: its Γ = c·v·t)
  assert.match(await page.textContent('#id-status'), /^g: the identification's model is time-invariant: its entries may depend on the params, not on t.* — see the marked model fields$/);
  assert.deepEqual(consoleErrors, []);
});

test("the editor keeps a discrete model's Φ through a resize, a rename and Undo", async () => {
  await loadExample();
  await page.fill('#dim-N', '3');
  await page.press('#dim-N', 'Enter');
  await page.waitForSelector('input[data-path="system.transition[2][2]"]');
  let model = await exportedModel(page);
  assert.equal(model.system.a, undefined, 'no a created');
  assert.deepEqual(model.system.transition, [['r*cos(w)', 'r*sin(w)', 0], ['-r*sin(w)', 'r*cos(w)', 0], [0, 0, 0]]);
  await page.click('#undo');
  await page.waitForSelector('input[data-path="system.transition[2][2]"]', { state: 'detached' });
  await page.fill('input[data-path="params.w.name"]', 'omega');
  await page.press('input[data-path="params.w.name"]', 'Tab');
  assert.equal(await page.inputValue('input[data-path="system.transition[1][0]"]'), '-r*sin(omega)');
  model = await exportedModel(page);
  assert.deepEqual(model.system.transition, [['r*cos(omega)', 'r*sin(omega)'], ['-r*sin(omega)', 'r*cos(omega)']]);
  // The tab's rows follow the params: omega, not estimated yet (w was).
  assert.deepEqual(await page.$$eval('#id-params tbody tr', (trs) => trs.map((tr) => tr.dataset.param)), ['r', 'omega', 'sv', 'sw']);
  // A Φ cell the core cannot read is marked at it as typed (the identification's check).
  await page.fill('input[data-path="system.transition[0][0]"]', 'r*cos(omega');
  await page.waitForSelector('td[data-path="system.transition[0][0]"] .cell-error', { timeout: 10000 });
  await page.fill('input[data-path="system.transition[0][0]"]', 'r*cos(omega)');
  await page.waitForSelector('td[data-path="system.transition[0][0]"] .cell-error', { state: 'detached', timeout: 10000 });
  assert.deepEqual(consoleErrors, []);
});

test("a script's identification job, with inline rows, opens in the tab from the Server tab", async () => {
  const example = JSON.parse(readFileSync(path.join(ROOT, 'examples', 'identification', 'oscillator.json'), 'utf8'));
  const csv = readFileSync(path.join(ROOT, 'examples', 'identification', 'oscillator.csv'), 'utf8').trim().split('\n').slice(1);
  const rows = csv.map((line) => line.split(',').map(Number));
  rows[2][1] = null; // a missing measurement
  const request = { kind: 'identification', model: example.model, data: { rows }, estimate: { r: { initial: 0.9, min: 0, max: 1 }, sv: {} }, method: 'conjugate', max_iterations: 200, starts: [{ r: 0.5, sv: 0.7 }] };
  const call = client(app.server.url);
  const submitted = await call('POST', '/v1/jobs', request);
  assert.equal(submitted.status, 202, JSON.stringify(submitted.json));
  const id = submitted.json.id;
  await page.click('#tab-jobs');
  await page.click('#jobs-refresh');
  await page.click(`#jobs-table tr[data-job="${id}"] .job-open`);
  await page.waitForFunction(() => /opened from the Server tab/.test(document.getElementById('id-status').textContent), null, { timeout: 60000 });
  assert.equal(await page.isVisible('#identification-panel'), true);
  // Its request in the fields: the rows as CSV text, the params, the method.
  const text = await page.inputValue('#id-data');
  assert.equal(text.split('\n')[0], 't,position_meas');
  assert.equal(text.split('\n')[3], '3,');
  assert.match(await page.textContent('#id-data-summary'), /1,000 data rows × 2 columns/);
  const estimated = await page.$$eval('#id-params tbody tr', (trs) =>
    trs.map((tr) => [tr.dataset.param, tr.querySelector('input[type=checkbox]').checked, ...[...tr.querySelectorAll('input:not([type=checkbox])')].map((i) => i.value)]),
  );
  // (The rows in the order of the model's params as the server stored them.)
  assert.deepEqual(Object.fromEntries(estimated.map(([name, ...rest]) => [name, rest])), {
    r: [true, '0.9', '0', '1'],
    w: [false, '', '', ''],
    sv: [true, '', '', ''],
    sw: [false, '', '', ''],
  });
  assert.equal(await page.inputValue('#id-method'), 'conjugate');
  assert.equal(await page.inputValue('#id-max-iterations'), '200');
  assert.equal(await page.inputValue('#id-starts'), 'r=0.5, sv=0.7');
  // Its result, as the server has it.
  const result = (await call('GET', `/v1/jobs/${id}/result`)).json;
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#id-download')]);
  assert.deepStrictEqual(JSON.parse(readFileSync(await download.path(), 'utf8')), result);
  assert.deepEqual(await page.$$eval('#id-estimates tbody tr', (trs) => trs.map((tr) => tr.dataset.param)), ['r', 'sv']);
  assert.equal(result.measurements, 999);
  assert.deepEqual(consoleErrors, []);
});

test("the tab's fields and data are kept over a reload, and the tab in the link", async () => {
  await loadExample();
  await page.selectOption('#id-method', 'conjugate');
  await page.fill('#id-max-iterations', '50');
  await page.fill('#id-max-2', '3'); // sv ≤ 3
  await page.fill('#id-starts', 'r=0.9, w=0.2\nsv=0.7');
  await page.waitForFunction(() => /&tab=identification$/.test(location.hash));
  const data = await page.inputValue('#id-data');
  await page.reload();
  await page.waitForSelector('body[data-ready=true]', { timeout: 30000 });
  assert.equal(await page.isVisible('#identification-panel'), true);
  assert.equal(await page.inputValue('#id-data'), data);
  assert.equal(await page.inputValue('#id-method'), 'conjugate');
  assert.equal(await page.inputValue('#id-max-iterations'), '50');
  assert.equal(await page.inputValue('#id-starts'), 'r=0.9, w=0.2\nsv=0.7');
  const rows = await page.$$eval('#id-params tbody tr', (trs) =>
    trs.map((tr) => [tr.dataset.param, tr.querySelector('input[type=checkbox]').checked, ...[...tr.querySelectorAll('input:not([type=checkbox])')].map((i) => i.value)]),
  );
  assert.deepEqual(rows, [
    ['r', true, '0.8', '0', '1'],
    ['w', true, '0.5', '0', ''],
    ['sv', true, '1', '0', '3'],
    ['sw', false, '', '', ''],
  ]);
  await page.waitForFunction(() => /read on the model’s grid/.test(document.getElementById('id-data-summary').textContent), null, { timeout: 30000 });
  assert.deepEqual(consoleErrors, []);
});
