// The Synthesis and Monte Carlo tabs in a real browser against the real server: a
// small grid and a bisection, and a small Monte Carlo, each run in the browser (wasm
// worker, the core's Sequential executor) and as a server job; the two must agree with
// each other and with the CLI (synthesis to 1e-9 relative; Monte Carlo bit-identical
// for the same seed, whatever the thread count).

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { holdJobs, kea, newPage, openApp, relDiff, screenshot } from './lib.mjs';

const STEPS = 2000; // small D: the grid's 7 analyses and 200 runs take well under a second

let server;
let browser;
let page;
let tmp;
const consoleErrors = [];

let app;

before(async () => {
  tmp = mkdtempSync(path.join(tmpdir(), 'kea-e2e-tabs-'));
  app = await openApp(consoleErrors);
  ({ server, browser, page } = app);
});

after(async () => {
  await app?.close();
  if (tmp) rmSync(tmp, { recursive: true, force: true });
});

function assertClose(actual, expected, what) {
  if (expected === null) {
    assert.equal(actual, null, what);
    return;
  }
  assert.ok(Number.isFinite(actual), `${what}: ${actual} is not a number`);
  assert.ok(relDiff(actual, expected) <= 1e-9, `${what}: ${actual} vs ${expected} (relative ${relDiff(actual, expected)})`);
}

/** The seed example with D = STEPS, as loaded in the editor; also written for the CLI. */
async function smallSeedExample() {
  await page.selectOption('#preset', 'seed-example');
  await page.waitForFunction(() => /^#preset=seed-example(&|$)/.test(location.hash));
  await page.fill('input[data-path="time.steps"]', String(STEPS));
  const model = JSON.parse(kea('preset', 'seed-example'));
  model.time.steps = STEPS;
  const file = path.join(tmp, 'seed-small.json');
  writeFileSync(file, JSON.stringify(model));
  return file;
}

/** Run a tab's request in `where` and wait for its result; returns the downloaded result JSON. */
async function runView(prefix, where) {
  await page.evaluate((p) => delete document.getElementById(`${p}-result`).dataset.where, prefix);
  await page.check(`input[name=${prefix}-where][value=${where}]`);
  await page.click(`#${prefix}-run`);
  await page.waitForFunction(
    ([p, w]) => document.getElementById(`${p}-result`).dataset.where === w && !document.getElementById(`${p}-run`).disabled,
    [prefix, where],
    { timeout: 60000 },
  );
  assert.match(await page.textContent(`#${prefix}-status`), where === 'browser' ? /browser, wasm/ : /server job/);
  const [download] = await Promise.all([page.waitForEvent('download'), page.click(`#${prefix}-download`)]);
  return JSON.parse(readFileSync(await download.path(), 'utf8'));
}

/** The grid's cells as shown: {index: {yz, zx, yx, meets, cheapest}}. */
function gridCells() {
  return page.$$eval('#syn-grid td[data-index]', (cells) =>
    Object.fromEntries(
      cells.map((c) => [
        c.dataset.index,
        {
          yz: c.dataset.yz === '' ? null : Number(c.dataset.yz),
          zx: c.dataset.zx === '' ? null : Number(c.dataset.zx),
          yx: c.dataset.yx === '' ? null : Number(c.dataset.yx),
          meets: c.dataset.meets === 'true',
          cheapest: c.classList.contains('cheapest'),
        },
      ]),
    ),
  );
}

test('the tabs switch with the mouse and the arrow keys', async () => {
  await page.click('#tab-synthesis');
  assert.equal(await page.getAttribute('#tab-synthesis', 'aria-selected'), 'true');
  assert.equal(await page.isVisible('#synthesis-panel'), true);
  assert.equal(await page.isVisible('#run'), false, "the analysis's Run button is hidden");
  await page.focus('#tab-synthesis');
  await page.keyboard.press('ArrowRight');
  assert.equal(await page.getAttribute('#tab-monte-carlo', 'aria-selected'), 'true');
  assert.equal(await page.evaluate(() => document.activeElement.id), 'tab-monte-carlo');
  assert.equal(await page.isVisible('#monte-carlo-panel'), true);
  assert.equal(await page.isVisible('#synthesis-panel'), false);
  await page.keyboard.press('Home');
  assert.equal(await page.getAttribute('#tab-analysis', 'aria-selected'), 'true');
  assert.equal(await page.isVisible('#run'), true);
});

test('the tab is kept in the link', async () => {
  await page.click('#tab-monte-carlo');
  await page.waitForFunction(() => /&tab=monte_carlo$/.test(location.hash));
  // A new page on that link opens on the Monte Carlo tab.
  const other = await page.context().newPage();
  await other.goto(page.url());
  await other.waitForSelector('body[data-ready=true]', { timeout: 30000 });
  assert.equal(await other.getAttribute('#tab-monte-carlo', 'aria-selected'), 'true');
  assert.equal(await other.isVisible('#monte-carlo-panel'), true);
  await other.close();
  // Back on Analysis, the link has no tab.
  await page.click('#tab-analysis');
  await page.waitForFunction(() => !location.hash.includes('tab='));
});

test('a synthesis grid gives the same table in the browser, on the server and in the CLI', async () => {
  const modelFile = await smallSeedExample();
  await page.click('#tab-synthesis');
  // The preset's example (a grid of f × c) is in the fields; each is set here all the
  // same (example.test.mjs checks the example, and the choices for a model of one's own).
  assert.deepEqual(
    await page.$$eval(['#syn-grid-param-0', '#syn-grid-param-1'].join(','), (s) => s.map((x) => x.value)),
    ['f', 'c'],
  );
  await page.selectOption('#syn-mode', 'grid');
  await page.selectOption('#syn-criterion', 'yx');
  await page.selectOption('#syn-criteria', 'bound');
  await page.selectOption('#syn-state', '');
  await page.fill('#syn-threshold', '10');
  await page.selectOption('#syn-grid-param-0', 'f');
  await page.fill('#syn-grid-values-0', '2, 4, 8');
  await page.selectOption('#syn-grid-cheaper-0', 'lower');
  await page.selectOption('#syn-grid-param-1', 'c');
  await page.fill('#syn-grid-values-1', '0.5, 0.25');
  await page.selectOption('#syn-grid-cheaper-1', '');
  await page.selectOption('#syn-grid-param-2', '');
  // The fields' reading is shown as it is typed: a decimal comma is seen to be two values.
  const count = () => page.textContent('#syn-grid-count');
  assert.equal(await count(), 'f: 3 values (2, 4, 8) × c: 2 values (0.5, 0.25) = 6 cells');
  await page.fill('#syn-grid-values-1', '0,5');
  assert.equal(await count(), 'f: 3 values (2, 4, 8) × c: 2 values (0, 5) = 6 cells');
  await page.fill('#syn-grid-values-1', '0.5; 0.25');
  assert.equal(await count(), 'f: 3 values (2, 4, 8) × c: 2 values (0.5, 0.25) = 6 cells');

  const fromBrowser = await runView('syn', 'browser');
  const inBrowser = await gridCells();
  await screenshot(page, '10-synthesis-grid-browser');
  const fromServer = await runView('syn', 'server');
  const onServer = await gridCells();
  await screenshot(page, '11-synthesis-grid-server');

  const request = {
    target: { criterion: 'yx', criteria: 'bound', threshold: 10 },
    mode: { grid: { params: [{ name: 'f', values: [2, 4, 8] }, { name: 'c', values: [0.5, 0.25] }], cost_order: [{ name: 'f', cheaper: 'lower' }] } },
  };
  const requestFile = path.join(tmp, 'grid.json');
  writeFileSync(requestFile, JSON.stringify(request));
  const cli = JSON.parse(kea('synthesize', requestFile, '--model', modelFile, '--json'));
  assert.equal(cli.status, 'found');
  assert.equal(cli.details.grid.cells.length, 6);

  for (const r of [fromBrowser, fromServer]) {
    assert.equal(r.status, 'found');
    assert.equal(r.analyses, 7, 'six cells and the re-analysed answer');
    assert.equal(r.steps, STEPS);
    assert.equal(r.message, cli.message);
  }
  for (const cell of cli.details.grid.cells) {
    const key = cell.index.join(',');
    for (const [name, shown] of [['browser', inBrowser[key]], ['server', onServer[key]]]) {
      assert.ok(shown, `${name} shows cell ${key}`);
      for (const c of ['yz', 'zx', 'yx']) assertClose(shown[c], cell.point[c], `${name} cell ${key} ${c}`);
      assert.equal(shown.meets, cell.point.meets, `${name} cell ${key} meets`);
      assert.equal(shown.meets, cell.point.yx >= 10, `cell ${key}: meets iff F_YX ≥ 10`);
    }
    for (const c of ['yz', 'zx', 'yx']) assertClose(inBrowser[key][c], onServer[key][c], `browser vs server cell ${key} ${c}`);
  }
  assert.equal(Object.keys(inBrowser).length, 6);
  // kea's criteria do not depend on c (docs/synthesis.md): the two columns are equal;
  // F_YX grows with f = φ/ψ, and f = 4 is the cheapest (lowest f) cell that meets 10.
  for (const i of [0, 1, 2]) assertClose(inBrowser[`${i},1`].yx, inBrowser[`${i},0`].yx, `row ${i}: F_YX does not depend on c`);
  assert.ok(inBrowser['0,0'].yx < 10 && inBrowser['1,0'].yx >= 10 && inBrowser['2,0'].yx > inBrowser['1,0'].yx);
  assert.deepEqual(
    Object.entries(inBrowser).filter(([, v]) => v.cheapest).map(([k]) => k),
    ['1,0'],
  );
  assert.deepEqual(cli.details.grid.cheapest, [1, 0]);
  assert.match(await page.textContent('#syn-cheapest'), /c = 0\.5, f = 4/);
  assert.match(await page.textContent('#syn-message'), /4 of 6 cells meet F_YX \(bound\) ≥ 10/);
  assert.equal(await page.getAttribute('#syn-analyses', 'data-value'), '7');
  // The answer is re-analysed: the verification row repeats it.
  const verified = await page.$eval('#syn-points tr[data-point=verified] td[data-criterion=yx]', (td) => Number(td.dataset.value));
  assertClose(verified, cli.answer.yx, 'verified F_YX');
  assert.doesNotMatch(await page.textContent('#syn-summary'), /kept from before/);

  // A server job resumed after a restart says how many of its analyses it kept (the
  // result's recalled_analyses; server/tests/http.rs restarts a server for real).
  await page.route('**/v1/jobs/*/result', async (route) => {
    const response = await route.fetch();
    await route.fulfill({ response, json: { ...(await response.json()), recalled_analyses: 3 } });
  });
  await runView('syn', 'server');
  await page.unroute('**/v1/jobs/*/result');
  assert.match(await page.textContent('#syn-summary'), /7 analyses \(3 of them kept from before a server restart\) of D/);
});

test('a bisection gives the same answer and verification in the browser and on the server', async () => {
  await page.selectOption('#syn-mode', 'bisect');
  await page.selectOption('#syn-bisect-param', 'f');
  await page.fill('#syn-bisect-low', '1');
  await page.fill('#syn-bisect-high', '10');
  await page.fill('#syn-threshold', '10');
  const inBrowser = await runView('syn', 'browser');
  await screenshot(page, '12-synthesis-bisect-browser');
  const onServer = await runView('syn', 'server');
  for (const r of [inBrowser, onServer]) {
    assert.equal(r.status, 'found');
    assert.equal(r.details.bisect.meets_side, 'high', 'a larger f = φ/ψ (a better sensor) meets');
    assert.ok(r.answer.yx >= 10 && r.verification.passed);
    assert.ok(r.verification.looser.yx < 10, 'the 1 % looser point misses');
    assertClose(r.verification.looser.params.f * 1.01, r.answer.params.f, 'the looser point is 1 % toward the missing side');
  }
  assert.equal(inBrowser.analyses, onServer.analyses);
  assertClose(inBrowser.answer.params.f, onServer.answer.params.f, 'f*');
  for (const c of ['yz', 'zx', 'yx']) {
    assertClose(inBrowser.answer[c], onServer.answer[c], `answer ${c}`);
    assertClose(inBrowser.verification.looser[c], onServer.verification.looser[c], `looser ${c}`);
  }
  // Shown: answer, re-analysed point and the looser one that misses.
  const rows = await page.$$eval('#syn-points tbody tr', (trs) => trs.map((tr) => [tr.dataset.point, tr.lastElementChild.textContent]));
  assert.deepEqual(rows, [
    ['answer', 'yes ✓'],
    ['verified', 'yes ✓'],
    ['looser', 'no'],
  ]);
  const shownF = await page.$eval('#syn-points tr[data-point=answer] td[data-param=f]', (td) => Number(td.dataset.value));
  assertClose(shownF, onServer.answer.params.f, 'shown f*');
  // The bracket reads low → high, whichever side meets.
  const [, lo, hi] = (await page.textContent('.syn-details summary')).match(/bracket \[([^,]+), ([^\]]+)\]/);
  assert.ok(Number(lo) < Number(hi), `bracket [${lo}, ${hi}]`);
});

/** Every value of the Monte Carlo criteria table: {`set.criterion.row`: value|null}. */
function mcCriteria() {
  return page.$$eval('#mc-criteria td[data-set]', (cells) =>
    Object.fromEntries(cells.map((c) => [`${c.dataset.set}.${c.dataset.criterion}.${c.dataset.row}`, c.dataset.value === '' ? null : Number(c.dataset.value)])),
  );
}

test('a Monte Carlo run is bit-identical in the browser, on the server and in the CLI', async () => {
  const modelFile = await smallSeedExample();
  await page.click('#tab-monte-carlo');
  await page.fill('#mc-runs', '200');
  await page.fill('#mc-seed', '7');
  await page.selectOption('#mc-truth', 'process');
  await page.selectOption('#mc-model-error', 'white');
  await page.fill('#mc-trace-points', '50');

  const inBrowser = await runView('mc', 'browser');
  const shownBrowser = await mcCriteria();
  await screenshot(page, '13-monte-carlo-browser');
  const onServer = await runView('mc', 'server');
  const shownServer = await mcCriteria();
  const cliCsv = path.join(tmp, 'monte-carlo.csv');
  const cli = JSON.parse(kea('monte-carlo', modelFile, '--runs', '200', '--seed', '7', '--trace-points', '50', '--json', '--csv', cliCsv));

  const strip = (r) => ({ ...r, timing: null });
  assert.deepStrictEqual(strip(inBrowser), strip(onServer), 'browser and server: bit-identical');
  assert.deepStrictEqual(strip(inBrowser), strip(cli), 'browser and CLI: bit-identical');
  assert.equal(inBrowser.steps, STEPS);
  assert.equal(inBrowser.traces.t.length, 50);
  assert.deepEqual(shownBrowser, shownServer);
  // The traces as CSV: the same text as the CLI's `--csv`.
  const [csv] = await Promise.all([page.waitForEvent('download'), page.click('#mc-download-csv')]);
  assert.match(csv.suggestedFilename(), /monte-carlo-traces\.csv$/);
  const text = readFileSync(await csv.path(), 'utf8');
  assert.equal(text, readFileSync(cliCsv, 'utf8'));
  assert.equal(text.trim().split('\n').length, 1 + 50, 'a header and one line per trace row');

  // The table shows the three sets of the result.
  for (const set of ['bound', 'covariance', 'monte_carlo']) {
    for (const c of ['yz', 'zx', 'yx']) {
      assert.equal(shownBrowser[`${set}.${c}.weighted`], inBrowser.criteria[set].weighted[c], `${set} ${c}`);
      assert.equal(shownBrowser[`${set}.${c}.0`], inBrowser.criteria[set].per_state[0][c], `${set} ${c} Y`);
    }
  }
  // Real against potential: with truth = process the covariance set is exact, and 200
  // runs estimate it within sampling error.
  const mc = inBrowser.criteria.monte_carlo.weighted;
  const cov = inBrowser.criteria.covariance.weighted;
  for (const c of ['yz', 'zx', 'yx']) assert.ok(relDiff(mc[c], cov[c]) < 0.1, `F_${c}: Monte Carlo ${mc[c]} vs covariance ${cov[c]}`);
  // Consistency: NEES, NIS and the state, with their bands and verdicts as computed.
  const c = inBrowser.consistency;
  const verdicts = await page.$$eval('#mc-consistency tbody tr', (trs) => trs.map((tr) => [tr.dataset.stat, tr.querySelector('[data-verdict]').dataset.verdict, Number(tr.querySelector('td[data-value]').dataset.value)]));
  assert.deepEqual(verdicts, [
    ['nees', c.nees.verdict, c.nees.time_average],
    ['nis', c.nis.verdict, c.nis.time_average],
    ['state-0', c.per_state[0].verdict, c.per_state[0].variance_ratio],
  ]);
  assert.equal(c.nees.verdict, 'consistent');
  assert.ok(c.nees.band[0] < c.nees.time_average && c.nees.time_average < c.nees.band[1]);
  // The plot: potential √R_ii, the sample SKO of the filtered error, and χ.
  const legend = await page.$$eval('#mc-chart .u-legend .u-series th', (ths) => ths.map((t) => t.textContent));
  for (const name of ['potential SKO √R_ii', 'sample SKO', 'bound χ']) {
    assert.ok(legend.some((l) => l.includes(name)), `legend ${legend} lacks ${name}`);
  }
  await page.check('#mc-log');
  await page.waitForSelector('#mc-chart .u-legend');
  await screenshot(page, '14-monte-carlo-server-log');
});

test('an invalid request is marked at its control; a model error at its cell', async () => {
  await page.fill('#mc-runs', '1');
  await page.check('input[name=mc-where][value=browser]');
  await page.click('#mc-run');
  await page.waitForFunction(() => document.querySelector('#mc-status').classList.contains('error'), null, { timeout: 30000 });
  // The message is at the field, without the request's path; the status points there.
  assert.match(await page.textContent('#mc-runs + .control-error'), /at least 2 runs/);
  assert.equal(await page.getAttribute('#mc-runs', 'aria-invalid'), 'true');
  assert.match(await page.textContent('#mc-status'), /see the marked fields/);
  assert.doesNotMatch(await page.textContent('#mc-status'), /runs:/);
  // One rule from the start: −5 gets the same words as 1 (not “must be ≥ 0”).
  await page.fill('#mc-runs', '-5');
  await page.click('#mc-run');
  await page.waitForFunction(() => /-5/.test(document.querySelector('#mc-runs + .control-error')?.textContent));
  assert.match(await page.textContent('#mc-runs + .control-error'), /^at least 2 runs are needed for sample SKOs, got -5$/);
  await page.fill('#mc-runs', '200'); // a fixed field is re-checked as it is typed: the mark goes
  assert.equal(await page.$('#mc-runs + .control-error'), null);
  assert.equal(await page.getAttribute('#mc-runs', 'aria-invalid'), null);
  // A seed above 2^53 − 1 is refused at the field, in words (not serde's "expected u64").
  await page.fill('#mc-seed', '1e20');
  await page.click('#mc-run');
  await page.waitForSelector('#mc-seed + .control-error');
  assert.match(await page.textContent('#mc-seed + .control-error'), /2\^53 − 1 = 9007199254740991/);
  assert.match(await page.textContent('#mc-status'), /see the marked fields/);
  await page.fill('#mc-seed', '7');
  assert.equal(await page.$('#mc-seed + .control-error'), null);

  await page.click('#tab-synthesis');
  await page.fill('input[data-path="system.a[0][0]"]', 's/m +* 1');
  await page.check('input[name=syn-where][value=server]');
  await page.click('#syn-run');
  await page.waitForFunction(() => document.querySelector('#syn-status').classList.contains('error'), null, { timeout: 30000 });
  assert.match(await page.textContent('#syn-status'), /marked model fields/);
  await page.waitForSelector('td[data-path="system.a[0][0]"] .cell-error');
  await screenshot(page, '15-synthesis-invalid-model');
  assert.ok(await page.$eval('#syn-result', (e) => e.classList.contains('stale')), 'the shown result is marked stale');
  await page.selectOption('#preset', 'seed-example');
  await page.waitForSelector('td[data-path="system.a[0][0]"] .cell-error', { state: 'detached', timeout: 10000 });
  // The run's error was about the model before: it goes with the change, as on the Analysis tab.
  await page.waitForFunction(() => !document.querySelector('#syn-status').classList.contains('error'), null, { timeout: 5000 });
  assert.equal(await page.textContent('#syn-status'), '');
});

test("a run's model error names the model's cell as the editor does, counting from 1, on both tabs", async () => {
  await page.selectOption('#preset', 'cv-tracker'); // t from 0 to 100
  await page.waitForFunction(() => /^#preset=cv-tracker(&|$)/.test(location.hash));
  // Finite at t₀ (the model is valid), not past t = 50: only a run finds it, at system.a[1][0].
  await page.fill('input[data-path="system.a[1][0]"]', '0*sqrt(50 - t)');
  await page.click('#tab-monte-carlo');
  await page.fill('#mc-runs', '20');
  await page.fill('#mc-trace-points', '');
  await page.click('#tab-synthesis');
  await page.selectOption('#syn-mode', 'grid');
  for (const [tab, prefix] of [['monte-carlo', 'mc'], ['synthesis', 'syn']]) {
    await page.click(`#tab-${tab}`);
    for (const where of ['browser', 'server']) {
      await page.check(`input[name=${prefix}-where][value=${where}]`);
      await page.evaluate((p) => document.getElementById(`${p}-status`).classList.remove('error'), prefix);
      await page.click(`#${prefix}-run`);
      await page.waitForFunction((p) => document.getElementById(`${p}-status`).classList.contains('error'), prefix, { timeout: 30000 });
      const status = await page.textContent(`#${prefix}-status`);
      assert.match(status, /^a \[2, 1\]: the expression is not finite here .*\(at step \d+, t = 50\.\d+\) — see the marked model fields$/, `${tab} in ${where}`);
      assert.doesNotMatch(status, /system\.|model\.|Invalid model/, `${tab} in ${where}`);
      await page.waitForSelector('td[data-path="system.a[1][0]"] .cell-error');
    }
  }
  // A grid value that makes the model invalid, beyond the 64 values checked here before
  // a request: the core's message quotes the model's error, at the place the editor names.
  await page.fill('input[data-path="system.a[1][0]"]', '0');
  await page.check('input[name=syn-where][value=browser]');
  await page.selectOption('#syn-grid-param-0', 'q');
  await page.fill('#syn-grid-values-0', [...Array.from({ length: 64 }, (_, i) => 1 + i / 64), -1].join(', '));
  await page.selectOption('#syn-grid-param-1', '');
  await page.selectOption('#syn-grid-param-2', '');
  await page.click('#syn-run');
  await page.waitForSelector('#syn-grid-values-0 + .control-error', { timeout: 30000 });
  const message = await page.textContent('#syn-grid-values-0 + .control-error');
  assert.match(message, /q = -1: φ \[1\]: an SKO must be ≥ 0/);
  assert.doesNotMatch(message, /system\.|model\./);
  await page.selectOption('#preset', 'seed-example');
  await page.waitForFunction(() => /^#preset=seed-example(&|$)/.test(location.hash));
});

test('synthesis inputs are refused at their control, in words', async () => {
  await smallSeedExample();
  await page.click('#tab-synthesis');
  const status = () => page.textContent('#syn-status');
  const runRefused = async () => {
    await page.evaluate(() => document.getElementById('syn-status').classList.remove('error'));
    await page.click('#syn-run');
    await page.waitForFunction(() => document.querySelector('#syn-status').classList.contains('error'), null, { timeout: 30000 });
  };
  // Unreadable, then refused by the core (low > high): at the field, no internal path.
  await page.check('input[name=syn-where][value=browser]'); // the server's refusal would log a 422
  await page.selectOption('#syn-mode', 'bisect');
  await page.selectOption('#syn-bisect-param', 'f');
  await page.fill('#syn-bisect-low', 'abc');
  await runRefused();
  assert.match(await page.textContent('#syn-bisect-low + .control-error'), /“abc” is not a number/);
  await page.fill('#syn-bisect-low', '20');
  assert.equal(await page.$('#syn-bisect-low + .control-error'), null, 'the fixed field is re-checked as it is typed');
  await page.fill('#syn-bisect-high', '10');
  await runRefused();
  // (Under load the status can say the refusal a moment before the field is marked.)
  await page.waitForSelector('#synthesis-panel .control-error');
  const shown = await page.$$eval('#synthesis-panel .control-error', (es) => es.map((e) => e.textContent));
  assert.equal(shown.length, 1, shown.join(' | '));
  assert.doesNotMatch(await status(), /mode\.bisect/);
  assert.match(await status(), /see the marked fields/);
  // A grid value that makes the model invalid (f = −1: a negative φ) is marked at the
  // grid's values, not at the model's φ cell.
  await page.selectOption('#syn-mode', 'grid');
  await page.selectOption('#syn-grid-param-0', 'f');
  await page.fill('#syn-grid-values-0', '2, -1');
  await page.selectOption('#syn-grid-param-1', '');
  await page.selectOption('#syn-grid-param-2', '');
  await page.selectOption('#syn-grid-cheaper-0', '');
  await runRefused();
  assert.match(await page.textContent('#syn-grid-values-0 + .control-error'), /f = -1 makes the model invalid: φ \[1\]: an SKO must be ≥ 0/);
  assert.equal(await page.$$eval('#editor .cell-error', (es) => es.length), 0, 'no model cell is marked');
  assert.doesNotMatch(await status(), /Invalid model/);
  await screenshot(page, '16-synthesis-override-error');
  // Without a cost order, the table's message names the control, not the API member.
  await page.fill('#syn-grid-values-0', '2, 4');
  await page.selectOption('#syn-criteria', 'bound');
  await page.fill('#syn-threshold', '10'); // f = 4 meets it
  await runView('syn', 'browser');
  assert.equal(await page.$$eval('#synthesis-panel .control-error', (es) => es.length), 0, 'the marks went');
  const message = await page.textContent('#syn-message');
  assert.match(message, /cost order/);
  assert.doesNotMatch(message, /cost_order/);
});

test('a result of a model edited during its run is shown as stale, on both tabs', async () => {
  await smallSeedExample();
  await page.click('#tab-monte-carlo');
  await page.fill('#mc-runs', '50');
  await page.fill('#mc-trace-points', '');
  for (const [tab, prefix] of [['monte-carlo', 'mc'], ['synthesis', 'syn']]) {
    await page.click(`#tab-${tab}`);
    const jobs = await holdJobs(page); // the edit comes while the run is under way
    const run = runView(prefix, 'server');
    await jobs.reached;
    await page.fill('input[data-path="params.c"]', tab === 'monte-carlo' ? '0.6' : '0.7');
    await jobs.release();
    await run;
    assert.ok(await page.$eval(`#${prefix}-result`, (e) => e.classList.contains('stale')), `${tab}: the result is marked stale`);
    assert.ok(await page.isVisible(`#${prefix}-result .stale-note`), tab);
  }
});

test('at 390 px wide a Monte Carlo result does not overflow sideways, and no number breaks', async () => {
  await smallSeedExample();
  await page.setViewportSize({ width: 390, height: 844 });
  try {
    await page.click('#tab-monte-carlo');
    await page.fill('#mc-runs', '50');
    await runView('mc', 'browser');
    const [scroll, inner] = await page.evaluate(() => [document.documentElement.scrollWidth, window.innerWidth]);
    assert.ok(scroll <= inner, `the page is ${scroll} px wide in a ${inner} px window`);
    // Every number cell is one line: "94.9 %" and "[1.2217, 2.9671]" do not wrap.
    const wrapped = await page.$$eval('#mc-result td.num', (cells) =>
      cells
        .filter((c) => {
          const text = document.createRange();
          text.selectNodeContents(c);
          return text.getBoundingClientRect().height > 1.5 * parseFloat(getComputedStyle(c).lineHeight);
        })
        .map((c) => c.textContent),
    );
    assert.deepEqual(wrapped, []);
    await screenshot(page, '17-monte-carlo-narrow');
  } finally {
    await page.setViewportSize({ width: 1440, height: 900 });
  }
});

test('a Monte Carlo of a model with no trace points says so instead of a chart', async () => {
  await page.click('#tab-monte-carlo');
  await page.fill('#mc-runs', '50');
  await page.fill('#mc-trace-points', '');
  await page.fill('input[data-path="options.trace_points"]', '0');
  await runView('mc', 'browser');
  assert.match(await page.textContent('#mc-chart'), /No trace points requested/);
  await page.fill('input[data-path="options.trace_points"]', '1000');
});

test('a long Monte Carlo run is cancelled, in the browser and on the server', async () => {
  await page.selectOption('#preset', 'seed-example');
  await page.waitForFunction(() => /^#preset=seed-example(&|$)/.test(location.hash));
  await page.fill('input[data-path="time.steps"]', '100000');
  await page.click('#tab-monte-carlo');
  await page.fill('#mc-runs', '20000'); // 2e9 runs × steps: many seconds on either side; a chunk of 256 steps is quick
  for (const where of ['browser', 'server']) {
    await page.evaluate(() => (document.getElementById('mc-progress').value = 0));
    await page.check(`input[name=mc-where][value=${where}]`);
    await page.click('#mc-run');
    await page.waitForFunction(() => document.getElementById('mc-progress').value > 0, null, { timeout: 30000 });
    assert.ok(await page.$eval('#mc-progress', (p) => p.value < 1));
    const start = Date.now();
    await page.keyboard.press('Escape');
    await page.waitForFunction(() => document.getElementById('mc-status').textContent === 'Cancelled.', null, { timeout: 10000 });
    assert.ok(Date.now() - start < 5000, `${where}: cancelling took under 5 s`);
    assert.equal(await page.isDisabled('#mc-run'), false);
  }
  const jobs = await (await fetch(`${server.url}/v1/jobs`)).json();
  const items = jobs.items ?? jobs.jobs ?? jobs;
  assert.ok(items.some((j) => j.kind === 'monte_carlo' && j.status === 'cancelled'), JSON.stringify(items).slice(0, 500));
});

test("the Synthesis and Monte Carlo tabs' fields are kept over a reload; stored values that do not fit are not", async () => {
  const errors = [];
  const other = await newPage(browser, errors); // a browser tab of its own: its own storage
  const ready = () => other.waitForSelector('body[data-ready=true]', { timeout: 30000 });
  // Every request field of the two tabs, by id.
  const fields = () =>
    other.$$eval('#synthesis-panel form :is(input, select), #monte-carlo-panel form :is(input, select)', (cs) => Object.fromEntries(cs.map((c) => [c.id, c.value])));
  try {
    await other.goto(`${server.url}/#preset=seed-example&tab=synthesis`);
    await ready();
    const defaults = await fields();
    await other.selectOption('#syn-criterion', 'zx');
    await other.selectOption('#syn-criteria', 'covariance');
    await other.fill('#syn-threshold', '3.5');
    await other.selectOption('#syn-grid-param-1', 'c'); // a grid row, kept though another mode is shown
    await other.fill('#syn-grid-values-1', '0.1, 0.2');
    await other.selectOption('#syn-mode', 'bisect');
    await other.selectOption('#syn-bisect-param', 'c'); // not the default (f)
    await other.fill('#syn-bisect-low', '0.5');
    await other.fill('#syn-bisect-high', '40');
    await other.fill('#syn-bisect-probes', '5');
    await other.click('#tab-monte-carlo');
    await other.fill('#mc-runs', '321');
    await other.fill('#mc-seed', '42');
    await other.selectOption('#mc-truth', 'mean');
    await other.selectOption('#mc-model-error', 'constant');
    await other.fill('#mc-trace-points', '77');
    const filled = await fields();
    assert.equal(filled['syn-bisect-param'], 'c');
    assert.notDeepEqual(filled, defaults);

    await other.reload();
    await ready();
    assert.deepEqual(await fields(), filled, 'every field is back');
    await other.click('#tab-synthesis');
    assert.ok(await other.isVisible('#syn-bisect-low'), "the kept mode's fields are shown");
    assert.equal(await other.isVisible('#syn-grid-values-0'), false);
    await other.selectOption('#syn-mode', 'grid');
    assert.match(await other.textContent('#syn-grid-count'), /c: 2 values \(0\.1, 0\.2\)/);

    // Stored values the page cannot take leave the defaults: text that is not JSON, a
    // mode and a param that do not exist (the param's values go with it), a number where
    // text is kept. What fits is still taken.
    await other.evaluate(() => {
      sessionStorage.setItem('kea-monte-carlo', '{not json');
      sessionStorage.setItem('kea-synthesis', JSON.stringify({
        'syn-criterion': 'yz', 'syn-mode': 'nope', 'syn-threshold': 7,
        'syn-bisect-param': 'no_such_param', 'syn-bisect-low': '1', 'syn-bisect-high': '2',
      }));
    });
    await other.reload();
    await ready();
    assert.deepEqual(await fields(), { ...defaults, 'syn-criterion': 'yz' });
    await other.evaluate(() => sessionStorage.setItem('kea-synthesis', '[1, 2]'));
    await other.reload();
    await ready();
    assert.deepEqual(await fields(), defaults);
  } finally {
    await other.context().close();
  }
  assert.deepEqual(errors, []);
});

test('the page logged no console errors', () => {
  assert.deepEqual(consoleErrors, []);
});
