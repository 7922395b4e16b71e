// The model's dimensions in the editor, and the keyboard focus, which stays where it
// was through every redraw.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { kea, openApp } from './lib.mjs';

let page;
const consoleErrors = [];

let app;

before(async () => {
  app = await openApp(consoleErrors);
  ({ page } = app);
});

after(() => app?.close());

async function preset(name) {
  await page.selectOption('#preset', name);
  await page.waitForFunction((n) => location.hash.startsWith(`#preset=${n}`), name);
  await page.waitForTimeout(300); // the core's check of the loaded model has answered
}

/** Load `model` as a file import. */
async function importModel(model, name = 'model.json') {
  await page.setInputFiles('#import-model', { name, mimeType: 'application/json', buffer: Buffer.from(JSON.stringify(model)) });
  await page.waitForFunction((n) => document.getElementById('page-status').textContent.includes(n), name);
  await page.waitForTimeout(300);
}

/** The model as "Export JSON" saves it. */
async function exported() {
  const [download] = await Promise.all([page.waitForEvent('download'), page.click('#export-model')]);
  return JSON.parse(readFileSync(await download.path(), 'utf8'));
}

/** The messages shown at the editor cell or field `path` names. */
function messagesAt(path) {
  return page.$$eval(`[data-error-path="${path}"]`, (es) => es.map((e) => e.textContent));
}

/** Every message the editor shows (at cells and fields, and at the top). */
function editorMessages() {
  return page.$$eval('#editor .cell-error, #editor .general-errors li', (es) => es.map((e) => e.textContent));
}

const states = () => page.$$eval('input[data-path^="system.states["]', (l) => l.map((x) => x.value));
const measurements = () => page.$$eval('input[data-path^="measurement.names["]', (l) => l.map((x) => x.value));

/** What has the keyboard focus: its id, path or focus key; BODY when the focus was lost. */
const focused = () =>
  page.evaluate(() => {
    const a = document.activeElement;
    return a === document.body ? 'BODY' : a.id || a.dataset.path || a.dataset.focus || a.tagName;
  });

/** Type `text` into dimension field `key` and leave it with Tab. */
async function setDimension(key, text) {
  await page.fill(`#dim-${key}`, text);
  await page.press(`#dim-${key}`, 'Tab');
  await page.waitForTimeout(300);
}

/** Run in the browser until the status says an error; returns it. */
async function refusedRun() {
  await page.check('input[name=mode][value=browser]');
  await page.evaluate(() => document.getElementById('status').classList.remove('error'));
  await page.click('#run');
  await page.waitForFunction(() => document.querySelector('#status').classList.contains('error'), null, { timeout: 30000 });
  return page.textContent('#status');
}

test('arrow keys step a dimension and keep the focus in its field', async () => {
  await preset('cv-tracker');
  await page.focus('#dim-N');
  await page.keyboard.press('ArrowUp');
  await page.waitForTimeout(200);
  assert.equal(await page.inputValue('#dim-N'), '3');
  assert.equal(await focused(), 'dim-N');
  await page.keyboard.press('ArrowUp');
  await page.waitForTimeout(200);
  assert.equal(await page.inputValue('#dim-N'), '4');
  assert.equal((await states()).length, 4);
  await page.keyboard.press('ArrowDown');
  await page.keyboard.press('ArrowDown');
  await page.waitForTimeout(200);
  assert.equal(await page.inputValue('#dim-N'), '2');
  assert.equal(await focused(), 'dim-N');
  await page.keyboard.press('Tab');
  assert.equal(await focused(), 'dim-n', 'Tab goes on from the field');
  // The other three dimensions alike.
  for (const key of ['n', 'L', 'M']) {
    await page.focus(`#dim-${key}`);
    await page.keyboard.press('ArrowUp');
    await page.waitForTimeout(200);
    assert.equal(await page.inputValue(`#dim-${key}`), '2', key);
    assert.equal(await focused(), `dim-${key}`, key);
    await page.keyboard.press('ArrowDown');
    await page.waitForTimeout(200);
    assert.equal(await focused(), `dim-${key}`, key);
  }
  assert.deepEqual(await exported(), JSON.parse(kea('preset', 'cv-tracker')), 'stepped up and back: the preset');
});

test('the focus stays on the control after removing a parameter or switching a form with the keyboard', async () => {
  await preset('seed-example');
  await page.focus('button[aria-label="remove parameter c"]');
  await page.keyboard.press('Enter');
  await page.waitForTimeout(300);
  assert.equal(await focused(), 'remove-param:psi', 'the × of the parameter in its place');
  await page.focus('button[aria-label="remove parameter m_g"]');
  await page.keyboard.press('Enter');
  await page.waitForTimeout(300);
  assert.equal(await focused(), 'remove-param:f', 'the last one: the × above');
  await page.focus('#form-system-errors');
  await page.keyboard.press('ArrowDown');
  await page.waitForTimeout(300);
  assert.equal(await page.inputValue('#form-system-errors'), 'W');
  assert.equal(await focused(), 'form-system-errors');
  await page.keyboard.press('ArrowUp');
  await page.waitForTimeout(300);
  assert.equal(await page.inputValue('#form-system-errors'), 'phi');
  assert.equal(await focused(), 'form-system-errors');
});

test('the page logged no console errors', () => {
  assert.deepEqual(consoleErrors, []);
});
