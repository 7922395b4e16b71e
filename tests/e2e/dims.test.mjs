// The model's dimensions in the editor: a dimension field applies only a whole number
// in its range (anything else is marked there, and the model keeps its size); what a
// smaller dimension removes comes back when it grows back, or with Undo; any state or
// measurement can be removed by the × beside its name; resizing keeps the schedule,
// pairs and weights consistent; members without a grid (schedule, pairs, weights, a
// misspelt member) are shown, their errors marked there with a way to remove them; and
// the keyboard focus stays where it was through every redraw.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { choosePreset, exportedModel, importModel, kea, openApp, refusedRun } from './lib.mjs';

let page;
const consoleErrors = [];

let app;

before(async () => {
  app = await openApp(consoleErrors);
  ({ page } = app);
});

after(() => app?.close());

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

test('an empty or out-of-range dimension is marked at its field and not applied: the model keeps its size', async () => {
  await choosePreset(page, 'helicopter-range');
  const original = await exportedModel(page);
  // Cleared, then a click elsewhere before typing the new value.
  await page.click('#dim-N', { clickCount: 3 });
  await page.keyboard.press('Backspace');
  await page.click('input[data-path=name]');
  await page.waitForTimeout(300);
  assert.deepEqual(await states(), original.system.states, 'no state was removed');
  assert.deepEqual(await messagesAt('dimensions.N'), ['empty: enter a whole number from 1 to 200; N stays 6']);
  assert.equal(await page.getAttribute('#dim-N', 'aria-invalid'), 'true');
  assert.match(await refusedRun(page), /fields to fix first/, 'a run does not take the model for what the field shows');
  for (const [text, message] of [
    ['0', /^the model needs at least one state/],
    ['250', /^250 is more than kea's limit of 200/],
    ['2.5', /^2\.5 is not a whole number/],
  ]) {
    await setDimension('N', text);
    assert.deepEqual(await states(), original.system.states, text);
    const shown = await messagesAt('dimensions.N');
    assert.equal(shown.length, 1, `${text}: ${shown}`);
    assert.match(shown[0], message);
  }
  // Esc puts the model's size back in the field.
  await page.focus('#dim-N');
  await page.keyboard.press('Escape');
  assert.equal(await page.inputValue('#dim-N'), '6');
  assert.deepEqual(await messagesAt('dimensions.N'), []);
  // n ≤ N.
  await setDimension('n', '7');
  assert.match((await messagesAt('dimensions.n'))[0], /^7 measurements of 6 states: kea needs n ≤ N; enter a whole number from 1 to 6; n stays 4/);
  assert.equal((await measurements()).length, 4);
  await setDimension('n', '4');
  assert.deepEqual(await editorMessages(), []);
  assert.deepEqual(await exportedModel(page), original, 'nothing changed');
});

test('a smaller N removes states, and growing N back restores them; Undo does too', async () => {
  await choosePreset(page, 'helicopter-range');
  const original = await exportedModel(page);
  await setDimension('N', '4');
  assert.deepEqual(await states(), ['D_f', 'V_f', 'j_f', 'D_b']);
  const note = await page.textContent('[data-note="undo-dims"]');
  assert.match(note, /^N 6 → 4 removed the states “V_b”, “j_b” with their entries in a, b, y₀, η₀, C\. Growing N back restores them/);
  await setDimension('N', '5');
  await setDimension('N', '6');
  assert.deepEqual(await exportedModel(page), original, 'grown back: the model as it was');
  assert.equal(await page.$('[data-note="undo-dims"]'), null);

  // Undo, after an edit of a state that was kept (the edit stays).
  await setDimension('N', '2');
  await page.fill('input[data-path="system.y0[0]"]', '7');
  await page.click('[data-note="undo-dims"] button');
  await page.waitForTimeout(300);
  assert.equal(await focused(), 'dim-N', 'the focus goes to the field Undo changed');
  const undone = await exportedModel(page);
  assert.deepEqual(undone.system.y0, [7, ...original.system.y0.slice(1)]);
  await page.fill('input[data-path="system.y0[0]"]', String(original.system.y0[0]));
  assert.deepEqual(await exportedModel(page), original);
  assert.deepEqual(await editorMessages(), []);

  // Growing and shrinking over new, empty states says nothing: nothing of value went.
  await setDimension('N', '8');
  await setDimension('N', '6');
  assert.equal(await page.$('[data-note="undo-dims"]'), null);
  assert.deepEqual(await exportedModel(page), original);
});

test('arrow keys step a dimension and keep the focus in its field', async () => {
  await choosePreset(page, 'cv-tracker');
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
  assert.deepEqual(await exportedModel(page), JSON.parse(kea('preset', 'cv-tracker')), 'stepped up and back: the preset');
});

test("the × beside a state's name removes that state from every member; Undo puts it back in its place", async () => {
  await choosePreset(page, 'helicopter-range');
  const original = await exportedModel(page);
  await page.focus('button[aria-label="remove state V_f"]');
  await page.keyboard.press('Enter');
  await page.waitForTimeout(300);
  assert.deepEqual(await states(), ['D_f', 'j_f', 'D_b', 'V_b', 'j_b']);
  assert.equal(await focused(), 'remove-state:1', 'the focus goes to the × of the state in its place');
  assert.equal(await page.getAttribute('[data-focus="remove-state:1"]', 'aria-label'), 'remove state j_f');
  const without = (rows, k) => rows.filter((_, i) => i !== k);
  const model = await exportedModel(page);
  assert.deepEqual(model.system.a, without(original.system.a, 1).map((row) => without(row, 1)));
  assert.deepEqual(model.system.b, without(original.system.b, 1));
  assert.deepEqual(model.system.eta0, without(original.system.eta0, 1));
  assert.deepEqual(model.measurement.c, original.measurement.c.map((row) => without(row, 1)));
  assert.match(await page.textContent('[data-note="undo-system"]'), /^Removed the state “V_f” with its entries in a, b, y₀, η₀, C\./);
  await page.click('[data-note="undo-system"] button');
  await page.waitForTimeout(300);
  assert.equal(await focused(), 'remove-state:1', 'the focus goes to the restored state’s ×');
  assert.equal(await page.getAttribute('[data-focus="remove-state:1"]', 'aria-label'), 'remove state V_f');
  assert.deepEqual(await exportedModel(page), original);

  // A measurement, by its own ×, with its schedule entry (helicopter-hover: V_f_meas has one).
  await choosePreset(page, 'helicopter-hover');
  const hover = await exportedModel(page);
  await page.click('button[aria-label="remove measurement V_f_meas"]');
  await page.waitForTimeout(300);
  assert.deepEqual(await measurements(), ['D_f_meas', 'D_b_meas', 'V_b_meas']);
  const removed = await exportedModel(page);
  assert.deepEqual(removed.measurement.schedule, [null, null, null]);
  assert.deepEqual(removed.measurement.c, without(hover.measurement.c, 1));
  assert.deepEqual(await editorMessages(), []);
  await page.click('[data-note="undo-measurement"] button');
  await page.waitForTimeout(300);
  assert.deepEqual(await exportedModel(page), hover);

  // The only state cannot be removed.
  await choosePreset(page, 'seed-example');
  assert.equal(await page.isDisabled('button[aria-label="remove state Y"]'), true);
});

test('resizing keeps the schedule, pairs and weights consistent, and growing back restores them', async () => {
  // helicopter-hover's schedule has one entry per measurement.
  await choosePreset(page, 'helicopter-hover');
  const hover = await exportedModel(page);
  await setDimension('n', '3');
  assert.deepEqual(await editorMessages(), [], 'no “schedule has 4 entries” nobody could fix');
  assert.equal((await exportedModel(page)).measurement.schedule.length, 3);
  await setDimension('n', '4');
  assert.deepEqual(await exportedModel(page), hover, 'the fourth measurement came back as it was');

  const model = JSON.parse(kea('preset', 'helicopter-range'));
  model.measurement.pairs = ['D_f', 'V_f', 'D_b', 'V_b'].map((s) => ({ state: s, measurement: `${s}_meas` }));
  model.criteria.weights = { yz: [0.25, 0.25, 0, 0.25, 0.25, 0], yx: [0.5, 0.1, 0.1, 0.1, 0.1, 0.1] };
  await importModel(page, model, 'weighted.json');
  assert.deepEqual(await editorMessages(), []);
  const original = await exportedModel(page);
  await setDimension('N', '4');
  const shrunk = await exportedModel(page);
  assert.deepEqual(shrunk.criteria.weights, { yz: [0.25, 0.25, 0, 0.25], yx: [0.5, 0.1, 0.1, 0.1] });
  assert.deepEqual(shrunk.measurement.pairs.map((p) => p.state), ['D_f', 'V_f', 'D_b'], 'the pair of V_b went with it');
  // The weights no longer sum to 1: said at the weights' field, with their place.
  const atWeights = await page.$$eval('[data-path="criteria.weights"] ~ .cell-error, .member:has([data-path="criteria.weights"]) .cell-error', (es) =>
    es.map((e) => e.textContent),
  );
  assert.ok(atWeights.some((m) => /weights must sum to 1/.test(m)), `${atWeights}`);
  await setDimension('N', '6');
  assert.deepEqual(await exportedModel(page), original);
  assert.deepEqual(await editorMessages(), []);

  // A state renamed: its pairs follow.
  await page.fill('input[data-path="system.states[0]"]', 'range');
  await page.press('input[data-path="system.states[0]"]', 'Tab');
  await page.waitForTimeout(300);
  assert.equal((await exportedModel(page)).measurement.pairs[0].state, 'range');
  assert.match(await page.inputValue('textarea[data-path="measurement.pairs"]'), /"state":"range"/);
  assert.deepEqual(await editorMessages(), []);
});

test('members without a grid are shown; an error at one is marked there, with a way to remove it', async () => {
  await choosePreset(page, 'helicopter-hover');
  assert.match(await page.inputValue('textarea[data-path="measurement.schedule"]'), /"unavailable":\[\[8,14\]\]/);
  assert.equal(await page.textContent('[data-summary="measurement.schedule"]'), 'V_f_meas: unavailable in [8, 14]; the others at every step');
  assert.equal(await page.inputValue('textarea[data-path="measurement.pairs"]'), '', 'no pairs: the default pairing');

  // An entry the core refuses, marked at the schedule, which Remove takes away.
  await page.fill('textarea[data-path="measurement.schedule"]', '[null, {"every": 0}, null, null]');
  await page.waitForTimeout(400);
  const marked = await page.$$eval('.member:has([data-path="measurement.schedule"]) .cell-error', (es) => es.map((e) => e.textContent));
  assert.equal(marked.length, 1, `${marked}`);
  assert.match(marked[0], /^schedule \[2\]/);
  assert.match(await refusedRun(page), /^schedule \[2\].*\(see the marked fields\)/);
  await page.fill('textarea[data-path="measurement.schedule"]', '[null, {"every": ');
  await page.waitForTimeout(300);
  assert.match((await messagesAt('measurement.schedule'))[0], /^not JSON/);
  await page.click('button[aria-label="remove measurement.schedule"]');
  await page.waitForTimeout(300);
  assert.equal(await focused(), 'f-measurement-schedule', 'the focus stays at the (now empty) field');
  assert.equal((await exportedModel(page)).measurement.schedule, undefined);
  assert.deepEqual(await editorMessages(), []);

  // A misspelt member from a file: shown where it belongs, its error there, removable.
  const typo = JSON.parse(kea('preset', 'seed-example'));
  typo.time = { t0: 0, t_end: 10, stpes: 1000 };
  await importModel(page, typo, 'typo.json');
  await page.fill('input[data-path="time.steps"]', '1000');
  await page.waitForTimeout(400);
  assert.deepEqual(await editorMessages(), ['unknown member; expected one of: t0, t_end, steps, auto']);
  assert.deepEqual(await messagesAt('time.stpes'), ['unknown member; expected one of: t0, t_end, steps, auto']);
  assert.match(await page.textContent('label[for="f-time-stpes"]'), /“stpes”/);
  await page.focus('button[aria-label="remove time.stpes"]');
  await page.keyboard.press('Enter');
  await page.waitForTimeout(400);
  assert.equal(await page.$('[data-path="time.stpes"]'), null);
  assert.deepEqual(await editorMessages(), []);
  assert.deepEqual((await exportedModel(page)).time, { t0: 0, t_end: 10, steps: 1000 });
  assert.notEqual(await focused(), 'BODY', 'the focus stays in the editor');
});

test('the focus stays on the control after removing a parameter or switching a form with the keyboard', async () => {
  await choosePreset(page, 'seed-example');
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
