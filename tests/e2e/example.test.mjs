// A preset brings its synthesis example (presets/synthesis/NAME.json) into the
// Synthesis tab's fields when it is loaded — from the picker or a `#preset=` link —
// and the browser's run of it gives the CLI's answer (`kea synthesize --preset NAME`).
// A model of one's own keeps the generic choices; edits to the fields survive a reload.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { kea, newPage, openApp, relDiff } from './lib.mjs';

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

/** The Synthesis tab's request fields, by id (without the `syn-` prefix). */
function fields(p = page) {
  return p.$$eval('#synthesis-panel form :is(input, select)', (cs) => Object.fromEntries(cs.map((c) => [c.id.replace(/^syn-/, ''), c.value])));
}

async function choosePreset(name) {
  await page.selectOption('#preset', name);
  await page.waitForFunction((n) => location.hash.startsWith(`#preset=${n}`), name);
}

test("a preset chosen in the picker fills the Synthesis tab with its example, and the browser's run finds the CLI's answer", async () => {
  await choosePreset('cv-tracker');
  await page.click('#tab-synthesis');
  const f = await fields();
  assert.deepEqual(
    [f.criterion, f.criteria, f.state, f.threshold, f.mode, f['bisect-param'], f['bisect-low'], f['bisect-high'], f['bisect-rel-tol'], f['bisect-probes']],
    ['yx', 'covariance', 'position', '300', 'bisect', 'r', '0.05', '5', '0.001', '9'],
  );
  assert.ok(await page.isVisible('#syn-bisect-low'), "the example's mode is shown");
  assert.match(await page.textContent('#syn-example'), /Example for preset cv-tracker/);
  assert.ok(await page.isVisible('#syn-example'));

  await page.check('input[name=syn-where][value=browser]');
  await page.click('#syn-run');
  await page.waitForFunction(() => document.getElementById('syn-result').dataset.status === 'found', null, { timeout: 60000 });
  assert.match(await page.textContent('#syn-message'), /r = 1\.20/);
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#syn-download')]);
  const shown = JSON.parse(readFileSync(await download.path(), 'utf8'));
  const cli = JSON.parse(kea('synthesize', '--preset', 'cv-tracker', '--json'));
  assert.ok(relDiff(shown.answer.params.r, cli.answer.params.r) <= 1e-9, `r = ${shown.answer.params.r} vs the CLI's ${cli.answer.params.r}`);
  assert.equal(shown.analyses, cli.analyses);
  assert.equal(shown.message, cli.message);

  // A change to a field: the note no longer says the fields are the example.
  await page.fill('#syn-threshold', '250');
  assert.equal(await page.isVisible('#syn-example'), false);
});

test('a #preset= link opens on its example (a grid); edits survive a reload, the next preset brings its own', async () => {
  const errors = [];
  const other = await newPage(app.browser, errors); // a browser tab of its own: its own storage
  const ready = () => other.waitForSelector('body[data-ready=true]', { timeout: 30000 });
  try {
    await other.goto(`${app.server.url}/#preset=helicopter-range&tab=synthesis`);
    await ready();
    const f = await fields(other);
    assert.deepEqual(
      [f.criterion, f.criteria, f.state, f.threshold, f.mode],
      ['yx', 'covariance', '', '40', 'grid'],
    );
    assert.deepEqual(
      [0, 1, 2].map((i) => [f[`grid-param-${i}`], f[`grid-values-${i}`], f[`grid-cheaper-${i}`]]),
      [['sd', '2.5, 5, 10', 'higher'], ['sv', '0.25, 0.5, 1', 'higher'], ['', '', '']],
    );
    assert.equal(await other.textContent('#syn-grid-count'), 'sd: 3 values (2.5, 5, 10) × sv: 3 values (0.25, 0.5, 1) = 9 cells');
    assert.match(await other.textContent('#syn-example'), /Example for preset helicopter-range/);

    // Reloaded as it is, the example and its note stay.
    await other.reload();
    await ready();
    assert.deepEqual(await fields(other), f);
    assert.ok(await other.isVisible('#syn-example'));

    // The person's edits are kept over a reload: the example does not overwrite them.
    await other.fill('#syn-threshold', '35');
    await other.fill('#syn-grid-values-1', '0.5, 1');
    const edited = await fields(other);
    await other.reload();
    await ready();
    assert.deepEqual(await fields(other), edited);
    assert.equal(await other.isVisible('#syn-example'), false, 'the fields are no longer the example');

    // Another preset, freshly loaded: its example replaces the edits.
    await other.selectOption('#preset', 'cv-tracker');
    await other.waitForFunction(() => location.hash.startsWith('#preset=cv-tracker'));
    const g = await fields(other);
    assert.deepEqual([g.criteria, g.state, g.threshold, g.mode, g['bisect-param']], ['covariance', 'position', '300', 'bisect', 'r']);
    assert.match(await other.textContent('#syn-example'), /Example for preset cv-tracker/);
  } finally {
    await other.context().close();
  }
  assert.deepEqual(errors, []);
});

test('a model of your own (imported) keeps the generic choices: the params the error levels use', async () => {
  await page.click('#tab-synthesis');
  const model = kea('preset', 'seed-example');
  await page.setInputFiles('#import-model', { name: 'mine.json', mimeType: 'application/json', buffer: Buffer.from(model) });
  await page.waitForFunction(() => document.getElementById('page-status').textContent.startsWith('Imported'));
  // The params that the error levels use come first: f for the seed example. psi,
  // in both φ = f*psi and ψ, scales the two together, which no criterion sees (a grid
  // on it had identical rows): it comes last, and the next param (m) is the second.
  const f = await fields();
  assert.deepEqual([f['grid-param-0'], f['grid-param-1'], f['bisect-param'], f['seed-param-0']], ['f', 'm', 'f', 'f']);
  assert.equal(await page.isVisible('#syn-example'), false, 'no example for a model of your own');
  // The preset itself brings its example instead (f × c).
  await choosePreset('seed-example');
  const g = await fields();
  assert.deepEqual(
    [g.criteria, g.threshold, g.mode, g['grid-param-0'], g['grid-values-0'], g['grid-cheaper-0'], g['grid-param-1'], g['grid-values-1'], g['grid-cheaper-1']],
    ['bound', '14', 'grid', 'f', '2, 4, 8', 'lower', 'c', '0.5, 0.25, 0.125', 'higher'],
  );
});

test('the page logged no console errors', () => {
  assert.deepEqual(consoleErrors, []);
});
