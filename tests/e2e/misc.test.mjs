// The page's ways in and out, in a real browser against the real server: an imported
// file and a link read as strictly as the core reads JSON; a run in the browser above
// the server's work limit asks first, and its progress says how far and how long; a
// server that does not answer is named as such; an edit survives a reload at once;
// an import can be undone with Back; the results' tables say they scroll in a narrow
// window; the name alone leaves results current; file names and durations read well.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { deflateRawSync } from 'node:zlib';
import { kea, newPage, openApp, startServer } from './lib.mjs';

let server;
let browser;
let page;
const consoleErrors = [];

let app;

before(async () => {
  app = await openApp(consoleErrors);
  ({ server, browser, page } = app);
});

after(() => app?.close());

function ready(p = page) {
  return p.waitForSelector('body[data-ready=true]', { timeout: 30000 });
}

/** Open `hash` on a fresh load of the page. */
async function open(hash, p = page) {
  await p.goto('about:blank');
  await p.goto(`${server.url}/${hash}`);
  await ready(p);
}

/** Import a file of `text` named `name` with the page's Import button; resolves to the page's message. */
async function importText(name, text) {
  await page.evaluate(() => (document.getElementById('page-status').textContent = ''));
  await page.setInputFiles('#import-model', { name, mimeType: 'application/json', buffer: Buffer.from(text) });
  await page.waitForFunction(() => document.getElementById('page-status').textContent !== '', null, { timeout: 20000 });
  return page.textContent('#page-status');
}

/** A model of N = 30 states with D = 10⁸ steps and a(t): 4.2e12 units of work, above a server's 1e12. */
function hugeModel() {
  const N = 30;
  const range = [...Array(N).keys()];
  const a = range.map((i) => range.map((j) => (i === j ? -1 - 0.01 * i : j === i + 1 ? '0.5 + 0.1*sin(t)' : 0)));
  const eye = range.map((i) => range.map((j) => (i === j ? 1 : 0)));
  return {
    kea_model: 1,
    name: 'chain N = 30',
    params: { q: 1, r: 0.5 },
    time: { t0: 0, t_end: 10, steps: 100000000 },
    system: { states: range.map((i) => `x${i + 1}`), a, b: eye, y0: Array(N).fill(1), eta0: Array(N).fill(1), phi: Array(N).fill('q') },
    measurement: { names: range.map((i) => `z${i + 1}`), c: eye, gamma: eye, psi: Array(N).fill('r') },
    criteria: { confidence: 0.95 },
  };
}

test('an imported file with a key given twice, or 1e400, is refused in the core’s words', async () => {
  await open('#preset=seed-example');
  const seed = kea('preset', 'seed-example');
  const twice = seed.replace('"steps": 1000000', '"steps": 1000000, "steps": 10');
  assert.notEqual(twice, seed);
  const said = await importText('twice.json', twice);
  assert.match(said, /^twice\.json is not JSON \(the key "steps" appears twice in one object at line \d+ column \d+\); the model is unchanged\.$/);
  assert.equal(await page.inputValue('input[data-path="time.steps"]'), '1000000');

  const huge = seed.replace(/"t_end": [^,]+/, '"t_end": 1e400');
  assert.match(await importText('huge.json', huge), /huge\.json is not JSON \(number out of range at line \d+ column \d+\)/);
  assert.equal(await page.inputValue('input[data-path="time.t_end"]'), '10');

  // A byte-order mark (Windows editors write one) is fine, as everywhere else.
  const bom = JSON.parse(seed);
  bom.params.c = 0.25;
  assert.match(await importText('bom.json', `\ufeff${JSON.stringify(bom)}`), /^Imported bom\.json/);
  assert.equal(await page.inputValue('input[data-path="params.c"]'), '0.25');
  // The params keep the file's order (the core's reader would sort them).
  const order = await page.$$eval('input[data-path^="params."]:not([data-path$=".name"])', (inputs) => inputs.map((i) => i.dataset.path.slice('params.'.length)));
  assert.deepEqual(order, Object.keys(bom.params));
});

test('a link whose model has a key twice is not read either', async () => {
  const twice = kea('preset', 'cv-tracker').replace('"kea_model": 1,', '"kea_model": 1, "kea_model": 1,');
  await open(`#model=${deflateRawSync(twice).toString('base64url')}`);
  assert.match(await page.textContent('#page-status'), /could not be read.*the key "kea_model" appears twice in one object at line 2/);
});

test('a browser run above the server’s work limit asks first; its progress says 0.01 % and the time left', async () => {
  await open('#preset=seed-example');
  assert.match(await importText('huge.json', JSON.stringify(hugeModel())), /^Imported/);
  await page.check('input[name=mode][value=browser]');
  await page.click('#run');
  await page.waitForFunction(() => document.getElementById('status').textContent.includes('estimated work'), null, { timeout: 20000 });
  const said = await page.textContent('#status');
  assert.match(said, /estimated work is 4\.\d{3}e12 \(D = 100000000 steps × .*\), above 1\.000e12, where this kea server refuses a run/);
  assert.match(said, /may take \d+ h( \d+ min)? or more/, 'the time it may take');
  assert.equal(await page.isVisible('#run-anyway'), true);
  assert.equal(await page.isDisabled('#run'), false, 'nothing runs');
  assert.equal(await page.$eval('#progress', (p) => p.value), 0);

  await page.click('#run-anyway');
  assert.equal(await page.isVisible('#run-anyway'), false);
  await page.waitForFunction(() => /^Running in this browser… \d+\.\d\d %/.test(document.getElementById('status').textContent), null, { timeout: 20000 });
  await page.waitForFunction(() => /about (\d+ h( \d+ min)?|\d+ min) left$/.test(document.getElementById('status').textContent), null, { timeout: 20000 });
  await page.click('#cancel');
  await page.waitForFunction(() => document.getElementById('status').textContent === 'Cancelled.');

  // A synthesis of many such analyses asks the same, in its own run bar.
  await page.click('#tab-synthesis');
  await page.selectOption('#syn-mode', 'bisect');
  await page.check('input[name=syn-where][value=browser]');
  await page.click('#syn-run');
  await page.waitForFunction(() => document.getElementById('syn-status').textContent.includes('estimated work'), null, { timeout: 20000 });
  assert.match(await page.textContent('#syn-status'), /at most \d+ analyses × D = 100000000 steps/);
  assert.equal(await page.isVisible('#syn-run-anyway'), true);
  assert.equal(await page.isDisabled('#syn-run'), false);
  // An edit of the model takes the question back: it was about the model before.
  await page.fill('input[data-path="time.steps"]', '1000');
  await page.waitForFunction(() => document.getElementById('syn-status').textContent === '');
  assert.equal(await page.isVisible('#syn-run-anyway'), false);
  await page.click('#tab-analysis');
});

test('a browser run asks at this server’s own --max-work (GET /v1/limits)', async () => {
  const other = await startServer(['--max-work', '1e9']);
  const errors = [];
  const p = await newPage(browser, errors);
  try {
    await p.goto(`${other.url}/#preset=seed-example`);
    await ready(p);
    await p.fill('input[data-path="time.steps"]', '10000000');
    await p.check('input[name=mode][value=browser]');
    await p.click('#run');
    await p.waitForFunction(() => document.getElementById('status').textContent.includes('estimated work'), null, { timeout: 20000 });
    assert.match(await p.textContent('#status'), /estimated work is 2\.\d{3}e9 .*, above 1\.000e9, where this kea server refuses a run/);
    assert.equal(await p.isVisible('#run-anyway'), true);
    assert.deepEqual(errors, []);
  } finally {
    await p.close();
    await other.stop();
  }
});

test('a run on a server that does not answer says so, on each tab', async () => {
  const other = await startServer();
  const errors = [];
  const p = await newPage(browser, errors);
  try {
    await p.goto(`${other.url}/#preset=cv-tracker`);
    await ready(p);
    await other.stop();
    const unanswered = /^The kea server does not answer \(.+\); run in this browser, or try again\.$/;
    await p.check('input[name=mode][value=server]');
    await p.click('#run');
    await p.waitForFunction(() => document.getElementById('status').classList.contains('error'), null, { timeout: 20000 });
    assert.match(await p.textContent('#status'), unanswered);
    for (const [tab, prefix] of [['synthesis', 'syn'], ['monte-carlo', 'mc']]) {
      await p.click(`#tab-${tab}`);
      await p.check(`input[name=${prefix}-where][value=server]`);
      await p.click(`#${prefix}-run`);
      await p.waitForFunction((x) => document.getElementById(`${x}-status`).classList.contains('error'), prefix, { timeout: 20000 });
      assert.match(await p.textContent(`#${prefix}-status`), unanswered);
    }
  } finally {
    await p.context().close();
  }
});

test('an edit made just before a reload is still there after it; another link is not overridden', async () => {
  await open('#preset=cv-tracker');
  await page.fill('input[data-path="params.r"]', '7');
  await page.reload(); // well within the 300 ms the address waits
  await ready();
  assert.equal(await page.inputValue('input[data-path="params.r"]'), '7');
  await page.waitForFunction(() => location.hash.startsWith('#model='));
  // A preset chosen just before the reload, too.
  await page.selectOption('#preset', 'seed-example');
  await page.waitForFunction(() => document.getElementById('preset').value === 'seed-example');
  await page.selectOption('#preset', 'helicopter-hover');
  await page.waitForFunction(() => document.getElementById('f-name').value.includes('hover'));
  await page.reload();
  await ready();
  assert.equal(await page.inputValue('#preset'), 'helicopter-hover');
  await page.waitForFunction(() => location.hash === '#preset=helicopter-hover'); // the address caught up
  // The kept change belongs to its address: the page left and opened again on it has
  // the change; opened on another link, that link as it is.
  await page.fill('input[data-path="time.steps"]', '123');
  await open('#preset=helicopter-hover');
  assert.equal(await page.inputValue('input[data-path="time.steps"]'), '123');
  await page.fill('input[data-path="time.steps"]', '456');
  await open('#preset=cv-tracker');
  assert.equal(await page.inputValue('#preset'), 'cv-tracker');
  assert.equal(await page.evaluate(() => sessionStorage.getItem('kea-draft')), null);
});

test('importing a file over an edited model leaves it one Back away, as choosing a preset does', async () => {
  await open('#preset=cv-tracker');
  await page.fill('input[data-path="params.q"]', '42');
  const said = await importText('seed.json', kea('preset', 'seed-example'));
  assert.match(said, /^Imported seed\.json; Undo or the browser’s Back brings your model back\.$/);
  assert.equal(await page.$('input[data-path="params.q"]'), null);
  await page.goBack();
  await page.waitForFunction(() => document.querySelector('input[data-path="params.q"]')?.value === '42', null, { timeout: 10000 });
  await page.goForward();
  await page.waitForFunction(() => document.querySelector('input[data-path="params.m_g"]') !== null, null, { timeout: 10000 });
});

test('on a 390 px wide screen the criteria table says it scrolls sideways, as the editor grids do', async () => {
  const errors = [];
  const p = await newPage(browser, errors);
  try {
    await p.setViewportSize({ width: 390, height: 844 });
    await p.goto(`${server.url}/#preset=helicopter-hover`);
    await ready(p);
    await p.check('input[name=mode][value=browser]');
    await p.click('#run');
    await p.waitForSelector('#criteria-table', { timeout: 60000 });
    const box = () => p.$eval('#criteria', (b) => ({ overflows: b.classList.contains('overflows'), right: b.classList.contains('more-right'), hint: b.querySelector('.scroll-hint').offsetParent !== null }));
    assert.deepEqual(await box(), { overflows: true, right: true, hint: true });
    await p.$eval('#criteria', (b) => (b.scrollLeft = b.scrollWidth));
    await p.waitForFunction(() => !document.getElementById('criteria').classList.contains('more-right'));
    // Wide enough, no hint.
    await p.setViewportSize({ width: 1440, height: 900 });
    await p.waitForFunction(() => !document.getElementById('criteria').classList.contains('overflows'));
    assert.equal((await box()).hint, false);
  } finally {
    await p.context().close();
  }
  assert.deepEqual(errors, []);
});

test('the name or description alone leaves the results current; the export’s name has no stray hyphen', async () => {
  await open('#preset=cv-tracker');
  await page.check('input[name=mode][value=browser]');
  await page.click('#run');
  await page.waitForFunction(() => document.getElementById('summary').dataset.where === 'browser' && !document.getElementById('run').disabled, null, { timeout: 60000 });
  await page.fill('#f-description', 'my notes');
  await page.waitForFunction(() => location.hash.startsWith('#model='));
  assert.equal(await page.$eval('#results', (r) => r.classList.contains('stale')), false);
  const [file] = await Promise.all([page.waitForEvent('download'), page.click('#export-model')]);
  assert.equal(file.suggestedFilename(), 'constant-velocity-tracker-textbook.json');
  await page.fill('input[data-path="params.q"]', '2');
  assert.equal(await page.$eval('#results', (r) => r.classList.contains('stale')), true);
});

test('a run’s “Done in” and “computed in” read in one format: ms below a second', async () => {
  await open('#preset=seed-example');
  await page.check('input[name=mode][value=browser]');
  await page.click('#run');
  await page.waitForFunction(() => document.getElementById('status').textContent.startsWith('Done'), null, { timeout: 60000 });
  const [, done] = (await page.textContent('#status')).match(/^Done in (.+) \(browser, wasm\)\.$/);
  const [, computed] = (await page.textContent('#summary')).match(/computed in (.+) on the browser/);
  for (const text of [done, computed]) {
    const [, x, unit] = text.match(/^(\S+) (ms|s)$/) ?? [];
    assert.ok(unit === 'ms' ? Number(x) < 1000 : Number(x) >= 1 && Number(x) < 60, `“${text}”: ms below a second, s from 1 s`);
  }
});

test('the page logged no console errors', () => {
  assert.deepEqual(consoleErrors, []);
});
