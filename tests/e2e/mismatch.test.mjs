// The mismatched filter in the page, in a real browser against the real server: a
// truth typed beside Run (NAME=VALUE) gives, in this browser and on the server, the
// table and chart of believed, actual and optimal SKOs that `kea analyze --truth-set`
// gives; a malformed truth is refused before a run. In the Monte Carlo tab, truth
// params make the runs imitate the truth: the actual SKO is drawn beside the sample one
// and judged against it, as `kea monte-carlo --truth-set` judges it.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { choosePreset, kea, openApp, runAnalysis, runMonteCarlo } from './lib.mjs';

let app;
let page;
const consoleErrors = [];

before(async () => {
  app = await openApp(consoleErrors);
  ({ page } = app);
});

after(() => app?.close());


test('a truth beside Run shows believed, actual and optimal SKOs as the CLI gives them', async () => {
  const cli = JSON.parse(kea('analyze', 'preset:helicopter-range', '--truth-set', 'sd=10', '--truth-set', 'f_f=0.3', '--json'));
  await choosePreset(page, 'helicopter-range');
  await page.fill('#run-truth', 'sd=10, f_f=0.3');
  for (const where of ['browser', 'server']) {
    await runAnalysis(page, where);
    const rows = await page.evaluate(() =>
      [...document.querySelectorAll('#mismatch-table tbody tr')].map((tr) => [tr.dataset.state, ...[...tr.querySelectorAll('td')].map((td) => td.textContent)]),
    );
    assert.equal(rows.length, 6, where);
    const fmt = (x) => (Math.abs(x) >= 1e-3 && Math.abs(x) < 1e6 ? Number(x.toPrecision(5)).toString() : x === 0 ? '0' : x.toExponential(4));
    cli.mismatch.states.forEach((s, i) => {
      assert.equal(rows[i][0], s.state);
      assert.equal(rows[i][1], fmt(s.actual_sko), `${where} ${s.state} actual`);
      assert.equal(rows[i][2], fmt(s.believed_sko), `${where} ${s.state} believed`);
      assert.equal(rows[i][3], fmt(s.optimal_sko), `${where} ${s.state} optimal`);
    });
    assert.match(await page.textContent('#mismatch-table caption'), /differs in structure/);
    assert.equal(await page.locator('#mismatch-chart .uplot').count(), 1, `${where}: the chart`);
  }
  // Without a truth the section goes.
  await page.fill('#run-truth', '');
  await runAnalysis(page, 'browser');
  assert.equal(await page.isHidden('#mismatch'), true);
  assert.deepEqual(consoleErrors, []);
});

test('a malformed truth is refused before a run', async () => {
  await choosePreset(page, 'cv-tracker');
  await page.fill('#run-truth', 'q=abc');
  await page.click('#run');
  await page.waitForFunction(() => document.querySelector('#status').classList.contains('error'));
  assert.match(await page.textContent('#status'), /Truth: expected NAME=VALUE \(such as sd=10\), got "q=abc"/);
  await page.fill('#run-truth', '');
});

test('Monte Carlo truth params judge the sample against the actual SKO as the CLI does', async () => {
  const cli = JSON.parse(kea('monte-carlo', 'preset:helicopter-range', '--runs', '200', '--truth-set', 'sd=10', '--truth-set', 'f_f=0.3', '--json'));
  await choosePreset(page, 'helicopter-range');
  await page.click('#tab-monte-carlo');
  await page.fill('#mc-runs', '200');
  await page.fill('#mc-seed', '1');
  await page.fill('#mc-truth-set', 'sd=10, f_f=0.3');
  for (const where of ['browser', 'server']) {
    await runMonteCarlo(page, where);
    const rows = await page.evaluate(() =>
      [...document.querySelectorAll('#mc-consistency tr[data-stat^="actual-"]')].map((tr) => [tr.querySelector('td.num').dataset.value, tr.querySelector('[data-verdict]').dataset.verdict]),
    );
    assert.equal(rows.length, 6, where);
    cli.consistency.per_state_actual.forEach((s, i) => {
      assert.equal(Number(rows[i][0]), s.variance_ratio, `${where} ${s.state}: the same bits`);
      assert.equal(rows[i][1], s.verdict, `${where} ${s.state}`);
    });
    // The believed SKO is optimistic for the range: the sample is judged against both.
    assert.equal(await page.getAttribute('#mc-consistency tr[data-stat="state-0"] [data-verdict]', 'data-verdict'), 'optimistic');
    assert.equal(await page.getAttribute('#mc-consistency tr[data-stat="actual-0"] [data-verdict]', 'data-verdict'), 'consistent');
    assert.match(await page.textContent('#mc-chart'), /actual SKO \(the model’s filter in the truth\)/, where);
  }
  // Truth params with the mean reading are refused before a run, at the field.
  await page.selectOption('#mc-truth', 'mean');
  await page.click('#mc-run');
  await page.waitForFunction(() => document.querySelector('#mc-status').classList.contains('error'));
  assert.match(await page.textContent('#mc-status'), /see the marked fields/);
  assert.match(await page.textContent('#mc-truth ~ .control-error'), /choose Truth = process/);
  await page.selectOption('#mc-truth', 'process');
  await page.fill('#mc-truth-set', '');
  await page.click('#tab-analysis');
  assert.deepEqual(consoleErrors, []);
});
