// The model editor at large N (a 200-state model: a, C and Γ have tens of thousands
// of cells): a cell's edit changes that cell, its marks and the model, and leaves every
// other node of the editor as it was; a pasted block is one edit; the large grids (not
// tables, editor.js) keep their labels over their columns and rows, move with the arrow
// keys and show errors at their cells; dimension changes and Undo work as at small N.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { chainModel, exportedModel, importModel, openApp } from './lib.mjs';

let page;
const consoleErrors = [];

let app;

before(async () => {
  app = await openApp(consoleErrors);
  ({ page } = app);
});

after(() => app?.close());

let imports = 0;

/** Load `model` as a file import; resolves when the core's check has answered. */
async function importFile(model) {
  await importModel(page, model, `large-${++imports}.json`, 0);
  await checked();
}

/** Wait for the core's check of the model shown (150 ms after an edit) to have answered. */
/** Wait until the core's check of the latest edit is shown (app.js's `data-checking`
 * on the body goes when it is), then a frame. */
async function checked() {
  await page.waitForFunction(() => document.body.dataset.checking === undefined, null, { timeout: 20000 });
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => setTimeout(r))));
}

function messagesAt(path) {
  return page.$$eval(`[data-error-path="${path}"]`, (es) => es.map((e) => e.textContent));
}

const cell = (path) => `input[data-path="${path}"]`;

/** Count the page's model changes (app.js announces each as kea:model-changed) from now on. */
const countChanges = () =>
  page.evaluate(() => {
    if (window.modelChanges === undefined) document.addEventListener('kea:model-changed', () => window.modelChanges++);
    window.modelChanges = 0;
  });

test('one cell edited at N = 200 changes that cell, its marks and the model: every other node stays', async () => {
  const model = chainModel(200, 50);
  model.measurement.c[10][10] = 'k'; // an unknown name: the core's message at its cell
  await importFile(model);
  assert.match((await messagesAt('measurement.c[10][10]'))[0], /k/);
  // Tag every input and message of the editor, to tell them from new ones.
  const tag = () =>
    page.evaluate(() => {
      const nodes = document.querySelectorAll('#editor input, #editor .cell-error, #editor tr, #editor [role=row]');
      nodes.forEach((n) => (n.tagged = true));
      return nodes.length;
    });
  const untagged = () =>
    page.$$eval('#editor input, #editor .cell-error, #editor tr, #editor [role=row]', (ns) => ns.filter((n) => !n.tagged).map((n) => n.dataset.errorPath ?? n.dataset.path ?? n.tagName));
  const tagged = () => page.$$eval('#editor input, #editor .cell-error, #editor tr, #editor [role=row]', (ns) => ns.filter((n) => n.tagged).length);
  const before = await tag();
  assert.ok(before > 50000, `${before} nodes`);
  await countChanges();

  await page.fill(cell('system.a[100][57]'), '0.25');
  await checked();
  assert.deepEqual(await untagged(), [], 'nothing was drawn anew');
  assert.equal(await tagged(), before, 'nothing was removed');
  assert.equal(await page.evaluate(() => window.modelChanges), 1);
  // A value the cell refuses: marked at it, the other mark the same node.
  await page.fill(cell('system.a[100][57]'), '1e400');
  await checked();
  assert.match((await messagesAt('system.a[100][57]'))[0], /“1e400” is too large/);
  assert.equal(await page.getAttribute(cell('system.a[100][57]'), 'aria-invalid'), 'true');
  assert.deepEqual(await untagged(), ['system.a[100][57]'], 'only the new message is new');
  // Fixed: its mark goes; the core's mark elsewhere has stayed the node it was.
  await page.fill(cell('system.a[100][57]'), '-2');
  await checked();
  assert.deepEqual(await messagesAt('system.a[100][57]'), []);
  assert.equal(await page.getAttribute(cell('system.a[100][57]'), 'aria-invalid'), null);
  assert.deepEqual(await untagged(), []);
  assert.equal(await tagged(), before);
  assert.equal(await page.$eval('[data-error-path="measurement.c[10][10]"]', (e) => e.tagged), true);
  // The focus and the caret stay in the cell through the check.
  assert.equal(await page.evaluate(() => document.activeElement.dataset.path), 'system.a[100][57]');
  await page.keyboard.press('End');
  await page.keyboard.type('.5');
  await checked();
  assert.deepEqual(
    await page.evaluate(() => [document.activeElement.dataset.path, document.activeElement.selectionStart, document.activeElement.value]),
    ['system.a[100][57]', 4, '-2.5'],
  );
  // The core's mark goes when its cell is fixed.
  await page.fill(cell('measurement.c[10][10]'), '1');
  await checked();
  assert.deepEqual(await page.$$eval('#editor .cell-error, #editor .general-errors li', (es) => es.map((e) => e.textContent)), []);
  const saved = await exportedModel(page);
  const expected = chainModel(200, 50);
  expected.system.a[100][57] = -2.5;
  assert.deepEqual(saved.system, expected.system);
  assert.deepEqual(saved.measurement, expected.measurement);
  assert.equal(await page.evaluate(() => window.modelChanges), 5);
});

test('a 200×200 block pasted into a is one edit of the model, its bad values marked at their cells', async () => {
  await importFile(chainModel(200, 50));
  await countChanges();
  const rows = Array.from({ length: 200 }, (_, i) => Array.from({ length: 200 }, (_, j) => (i === j ? '-0.25' : j === i + 1 ? '2' : '0')));
  rows[3][4] = '1e400';
  rows[150][20] = 'q*2';
  await page.$eval(
    cell('system.a[0][0]'),
    (input, text) => {
      input.focus();
      const data = new DataTransfer();
      data.setData('text/plain', text);
      input.dispatchEvent(new ClipboardEvent('paste', { clipboardData: data, bubbles: true, cancelable: true }));
    },
    rows.map((r) => r.join('\t')).join('\r\n'),
  );
  assert.equal(await page.evaluate(() => window.modelChanges), 1, 'one change, not one per cell');
  assert.equal(await page.textContent('#page-status'), 'Pasted 40000 values into a (N×N).');
  await checked();
  assert.equal(await page.inputValue(cell('system.a[150][20]')), 'q*2');
  assert.equal(await page.getAttribute(cell('system.a[150][20]'), 'title'), 'q*2');
  assert.deepEqual(await page.$$eval('#editor .cell-error', (es) => es.map((e) => e.dataset.errorPath)), ['system.a[3][4]']);
  assert.equal(await page.evaluate(() => document.activeElement.dataset.path), 'system.a[0][0]', 'the focus stays where the paste went');
  const saved = await exportedModel(page);
  assert.deepEqual(saved.system.a[3].slice(2, 6), [0, -0.25, '1e400', 0]);
  assert.equal(saved.system.a[150][20], 'q*2');
  assert.equal(saved.system.a[199][199], -0.25);
  // Fixed by another paste at the bad cell (a block of one row, by a tab).
  await page.$eval(cell('system.a[3][4]'), (input) => {
    const data = new DataTransfer();
    data.setData('text/plain', '0\t0');
    input.dispatchEvent(new ClipboardEvent('paste', { clipboardData: data, bubbles: true, cancelable: true }));
  });
  await checked();
  assert.deepEqual(await messagesAt('system.a[3][4]'), []);
  assert.equal(await page.evaluate(() => window.modelChanges), 2);
});

test('a large grid keeps its labels over its columns and beside its rows, and moves with the arrow keys', async () => {
  const model = chainModel(200, 50);
  model.system.states[7] = 'a rather long state name';
  await importFile(model);
  // The middles of these elements, across (x) and down (y), with `target` scrolled into view.
  const middles = (target, selectors) =>
    page.evaluate(
      ([target, selectors]) => {
        document.querySelector(target).scrollIntoView({ block: 'center', inline: 'center' });
        return selectors.map((s) => {
          const r = document.querySelector(s).getBoundingClientRect();
          return [r.left + r.width / 2, r.top + r.height / 2];
        });
      },
      [target, selectors],
    );
  // Column 150's label over its cells (the grid scrolls sideways: 200 columns); row
  // 120's label beside its cells.
  const columnLabel = '[data-grid="system.a"] .col-label[data-label-of="system.states[150]"]';
  const [label, ...cells] = await middles(cell('system.a[120][150]'), [columnLabel, ...[0, 120, 199].map((i) => cell(`system.a[${i}][150]`))]);
  for (const [x] of cells) assert.ok(Math.abs(x - label[0]) < 1, `cell at ${x}, its column's label at ${label[0]}`);
  const [rowLabel, rowCell] = await middles(cell('system.a[120][3]'), ['[data-grid="system.a"] .label[data-label-of="system.states[120]"]', cell('system.a[120][3]')]);
  assert.ok(Math.abs(rowLabel[1] - rowCell[1]) < 4, `row label at ${rowLabel[1]}, its cell at ${rowCell[1]}`);
  assert.ok(rowLabel[0] < rowCell[0]);
  assert.ok(await page.isVisible('[data-grid="system.a"] .scroll-hint'), 'the grid says it scrolls');
  // A rename reaches the labels; a long one is cut short, whole in the tooltip.
  await page.fill(cell('system.states[150]'), 'speed');
  assert.equal(await page.textContent('[data-grid="measurement.c"] [data-label-of="system.states[150]"]'), 'speed');
  assert.equal(await page.getAttribute('[data-grid="system.a"] .col-label[data-label-of="system.states[150]"]', 'title'), 'speed');
  assert.equal(await page.getAttribute('[data-grid="system.a"] [data-label-of="system.states[7]"]', 'title'), 'a rather long state name');
  // The arrow keys and Enter, as in a table.
  await page.click(cell('system.a[120][3]'));
  await page.keyboard.press('ArrowDown');
  await page.keyboard.press('Enter');
  await page.keyboard.press('ArrowUp');
  await page.keyboard.press('End');
  await page.keyboard.press('ArrowRight');
  assert.equal(await page.evaluate(() => document.activeElement.dataset.path), 'system.a[121][4]');
  await page.keyboard.press('Tab');
  assert.equal(await page.evaluate(() => document.activeElement.dataset.path), 'system.a[121][5]', 'Tab goes on to the next cell');
});

test('at N = 200 a smaller N is undone, and the focus stays in the field', async () => {
  const model = chainModel(200, 50);
  model.system.a[199][199] = 'q';
  await importFile(model);
  await page.fill('#dim-N', '150');
  await page.press('#dim-N', 'Tab');
  await checked();
  assert.equal(await page.$(cell('system.a[150][150]')), null);
  assert.match(await page.textContent('[data-note="undo-dims"]'), /^N 200 → 150 removed the states “y151”/);
  await page.click('[data-note="undo-dims"] button');
  await checked();
  assert.equal(await page.evaluate(() => document.activeElement.id), 'dim-N');
  assert.equal(await page.inputValue(cell('system.a[199][199]')), 'q');
  const saved = await exportedModel(page);
  assert.deepEqual(saved.system, model.system);
  assert.deepEqual(saved.measurement, model.measurement);
});

test('the page logged no console errors', () => {
  assert.deepEqual(consoleErrors, []);
});
