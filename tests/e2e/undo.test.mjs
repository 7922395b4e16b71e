// Undo and Redo of the model editor (editor.js, history.js): every kind of edit undone
// gives back the model's JSON exactly, and redone the JSON it made; a cell's typing is
// one edit, a pasted block one, a smaller N one (its rows come back); Ctrl+Z in a field
// with typing not committed is the browser's; a new edit clears Redo; the buttons say
// what they would do, and are disabled when there is nothing to do.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { chainModel, choosePreset, exportedModel, importModel, openApp } from './lib.mjs';

let page;
const consoleErrors = [];
let app;

before(async () => {
  app = await openApp(consoleErrors);
  ({ page } = app);
});

after(() => app?.close());

let imports = 0;
/** Import `model` as a file of a new name; returns the name. */
async function importFile(model) {
  const name = `undo-${++imports}.json`;
  await importModel(page, model, name);
  return name;
}

/** The model's JSON as "Export JSON" saves it (compact again, so that texts compare exactly). */
const json = async () => JSON.stringify(await exportedModel(page));

const cell = (path) => `:is(input, textarea)[data-path="${path}"]`;
const label = (id) => page.getAttribute(`#${id}`, 'aria-label');
const disabled = (id) => page.$eval(`#${id}`, (b) => b.disabled);
const focused = () => page.evaluate(() => document.activeElement.dataset.path ?? document.activeElement.dataset.focus ?? document.activeElement.id);

async function undo() {
  await page.click('#undo');
  await page.waitForTimeout(200);
}
async function redo() {
  await page.click('#redo');
  await page.waitForTimeout(200);
}

/** `act()` undone gives back the JSON before it, redone the JSON after it; the Undo button named it `name`. */
async function undoable(act, name) {
  const before = await json();
  await act();
  await page.waitForTimeout(200);
  const made = await json();
  assert.notEqual(made, before, `${name}: the action changed the model`);
  assert.equal(await label('undo'), `Undo: ${name}`);
  await undo();
  assert.equal(await json(), before, `${name}: undone`);
  assert.equal(await label('redo'), `Redo: ${name}`);
  await redo();
  assert.equal(await json(), made, `${name}: redone`);
  await undo();
  assert.equal(await json(), before, `${name}: undone again`);
}

test('the buttons are disabled with nothing to undo or redo, and name what they would do', async () => {
  // The page's first model: nothing to undo.
  assert.equal(await disabled('undo'), true);
  assert.equal(await disabled('redo'), true);
  assert.equal(await label('undo'), 'Undo (nothing to undo)');
  assert.equal(await label('redo'), 'Redo (nothing to redo)');
  await choosePreset(page, 'helicopter-range');
  await page.fill(cell('system.a[1][2]'), '0.5');
  await page.press(cell('system.a[1][2]'), 'Tab');
  assert.equal(await disabled('undo'), false);
  assert.equal(await label('undo'), 'Undo: edit of a [2, 3]');
  assert.match(await page.getAttribute('#undo', 'title'), /^Undo: edit of a \[2, 3\] — Ctrl\+Z$/);
  assert.equal(await disabled('redo'), true);
  await undo();
  assert.equal(await disabled('undo'), false, 'the preset chosen before is one Undo away');
  assert.equal(await label('undo'), 'Undo: choice of the preset helicopter-range');
  assert.equal(await label('redo'), 'Redo: edit of a [2, 3]');
  assert.equal(await disabled('redo'), false);
});

test("a cell's typing is one edit: Ctrl+Z after it is committed reverts it whole, with the focus at the cell", async () => {
  await choosePreset(page, 'helicopter-range');
  const original = await json();
  await page.click(cell('system.y0[0]'));
  await page.keyboard.press('Control+a');
  await page.keyboard.type('12.5', { delay: 20 });
  await page.keyboard.press('Enter'); // commits, and moves to the next cell
  await page.waitForTimeout(200);
  const typed = await json();
  assert.equal(JSON.parse(typed).system.y0[0], 12.5);
  await page.focus(cell('system.y0[1]')); // back in the editor (the export took the focus)
  await page.keyboard.press('Control+z');
  await page.waitForTimeout(200);
  assert.equal(await focused(), 'system.y0[0]', 'the focus at the cell undone');
  assert.equal(await json(), original, 'one Ctrl+Z undid the four keystrokes');
  await page.focus(cell('system.y0[0]'));
  assert.equal(await page.inputValue(cell('system.y0[0]')), String(JSON.parse(original).system.y0[0]));
  await page.keyboard.press('Control+Shift+z');
  await page.waitForTimeout(200);
  assert.equal(await json(), typed);
  await page.keyboard.press('Control+z');
  await page.keyboard.press('Control+y');
  await page.waitForTimeout(200);
  assert.equal(await json(), typed, 'Ctrl+Y redoes too');
});

test('Ctrl+Z in a field with typing not committed is the browser’s: the editor’s history waits', async () => {
  await choosePreset(page, 'helicopter-range');
  const original = await json();
  await page.fill(cell('system.a[0][0]'), '3');
  await page.press(cell('system.a[0][0]'), 'Tab');
  const edited = await json();
  await page.click(cell('system.y0[1]'));
  await page.keyboard.press('End');
  await page.keyboard.type('7');
  assert.equal(await page.inputValue(cell('system.y0[1]')), '407');
  await page.keyboard.press('Control+z'); // the browser's undo of the typing
  await page.waitForTimeout(200);
  assert.equal(await page.inputValue(cell('system.y0[1]')), '40');
  assert.equal(await label('undo'), 'Undo: edit of a [1, 1]', 'the editor did not undo');
  await page.keyboard.press('Control+z'); // the field is as committed: now the editor's
  await page.waitForTimeout(200);
  assert.equal(await json(), original, 'the edit of a [1, 1] undone');
  await page.focus(cell('system.y0[1]'));
  await page.keyboard.press('Control+Shift+z');
  await page.waitForTimeout(200);
  assert.equal(await json(), edited, 'redone');
});

test('a pasted block is one edit', async () => {
  await choosePreset(page, 'helicopter-range');
  await undoable(async () => {
    await page.focus(cell('measurement.c[0][0]'));
    await page.evaluate((sel) => {
      const data = new DataTransfer();
      data.setData('text/plain', '1\t2\n3\t4\n');
      document.querySelector(sel).dispatchEvent(new ClipboardEvent('paste', { clipboardData: data, bubbles: true, cancelable: true }));
    }, cell('measurement.c[0][0]'));
  }, 'paste of 4 values into C');
  await redo();
  await undo();
  assert.equal(await focused(), 'measurement.c[0][0]', 'the focus at the block’s first cell');
});

test('a smaller N undone gives back the states removed, exactly; and the other dimension changes', async () => {
  await choosePreset(page, 'helicopter-range');
  const states = () => page.$$eval('input[data-path^="system.states["]', (l) => l.map((x) => x.value));
  const six = await states();
  const dim = (key, value) => async () => {
    await page.fill(`#dim-${key}`, value);
    await page.press(`#dim-${key}`, 'Tab');
  };
  await undoable(dim('N', '4'), 'N 6 → 4');
  assert.deepEqual(await states(), six);
  await undoable(dim('n', '1'), 'n 4 → 1');
  await undoable(dim('L', '5'), 'L 2 → 5');
  await undoable(dim('M', '2'), 'M 4 → 2');
  await undoable(() => page.click('[data-remove-of="system.states[1]"]'), 'removal of the state “V_f”');
  await redo();
  await undo();
  assert.equal(await focused(), 'remove-state:1', 'the focus at the × of the state given back');
  await undoable(() => page.click('[data-remove-of="measurement.names[0]"]'), 'removal of the measurement “D_f_meas”');
  // The note's own Undo is an edit too.
  await dim('N', '3')();
  await undoable(() => page.click('[data-note="undo-dims"] button'), "N 3 → 6 (the note's Undo)");
});

test('params, forms, members, fields: each undone and redone', async () => {
  await choosePreset(page, 'helicopter-range');
  const params = await page.$$eval('input[data-path^="params."][data-path$=".name"]', (l) => l.map((x) => x.value));
  const p = params[0];
  await undoable(async () => {
    await page.fill(cell(`params.${p}.name`), 'renamed');
    await page.press(cell(`params.${p}.name`), 'Enter');
  }, `rename of parameter ${p} → renamed`);
  await undoable(() => page.click('[data-focus="add-param"]'), 'new parameter p1');
  await undoable(() => page.click(`[data-focus="remove-param:${p}"]`), `removal of parameter ${p}`);
  await undoable(() => page.selectOption('#form-system-errors', 'W'), 'Model errors given as: covariance W');
  await undoable(() => page.selectOption('#form-measurement-noise', 'g'), "Noise matrix: seed's g (N×M)");
  await undoable(() => page.selectOption('#form-measurement-errors', 'V'), 'Measurement errors given as: covariance V');
  await undoable(async () => {
    await page.fill(cell('measurement.schedule'), '[null, {"every": 2}, null, null]');
    await page.click(cell('name'));
  }, 'edit of schedule');
  await undoable(async () => {
    await page.fill(cell('time.t_end'), '42');
    await page.press(cell('time.t_end'), 'Enter');
  }, 'edit of t_E');
  await undoable(() => page.click(cell('options.steady_state_shortcut')), 'edit of Steady-state shortcut');
  await undoable(async () => {
    await page.fill(cell('system.states[0]'), 'renamed_state');
    await page.press(cell('system.states[0]'), 'Tab');
  }, 'edit of state names [1]');
});

test('an import and a preset chosen are undone: the model before comes back', async () => {
  await choosePreset(page, 'helicopter-range');
  await page.fill(cell('name'), 'my own');
  await page.press(cell('name'), 'Tab');
  const own = await json();
  const model = JSON.parse(own);
  model.name = 'imported';
  model.system.y0[0] = 99;
  let file;
  await undoable(async () => {
    file = await importFile(model);
  }, `import of undo-${imports + 1}.json`);
  assert.equal(file, `undo-${imports}.json`);
  assert.equal(await json(), own);
  await undoable(() => choosePreset(page, 'seed-example'), 'choice of the preset seed-example');
  assert.equal(await json(), own);
});

test('a new edit clears Redo', async () => {
  await choosePreset(page, 'helicopter-range');
  await page.fill(cell('system.u[0]'), '1');
  await page.press(cell('system.u[0]'), 'Tab');
  await undo();
  assert.equal(await disabled('redo'), false);
  await page.fill(cell('system.u[1]'), '2');
  await page.press(cell('system.u[1]'), 'Tab');
  assert.equal(await disabled('redo'), true);
  assert.equal(await label('redo'), 'Redo (nothing to redo)');
});

test('an undo marks the results stale and is kept over a reload', async () => {
  await choosePreset(page, 'helicopter-range');
  await page.check('input[name=mode][value=browser]');
  await page.click('#run');
  await page.waitForFunction(() => /^Done/.test(document.getElementById('status').textContent), null, { timeout: 60000 });
  await page.fill(cell('system.u[0]'), '1');
  await page.press(cell('system.u[0]'), 'Tab');
  const original = await json();
  await page.fill(cell('system.u[0]'), '5');
  await page.press(cell('system.u[0]'), 'Tab');
  await page.click('#run');
  await page.waitForFunction(() => /^Done/.test(document.getElementById('status').textContent) && !document.getElementById('results').classList.contains('stale'), null, { timeout: 60000 });
  await undo();
  assert.equal(await page.$eval('#results', (r) => r.classList.contains('stale')), true);
  await page.reload(); // at once: the address may not have caught up yet (the draft in sessionStorage has it)
  await page.waitForSelector('body[data-ready=true]', { timeout: 30000 });
  assert.equal(await json(), original);
  assert.deepEqual(consoleErrors, []);
});

test('at N = 200 a cell’s edit is undone in place (no node drawn anew), and a smaller N exactly', async () => {
  const model = chainModel(200, 50);
  await importFile(model);
  const original = await json();
  await page.fill(cell('system.a[150][20]'), '7');
  await page.press(cell('system.a[150][20]'), 'Tab');
  await page.evaluate(() => document.querySelectorAll('#editor input').forEach((n) => (n.tagged = true)));
  await undo();
  assert.equal(await page.$$eval('#editor input', (ns) => ns.filter((n) => !n.tagged).length), 0, 'nothing drawn anew');
  assert.equal(await page.inputValue(cell('system.a[150][20]')), '0');
  assert.equal(await json(), original);
  await page.fill('#dim-N', '150');
  await page.press('#dim-N', 'Tab');
  await page.waitForFunction(() => document.getElementById('undo').getAttribute('aria-label') === 'Undo: N 200 → 150', null, { timeout: 30000 });
  await undo();
  await page.waitForFunction(() => document.querySelectorAll('[data-path^="system.states["]').length >= 200, null, { timeout: 30000 });
  assert.equal(await json(), original, 'the 50 states and their rows and columns back');
});
