// The Nonlinear tab's model (web/nonlinear.js): the nonlinear model's JSON
// (src/nonlinear/model.rs, `kea_nonlinear`) as text, loaded with the seed-002 preset
// (the wasm module's copy, exactly as shipped), and beside it fields for what one edits
// most: the time grid, each state's f and each measurement's h. The text is the model:
// a field's edit is written into it (the text then in the page's layout), and an edit of
// the text is shown in the fields once it reads as JSON.

import { numberProblem, parseCell, toNumber } from './numbers.js';
import { el, wasmCall } from './views.js';

export const PRESET = 'seed-002';

const TIME = [
  ['t0', 't₀', false],
  ['t_end', 't_end', false],
  ['steps', 'Steps D', true],
];

/** A value on one line: a number, a text, or an array of such (a matrix's rows too). */
const inline = (v) => v === null || typeof v !== 'object' || (Array.isArray(v) && v.every(inline));

/**
 * A model as the page writes it: one member a line, indented by one space a level, an
 * array of numbers or texts (a matrix too) on one line — the presets' layout.
 */
export function modelText(v, indent = '') {
  const inner = `${indent} `;
  if (Array.isArray(v)) {
    if (v.every(inline)) return `[${v.map((x) => modelText(x)).join(', ')}]`;
    return `[\n${v.map((x) => inner + modelText(x, inner)).join(',\n')}\n${indent}]`;
  }
  if (v && typeof v === 'object') {
    const keys = Object.keys(v);
    if (!keys.length) return '{}';
    return `{\n${keys.map((k) => `${inner}${JSON.stringify(k)}: ${modelText(v[k], inner)}`).join(',\n')}\n${indent}}`;
  }
  return JSON.stringify(v);
}

/** What a model value shows in a field: a number's digits or an expression's text. */
const shown = (v) => (v === null || v === undefined ? '' : typeof v === 'object' ? JSON.stringify(v) : String(v));

/** The text's model, or why there is none: {model} or {problem}. */
function read(text) {
  let model;
  try {
    model = JSON.parse(text);
  } catch (e) {
    return { problem: `not JSON: ${e.message}` };
  }
  if (!model || typeof model !== 'object' || Array.isArray(model)) return { problem: 'a nonlinear model is a JSON object {"kea_nonlinear": 1, "time": …, "system": …, "measurement": …}' };
  return { model };
}

export class ModelBox {
  /** `onChange()`: the model changed (its text or a field). */
  constructor({ onChange }) {
    this.onChange = onChange;
    this.text = el('textarea', {
      id: 'nl-model',
      rows: 18,
      spellcheck: 'false',
      autocomplete: 'off',
      'data-request-path': 'model',
      'aria-describedby': 'nl-model-help nl-model-note',
    });
    this.note = el('p', { id: 'nl-model-note', class: 'view-status', role: 'status', 'aria-live': 'polite' });
    this.time = Object.fromEntries(
      TIME.map(([key, , integer]) => [key, el('input', { id: `nl-time-${key.replace('_', '-')}`, spellcheck: 'false', autocomplete: 'off', inputmode: integer ? 'numeric' : 'decimal', 'data-request-path': `model.time.${key}` })]),
    );
    this.fBody = el('tbody');
    this.hBody = el('tbody');
    this.presetButton = el('button', { type: 'button', id: 'nl-preset', text: `Load the preset ${PRESET}`, title: `The model of presets/nonlinear/${PRESET}.json, in place of the text`, onclick: () => this.loadPreset() });
    this.text.addEventListener('input', () => this.textChanged());
    for (const [key, input] of Object.entries(this.time)) input.addEventListener('input', () => this.timeChanged(key));
    this.states = [];
    this.names = [];
    this.parsed = read('');
  }

  root() {
    const timeFields = TIME.map(([key, label]) => el('div', { class: 'field' }, el('label', { for: this.time[key].id, text: label }), this.time[key]));
    const table = (id, caption, head, body) =>
      el('div', { class: 'scroll' }, el('table', { class: 'criteria nl-exprs', id }, el('caption', { text: caption }), el('thead', {}, el('tr', {}, ...head.map((t) => el('th', { scope: 'col', text: t })))), body));
    this.box = el(
      'div',
      { class: 'nl-model' },
      el('div', { class: 'row' }, ...timeFields),
      table('nl-f', 'dx/dt = f(x, t) + noise of intensity W: each state’s f, an expression in the states, t and the params', ['state', 'f'], this.fBody),
      table('nl-h', 'y = h(x, t) + v: each measurement’s h', ['measurement', 'h'], this.hBody),
      el(
        'div',
        { class: 'field wide nl-model-text' },
        el('div', { class: 'row' }, el('label', { for: 'nl-model', text: 'The model (JSON)' }), this.presetButton),
        el('div', { class: 'nl-model-box' }, this.text), // a run's messages at the model come under it
        el('small', {
          id: 'nl-model-help',
          class: 'help',
          text: 'The nonlinear model (kea_nonlinear 1): params; time (t0, t_end, steps D: Δt = (t_end − t0)/D); system (states, f, y0, eta0 or P0, phi or W: the process noise intensity per unit time); measurement (names, h, psi or V: one sample’s noise); procedure (alpha, earlier_residuals: the defaults the fields below override). F = ∂f/∂x and H = ∂h/∂x are derived from the texts. An edit in the fields above rewrites this text in the presets’ layout.',
        }),
        this.note,
      ),
    );
    return this.box;
  }

  /** The preset's text, exactly as shipped (the wasm module's copy of presets/nonlinear/). */
  async loadPreset() {
    const text = await wasmCall('nonlinear_preset', { name: PRESET });
    this.set(text);
    return text;
  }

  value() {
    return this.text.value;
  }

  /** The model the text holds now, or null. */
  model() {
    return this.parsed.model ?? null;
  }

  /** Put `text` in the box, as if typed. */
  set(text) {
    this.text.value = text;
    this.textChanged();
  }

  textChanged() {
    this.parsed = read(this.text.value);
    this.say();
    if (this.parsed.model) this.fill(this.parsed.model);
    for (const c of this.controls()) c.disabled = !this.parsed.model;
    this.onChange?.();
  }

  say() {
    const p = this.parsed.problem;
    this.note.textContent = p ? `The text is ${p.startsWith('not JSON') ? p : `not a model: ${p}`}; the fields above follow it once it reads.` : '';
    this.note.classList.toggle('error', Boolean(p));
  }

  /** The fields' controls (disabled while the text does not read). */
  controls() {
    return [...Object.values(this.time), ...this.fBody.querySelectorAll('input'), ...this.hBody.querySelectorAll('input')];
  }

  /** The fields as the model has them: the time grid, a row per state and per measurement. */
  fill(model) {
    for (const [key] of TIME) this.time[key].value = shown(model.time?.[key]);
    const list = (v) => (Array.isArray(v) ? v : []);
    this.states = list(model.system?.states).map(String);
    this.names = list(model.measurement?.names).map(String);
    const rows = (body, names, values, prefix, path, what) => {
      const count = Math.max(names.length, values.length);
      body.replaceChildren(
        ...Array.from({ length: count }, (_, i) => {
          const name = names[i] ?? `(${what} ${i + 1})`;
          const input = el('input', { id: `nl-${prefix}-${i}`, value: shown(values[i]), spellcheck: 'false', autocomplete: 'off', 'aria-label': `${prefix} of ${name}`, 'data-request-path': `${path}[${i}]` });
          input.addEventListener('input', () => this.exprChanged(path, i, input.value));
          return el('tr', { 'data-name': name }, el('th', { scope: 'row', text: name }), el('td', {}, input));
        }),
      );
    };
    rows(this.fBody, this.states, list(model.system?.f), 'f', 'model.system.f', 'state');
    rows(this.hBody, this.names, list(model.measurement?.h), 'h', 'model.measurement.h', 'measurement');
  }

  /** Write `change(model)` into the text (the fields' edits): the text in the presets' layout. */
  write(change) {
    const model = this.parsed.model;
    if (!model) return;
    change(model);
    this.text.value = `${modelText(model)}\n`;
    this.onChange?.();
  }

  exprChanged(path, i, text) {
    const [section, member] = path.split('.').slice(1);
    this.write((m) => {
      m[section] ??= {};
      if (!Array.isArray(m[section][member])) m[section][member] = [];
      m[section][member][i] = parseCell(text);
    });
  }

  timeChanged(key) {
    const text = this.time[key].value;
    if (this.timeProblem(key)) return; // marked at the field (localErrors); the text keeps its value
    this.write((m) => {
      if (!m.time || typeof m.time !== 'object') m.time = {};
      m.time[key] = toNumber(text);
    });
  }

  timeProblem(key) {
    const integer = TIME.find(([k]) => k === key)[2];
    return numberProblem(this.time[key].value, integer ? { integer: true, min: 1 } : {});
  }

  /** What the fields hold that the text cannot take: [{path, message}]. */
  localErrors() {
    if (!this.parsed.model) return [{ path: 'model', message: `the model’s text is ${this.parsed.problem}` }];
    return TIME.map(([key]) => [key, this.timeProblem(key)])
      .filter(([, problem]) => problem)
      .map(([key, message]) => ({ path: `model.time.${key}`, message }));
  }
}
