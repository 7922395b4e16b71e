// The model editor in a real browser: switching a quantity's form converts its values
// (and a round trip restores the texts), a parameter's rename reaches its uses, a
// number too large for a double is refused at its cell, cells show their full text,
// and messages name fields by their labels.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { choosePreset, exportedModel, openApp, refusedRun, relDiff } from './lib.mjs';

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

/** The messages shown at the editor cell or field `path` names (the input's holder). */
function messagesAt(path) {
  return page.$$eval(`[data-error-path="${path}"]`, (es) => es.map((e) => e.textContent));
}

/** Every message the editor shows (at cells and at the top). */
function editorMessages() {
  return page.$$eval('#editor .cell-error, #editor .general-errors li', (es) => es.map((e) => e.textContent));
}

const cell = (path) => `input[data-path="${path}"]`;

test('a number too large for a double is refused at its cell, in words, before sending', async () => {
  await choosePreset(page, 'seed-example');
  await page.fill(cell('system.y0[0]'), '1e400');
  await page.waitForTimeout(300);
  const shown = await messagesAt('system.y0[0]');
  assert.equal(shown.length, 1, `${shown}`);
  assert.match(shown[0], /“1e400” is too large/);
  assert.doesNotMatch(shown[0], /null/);
  await page.fill(cell('system.y0[0]'), '0');
  await page.waitForTimeout(300);
  assert.deepEqual(await editorMessages(), []);
});

test('"Add parameter" selects the placeholder name, so typing replaces it', async () => {
  await choosePreset(page, 'seed-example');
  await page.click('text=Add parameter');
  await page.keyboard.type('wind');
  await page.keyboard.press('Enter');
  assert.ok(await page.$(cell('params.wind')), 'the parameter is called wind');
  assert.equal(await page.$(cell('params.windp1')), null);
  await choosePreset(page, 'seed-example');
});

test("a cell's full text is its tooltip, kept up to date as it is typed", async () => {
  await choosePreset(page, 'seed-example');
  const a = cell('system.a[0][0]');
  assert.equal(await page.getAttribute(a, 'title'), 's/m');
  const long = 'sqrt(2*alpha*beta*gamma_long_name)/m + s';
  await page.fill(a, long);
  assert.equal(await page.getAttribute(a, 'title'), long);
  await page.fill(a, '');
  assert.equal(await page.getAttribute(a, 'title'), null, 'no tooltip for an empty cell');
  await choosePreset(page, 'seed-example');
});

test('messages name single fields by their labels and parameters by their names, not by JSON paths', async () => {
  await choosePreset(page, 'seed-example');
  await page.fill(cell('time.t_end'), '-5');
  assert.match(await refusedRun(page), /^t_E: t_end \(-5\) must be greater than t0 \(0\)/);
  await choosePreset(page, 'seed-example');
  await page.fill(cell('criteria.confidence'), '1.5');
  const confidence = await refusedRun(page);
  assert.match(confidence, /^Confidence P: /);
  assert.doesNotMatch(confidence, /criteria\./);
  await choosePreset(page, 'seed-example');
  await page.fill(cell('params.w.name'), '2x');
  await page.press(cell('params.w.name'), 'Tab');
  assert.match(await refusedRun(page), /^parameter “2x”: a parameter name must be an identifier/);
  // The core's error (at `params["2x"]`: the name is not an identifier) marks the name cell.
  assert.equal(await page.getAttribute(`input[data-path='params["2x"].name']`, 'aria-invalid'), 'true');
  assert.equal(await page.getAttribute(`input[data-path='params["2x"]']`, 'aria-invalid'), null);
  // Every single field and a parameter's two cells, as the page's other views name them.
  const places = await page.evaluate(async () => {
    const { modelPlace } = await import('./editor.js');
    return ['time.t0', 'time.t_end', 'time.steps', 'criteria.confidence', 'options.trace_points', 'params["2x"]', 'params["2x"].name', 'params["a.b"]', 'params.q.name', 'system.phi[0]', 'measurement.g[1][0]'].map(modelPlace);
  });
  assert.deepEqual(places, ['t₀: ', 't_E: ', 'Steps D: ', 'Confidence P: ', 'Trace points: ', 'parameter “2x”: ', 'name of parameter “2x”: ', 'parameter “a.b”: ', 'name of parameter “q”: ', 'φ [1]: ', 'g [2, 1]: ']);
  await choosePreset(page, 'seed-example');
});

/** Every criterion cell of the results table: {`set.criterion.row`: value|null}. */
function criteria() {
  return page.$$eval('#criteria-table td[data-criterion]', (cells) =>
    Object.fromEntries(cells.map((c) => [`${c.dataset.set}.${c.dataset.criterion}.${c.dataset.row}`, c.dataset.value === '' ? null : Number(c.dataset.value)])),
  );
}

/** Run in the browser until the result is shown; returns its criteria. */
async function runCriteria() {
  await page.check('input[name=mode][value=browser]');
  await page.evaluate(() => delete document.querySelector('#summary').dataset.where);
  await page.click('#run');
  await page.waitForFunction(() => document.querySelector('#summary')?.dataset.where === 'browser' && !document.querySelector('#run').disabled, null, { timeout: 60000 });
  return criteria();
}

/** Choose the form `value` of the form choice `id` (the editor redraws). */
async function pickForm(id, value) {
  await page.selectOption(`#${id}`, value);
  await page.waitForTimeout(300); // the core's check has answered
}

test("the seed's g becomes Γ = C g (the same model: the same criteria), and switching back restores g's text", async () => {
  await choosePreset(page, 'seed-example');
  await page.fill(cell('time.steps'), '20000'); // quick runs
  const withG = await runCriteria();
  await pickForm('form-measurement-noise', 'gamma');
  assert.equal(await page.inputValue(cell('measurement.gamma[0][0]')), 'c*(v*t/m_g)');
  assert.deepEqual(await editorMessages(), []);
  const withGamma = await runCriteria();
  assert.ok(Object.keys(withG).length > 0);
  for (const [key, value] of Object.entries(withG)) {
    if (value === null) assert.equal(withGamma[key], null, key);
    else assert.ok(relDiff(withGamma[key], value) <= 1e-12, `${key}: ${withGamma[key]} with Γ vs ${value} with g`);
  }
  await pickForm('form-measurement-noise', 'g');
  assert.equal(await page.inputValue(cell('measurement.g[0][0]')), 'v*t/m_g', "g's own text, not a quotient");
  assert.equal(await page.$('.form-note'), null, 'nothing to say');
  await choosePreset(page, 'seed-example');
});

test('g ↔ Γ with numbers: Γ = C g computed; an edited Γ gives g = Γ / C; a C that fixes no g says so', async () => {
  await choosePreset(page, 'seed-example');
  await page.fill(cell('measurement.c[0][0]'), '0.5');
  await page.fill(cell('measurement.g[0][0]'), '3');
  await pickForm('form-measurement-noise', 'gamma');
  assert.equal(await page.inputValue(cell('measurement.gamma[0][0]')), '1.5');
  await page.fill(cell('measurement.gamma[0][0]'), '2'); // edited: switching back converts
  await pickForm('form-measurement-noise', 'g');
  assert.equal(await page.inputValue(cell('measurement.g[0][0]')), '4');
  const model = await exportedModel(page);
  assert.deepEqual(model.measurement.g, [[4]]);
  assert.equal(model.measurement.gamma, undefined);

  // cv-tracker: C = [1 0] measures one of two states, so Γ = C g has many g.
  await choosePreset(page, 'cv-tracker');
  await pickForm('form-measurement-noise', 'g');
  const note = await page.textContent('[data-note="measurement-noise"]');
  assert.match(note, /g is 0: Γ = C g gives g only when C is diagonal/);
  assert.match(note, /Switching straight back restores/);
  await pickForm('form-measurement-noise', 'gamma');
  assert.equal(await page.inputValue(cell('measurement.gamma[0][0]')), '1', 'Γ as it was');
  assert.equal(await page.$('.form-note'), null);
  await choosePreset(page, 'seed-example');
});

test('switching φ ↔ W and ψ ↔ V and back restores the texts exactly; after an edit it converts', async () => {
  await choosePreset(page, 'seed-example');
  await pickForm('form-system-errors', 'W');
  assert.equal(await page.inputValue(cell('system.W[0][0]')), '(f*psi)^2');
  await pickForm('form-system-errors', 'phi');
  assert.equal(await page.inputValue(cell('system.phi[0]')), 'f*psi');
  await pickForm('form-measurement-errors', 'V');
  assert.equal(await page.inputValue(cell('measurement.V[0][0]')), 'psi^2');
  await pickForm('form-measurement-errors', 'psi');
  assert.equal(await page.inputValue(cell('measurement.psi[0]')), 'psi');
  // An edit in between: the new value is converted.
  await pickForm('form-measurement-errors', 'V');
  await page.fill(cell('measurement.V[0][0]'), '4e-10');
  await pickForm('form-measurement-errors', 'psi');
  assert.equal(await page.inputValue(cell('measurement.psi[0]')), '0.00002');
  assert.deepEqual(await editorMessages(), []);

  // A covariance with what SKOs cannot say: its entries named, and a way back.
  await choosePreset(page, 'cv-tracker');
  await page.fill('#dim-L', '2');
  await page.press('#dim-L', 'Tab');
  await pickForm('form-system-errors', 'W');
  await page.fill(cell('system.W[0][1]'), '0.1');
  await page.fill(cell('system.W[1][1]'), '-1');
  await pickForm('form-system-errors', 'phi');
  const note = await page.textContent('[data-note="system-errors"]');
  assert.match(note, /W \[1, 2\] \(SKOs give a diagonal covariance\)/);
  assert.match(note, /W \[2, 2\] \(a negative variance has no SKO\)/);
  await pickForm('form-system-errors', 'W');
  assert.equal(await page.inputValue(cell('system.W[0][1]')), '0.1');
  assert.equal(await page.inputValue(cell('system.W[1][1]')), '-1');
  await choosePreset(page, 'seed-example');
});

test("a parameter's rename reaches its uses in every expression, whole names only, and says so", async () => {
  await choosePreset(page, 'seed-example');
  // The uses of m: a = s/m, b = v/m, and u below; not m_g (g = v*t/m_g).
  await page.fill(cell('system.u[0]'), '-w + 0*sin(s)*m_g/m');
  await page.fill(cell('params.m.name'), 'mass');
  await page.press(cell('params.m.name'), 'Tab');
  assert.equal(await page.inputValue(cell('system.a[0][0]')), 's/mass');
  assert.equal(await page.inputValue(cell('system.b[0][0]')), 'v/mass');
  assert.equal(await page.inputValue(cell('system.u[0]')), '-w + 0*sin(s)*m_g/mass');
  assert.equal(await page.inputValue(cell('measurement.g[0][0]')), 'v*t/m_g');
  assert.equal(await page.textContent('[data-note="params"]'), 'renamed m → mass in 3 cells');
  // s: not the s of sin.
  await page.fill(cell('params.s.name'), 'spring');
  await page.press(cell('params.s.name'), 'Tab');
  assert.equal(await page.inputValue(cell('system.a[0][0]')), 'spring/mass');
  assert.equal(await page.inputValue(cell('system.u[0]')), '-w + 0*sin(spring)*m_g/mass');
  assert.equal(await page.getAttribute(cell('system.u[0]'), 'title'), '-w + 0*sin(spring)*m_g/mass', 'the tooltip follows');
  assert.equal(await page.textContent('[data-note="params"]'), 'renamed s → spring in 2 cells');
  await page.waitForTimeout(300);
  assert.deepEqual(await editorMessages(), [], 'the model is still valid');
  const model = await exportedModel(page);
  assert.deepEqual(model.system.a, [['spring/mass']]);
  assert.equal(model.params.mass, 100);

  // A form kept for switching back is renamed too.
  await pickForm('form-system-errors', 'W');
  await page.fill(cell('params.f.name'), 'ratio');
  await page.press(cell('params.f.name'), 'Tab');
  assert.equal(await page.inputValue(cell('system.W[0][0]')), '(ratio*psi)^2');
  await pickForm('form-system-errors', 'phi');
  assert.equal(await page.inputValue(cell('system.phi[0]')), 'ratio*psi');

  // A name no expression can use leaves the uses, and says so.
  await page.fill(cell('params.mass.name'), '2m');
  await page.press(cell('params.mass.name'), 'Tab');
  assert.equal(await page.inputValue(cell('system.a[0][0]')), 'spring/mass');
  assert.equal(await page.textContent('[data-note="params"]'), 'mass is still used in 3 cells: expressions cannot use “2m” as a parameter');
  // Nor does a name the language reads as something else (t: the time variable, which
  // g = v*t/m_g uses; renamed back, the parameter must not take it).
  await page.fill(`input[data-path='params["2m"].name']`, 'mass');
  await page.press(`input[data-path='params["2m"].name']`, 'Tab');
  await page.fill(cell('params.v.name'), 't');
  await page.press(cell('params.v.name'), 'Tab');
  assert.equal(await page.inputValue(cell('system.b[0][0]')), 'v/mass');
  await page.fill(cell('params.t.name'), 'v');
  await page.press(cell('params.t.name'), 'Tab');
  assert.equal(await page.inputValue(cell('measurement.g[0][0]')), 'v*t/m_g');
  await choosePreset(page, 'seed-example');
  assert.equal(await page.textContent('[data-note="params"]'), '', 'a loaded model starts with no note');
});

test('a block pasted into a grid cell fills the grid from there, as in a spreadsheet', async () => {
  await choosePreset(page, 'cv-tracker');
  // Paste `text` into the cell at `path`, as the clipboard would.
  const paste = (path, text) =>
    page.$eval(cell(path), (input, text) => {
      const data = new DataTransfer();
      data.setData('text/plain', text);
      input.dispatchEvent(new ClipboardEvent('paste', { clipboardData: data, bubbles: true, cancelable: true }));
    }, text);
  // From a spreadsheet: tab-separated rows; a third row falls beyond a's edge. (It was
  // all put into the one cell, "0\t1 -0.5\t0", and marked as implicit multiplication.)
  await paste('system.a[0][0]', '0\t1\r\n-0.5\t-0.1\r\n7\t7\r\n');
  const model = await exportedModel(page);
  assert.deepEqual(model.system.a, [[0, 1], [-0.5, -0.1]]);
  assert.equal(await page.textContent('#page-status'), 'Pasted 4 values into a (N×N); 2 beyond its edge left out.');
  assert.deepEqual(await messagesAt('system.a[0][0]'), []);
  // From MATLAB or numpy: spaces or commas, on several lines; each value checked as
  // if typed.
  await paste('system.a[0][1]', '2\n1e400, 3');
  assert.equal(await page.inputValue(cell('system.a[0][1]')), '2');
  assert.equal(await page.inputValue(cell('system.a[1][1]')), '1e400');
  assert.equal(await page.textContent('#page-status'), 'Pasted 2 values into a (N×N); 1 beyond its edge left out.');
  assert.ok((await messagesAt('system.a[1][1]')).length > 0, 'a bad pasted value is marked at its cell');
  // One value pastes into the cell as usual (the page does not take it over).
  const taken = await page.$eval(cell('system.a[1][1]'), (input) => {
    const data = new DataTransfer();
    data.setData('text/plain', '0.25');
    return input.dispatchEvent(new ClipboardEvent('paste', { clipboardData: data, bubbles: true, cancelable: true }));
  });
  assert.equal(taken, true, 'a single value is left to the browser');
});

test('the page logged no console errors', () => {
  assert.deepEqual(consoleErrors, []);
});
