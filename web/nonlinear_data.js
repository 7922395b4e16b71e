// The Nonlinear tab's data (web/nonlinear.js): a truth simulated by the core
// (`data.truth`, src/nonlinear/truth.rs: seeded, so the same data in the browser and on
// the server — another f, unmodelled inputs, another initial state, if given) or
// measured data as CSV (`data.csv_text`: t, a column per measurement, optionally a
// STATE_true column per state; the Identification tab's data box, DataBox).

import { numberProblem, parseCell, toNumber } from './numbers.js';
import { DataBox } from './identification_data.js';
import { el, field, input } from './views.js';

const MAX_SUBSTEPS = 1000; // the core's (nonlinear::truth::MAX_SUBSTEPS)

export class NonlinearData {
  /** `probe()`: the request to read a CSV with (DataBox.probe); `onChange()`: the data changed. */
  constructor({ probe, onChange }) {
    this.onChange = onChange;
    const radio = (value, text, checked) => el('label', {}, el('input', { type: 'radio', name: 'nl-data-mode', value, checked }), ` ${text}`);
    this.modes = el('fieldset', { class: 'mode', id: 'nl-data-mode', 'data-request-path': 'data' }, el('legend', { text: 'From' }), radio('truth', 'simulate a truth', true), radio('csv', 'measured (CSV)', false));
    this.seed = input('nl-truth-seed', '1', { inputmode: 'numeric', 'data-request-path': 'data.truth.seed' });
    this.substeps = input('nl-truth-substeps', '', { inputmode: 'numeric', placeholder: '10', 'data-request-path': 'data.truth.substeps' });
    this.truthBody = el('tbody');
    this.rows = []; // one per state: {f, input, y0}
    this.texts = []; // the rows' texts, kept by index across redraws
    this.csv = new DataBox({
      probe,
      onChange,
      prefix: 'nl',
      kind: 'nonlinear',
      path: 'data.csv_text',
      placeholder: 't,y,x1_true,x2_true\n0,,1000,50\n0.01,999.6,1000.5,50.05\n…',
      help: 'A header row naming the columns in any order: t; one column per measurement name; optionally STATE_true per state (x1_true: the truth, for the true errors); others (a row counter) are ignored. One row per step, t on the model’s grid t₀ + nΔt, n = 0…D (a row at t₀ holds the truth only). An empty cell is a missing value.',
    });
    this.truthPart = el(
      'div',
      { class: 'nl-truth', id: 'nl-truth', 'data-request-path': 'data.truth' },
      el('div', { class: 'row' }, field('Seed', this.seed), field('Substeps per step', this.substeps)),
      el(
        'div',
        { class: 'scroll' },
        el(
          'table',
          { class: 'criteria nl-exprs', id: 'nl-truth-table' },
          el('caption', { text: 'The truth: dx = (f_true + u) dt + dβ, y = h(x) + v (empty: the model’s f, no input, x(t₀) drawn from N(y0, P0))' }),
          el('thead', {}, el('tr', {}, ...['state', 'truth f', 'input u', 'x(t₀)'].map((t) => el('th', { scope: 'col', text: t })))),
          this.truthBody,
        ),
      ),
      el('p', { class: 'help', text: 'Simulated by the core, Euler–Maruyama at Δt/substeps with the model’s noises, from one ChaCha8 stream of the seed: the same data in this browser and on the server. A truth unlike the model (another f, a thrust u(x, t)) shows where the procedure helps.' }),
    );
    this.csvPart = el('div', { class: 'nl-csv', hidden: true }, this.csv.root());
    this.modes.addEventListener('change', () => {
      this.showMode();
      this.onChange?.();
      if (this.mode() === 'csv') this.csv.check();
    });
  }

  root() {
    return el('div', { class: 'nl-data' }, this.modes, this.truthPart, this.csvPart);
  }

  mode() {
    return this.modes.querySelector('input:checked').value;
  }

  setMode(mode) {
    for (const r of this.modes.querySelectorAll('input')) r.checked = r.value === mode;
    this.showMode();
  }

  showMode() {
    const csv = this.mode() === 'csv';
    this.truthPart.hidden = csv;
    this.csvPart.hidden = !csv;
  }

  /** The truth's rows for the model's states (their texts kept by index). */
  setStates(states, model) {
    this.read();
    const f = Array.isArray(model?.system?.f) ? model.system.f : [];
    const y0 = Array.isArray(model?.system?.y0) ? model.system.y0 : [];
    this.rows = states.map((name, i) => {
      const kept = this.texts[i] ?? {};
      const cell = (key, placeholder, label) => input(`nl-truth-${key}-${i}`, kept[key] ?? '', { placeholder, 'aria-label': `${name}: ${label}`, 'data-request-path': `data.truth.${key === 'u' ? 'input' : key}[${i}]` });
      return {
        name,
        f: cell('f', f[i] === undefined ? '' : String(f[i]), 'truth f'),
        u: cell('u', '0', 'input u'),
        y0: cell('y0', `~ N(${y0[i] ?? '?'}, P0)`, 'x(t₀)'),
      };
    });
    this.truthBody.replaceChildren(
      ...this.rows.map((r) => el('tr', { 'data-state': r.name }, el('th', { scope: 'row', text: r.name }), ...['f', 'u', 'y0'].map((k) => el('td', {}, r[k])))),
    );
  }

  read() {
    this.rows.forEach((r, i) => (this.texts[i] = { f: r.f.value, u: r.u.value, y0: r.y0.value }));
  }

  /** The request's `data`, and the errors of fields that do not read: {data, errors}. */
  request() {
    if (this.mode() === 'csv') {
      const text = this.csv.value();
      const errors = text.trim() === '' ? [{ path: 'data.csv_text', message: 'no data: upload a CSV file or paste its text' }] : [];
      return { data: { csv_text: text }, errors };
    }
    const errors = [];
    const truth = {};
    const number = (control, path, options) => {
      const problem = numberProblem(control.value, options);
      if (problem) errors.push({ path, message: problem });
      return toNumber(control.value);
    };
    truth.seed = number(this.seed, 'data.truth.seed', { integer: true, min: 0 });
    if (this.substeps.value.trim() !== '') truth.substeps = number(this.substeps, 'data.truth.substeps', { integer: true, min: 1, max: MAX_SUBSTEPS });
    const given = (key) => this.rows.some((r) => r[key].value.trim() !== '');
    if (given('f')) truth.f = this.rows.map((r) => parseCell(r.f.value.trim() || r.f.placeholder));
    if (given('u')) truth.input = this.rows.map((r) => parseCell(r.u.value.trim() || '0'));
    if (given('y0')) {
      truth.y0 = this.rows.map((r, i) => {
        const text = r.y0.value;
        if (text.trim() === '') errors.push({ path: `data.truth.y0[${i}]`, message: 'give every state’s x(t₀), or none (drawn from N(y0, P0))' });
        return parseCell(text);
      });
    }
    return { data: { truth }, errors };
  }

  /** A request's data (a server job opened) in the fields. */
  fill(data) {
    if (typeof data?.csv_text === 'string') {
      this.setMode('csv');
      this.csv.set(data.csv_text, 'the request’s CSV');
      return;
    }
    const t = data?.truth;
    if (!t) return;
    this.setMode('truth');
    this.seed.value = t.seed === undefined ? '' : String(t.seed);
    this.substeps.value = t.substeps === undefined ? '' : String(t.substeps);
    const text = (list, i, skip) => (Array.isArray(list) && list[i] !== undefined && String(list[i]) !== skip ? String(list[i]) : '');
    this.rows.forEach((r, i) => {
      r.f.value = text(t.f, i, r.f.placeholder);
      r.u.value = text(t.input, i, '0');
      r.y0.value = text(t.y0, i);
    });
    this.read();
  }

  /** What is kept over a reload (the CSV's text apart: NonlinearView keeps it as it changes). */
  kept() {
    this.read();
    return { mode: this.mode(), seed: this.seed.value, substeps: this.substeps.value, rows: this.texts };
  }

  restore(k) {
    if (!k || typeof k !== 'object') return;
    if (typeof k.seed === 'string') this.seed.value = k.seed;
    if (typeof k.substeps === 'string') this.substeps.value = k.substeps;
    if (Array.isArray(k.rows)) this.texts = k.rows.map((r) => (r && typeof r === 'object' ? r : {}));
    if (typeof k.csv === 'string' && k.csv) this.csv.set(k.csv);
    if (k.mode === 'csv' || k.mode === 'truth') this.setMode(k.mode);
  }
}
