// The Sensitivity tab in a real browser against the real server: on the editor's
// model, in this browser (wasm) and as a server job, its tornado and table show what
// `kea sensitivity` gives, bit for bit; a param the model lacks is marked at the field.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { choosePreset, kea, openApp } from './lib.mjs';

let app;
let page;
const consoleErrors = [];

before(async () => {
  app = await openApp(consoleErrors);
  ({ page } = app);
});

after(() => app?.close());

async function runIn(where) {
  await page.check(`input[name=sens-where][value=${where}]`);
  const before = await page.evaluate(() => document.querySelector('#sens-summary')?.textContent ?? '');
  await page.click('#sens-run');
  await page.waitForFunction(
    (b) => {
      const s = document.querySelector('#sens-summary');
      return s && s.textContent !== b && !document.querySelector('#sens-run').disabled;
    },
    before,
    { timeout: 60000 },
  );
}

/** The tornado's rows: [param, S] top to bottom, and the bars' widths (%). */
function tornado() {
  return page.evaluate(() =>
    [...document.querySelectorAll('#sens-tornado .tornado-row')].map((r) => ({
      param: r.dataset.param,
      s: r.dataset.value === '' ? null : Number(r.dataset.value),
      width: parseFloat(r.querySelector('.tornado-bar').style.width) || 0,
      negative: r.querySelector('.tornado-bar').classList.contains('negative'),
    })),
  );
}

test('the tornado shows kea sensitivity, in this browser and on the server', async () => {
  const cli = JSON.parse(kea('sensitivity', 'preset:helicopter-range', '--param', 'sd', '--param', 'sv', '--param', 'sv_f', '--rank-by', 'covariance.zx', '--json'));
  await choosePreset(page, 'helicopter-range');
  await page.click('#tab-sensitivity');
  await page.fill('#sens-params', 'sd, sv, sv_f');
  await page.selectOption('#sens-rank-by', 'covariance.zx');
  for (const where of ['browser', 'server']) {
    await runIn(where);
    const rows = await tornado();
    assert.deepEqual(rows.map((r) => r.param), cli.params.map((p) => p.name), `${where}: ranked as the CLI`);
    rows.forEach((r, i) => {
      assert.equal(r.s, cli.params[i].sensitivity.covariance.zx, `${where}: ${r.param}'s S, bit for bit`);
      assert.equal(r.negative, r.s < 0);
    });
    assert.ok(Math.abs(rows[0].width - 50) < 1e-9, `${where}: the largest |S| spans half the track`);
    assert.ok(rows.every((r, i) => i === 0 || r.width <= rows[i - 1].width));
  }
  // Another criterion re-ranks the chart.
  await page.selectOption('#sens-chart-criterion', 'covariance.yx');
  const yx = await tornado();
  const expected = [...cli.params].sort((a, b) => Math.abs(b.sensitivity.covariance.yx) - Math.abs(a.sensitivity.covariance.yx));
  assert.deepEqual(yx.map((r) => r.param), expected.map((p) => p.name));
  assert.deepEqual(consoleErrors, []);
});

test('a param the model does not have is marked at the field', async () => {
  await choosePreset(page, 'cv-tracker');
  await page.click('#tab-sensitivity');
  await page.fill('#sens-params', 'q, nope');
  await page.check('input[name=sens-where][value=browser]');
  await page.click('#sens-run');
  await page.waitForFunction(() => document.querySelector('#sens-status').classList.contains('error'), null, { timeout: 30000 });
  const text = await page.evaluate(() => document.querySelector('#sens-params').closest('.field, label, div').textContent);
  assert.match(text, /"nope" is not a param of the model/);
});
