// The Identification tab (METHOD §3): the maximum-likelihood params of the editor's
// model — discrete (system.transition, Φ per step), or continuous and discretised by the
// core as the analysis does — from measured data (the data box,
// identification_data.js), in this browser (wasm, the core's Sequential executor: the
// same bits as the server and `kea identify`) or as a server job of kind
// `identification`; the estimates with their standard errors and 95 % intervals, J, the
// identifiability verdict and the stop reason in words, whether the model fits the data
// (the innovations), the distinct optima of several starts (identification_fit.js), and J
// and each param's path over the iterations (identification_plots.js).

import { isDiscrete } from './editor.js';
import { numberProblem, toNumber } from './numbers.js';
import { DataBox, rowsToCsv } from './identification_data.js';
import { fitBlock, optimaTable, parseStarts, startsText } from './identification_fit.js';
import { CHART_HEIGHT, iterationChart } from './identification_plots.js';
import { resumedText } from './results.js';
import { KeptFields, RunBar, RunView, duration, el, field, fmt, input, recheckControl, requestErrors, select } from './views.js';

const METHODS = [
  ['scoring', 'Fisher scoring (the default)'],
  ['gradient', 'gradient descent'],
  ['conjugate', 'conjugate directions'],
];
const BOUND_CHOICES = [
  ['no', 'no'],
  ['yes', 'yes: the expected information at θ̂'],
];
const MAX_ITERATIONS = 10000; // the core's limit (identification::request::MAX_ITERATIONS)
const BOUNDS = ['initial', 'min', 'max'];
// The example the tab loads (a copy of examples/identification/, served with the page).
const EXAMPLE = 'examples/identification/oscillator.json';
const KEEP_ESTIMATE = 'kea-identification-estimate';
const KEEP_DATA = 'kea-identification-data';

/** A name a path writes after a dot (the core's `is_identifier`). */
const IDENTIFIER = /^[\p{L}_][\p{L}\p{N}_]*$/u;

/** The request path of a member of `parent`, as the core writes it: `estimate.r`, or `estimate["a.b"]`. */
function memberPath(parent, key) {
  return IDENTIFIER.test(key) ? `${parent}.${key}` : `${parent}[${JSON.stringify(key)}]`;
}

/** A number as an input shows it (the JSON's digits). */
const shown = (x) => (typeof x === 'number' && Number.isFinite(x) ? String(x) : '');

function readKept(key) {
  try {
    return sessionStorage.getItem(key);
  } catch {
    return null;
  }
}

function keep(key, value) {
  try {
    if (value === null) sessionStorage.removeItem(key);
    else sessionStorage.setItem(key, value);
  } catch {
    // storage off or full: not kept
  }
}

export class IdentificationView extends RunView {
  /** `ctx`: {model(), loadModel(model, label), showModelErrors(errors), download(name, type, text), fileStem()}. */
  constructor(root, ctx) {
    super();
    this.root = root;
    this.ctx = ctx;
    this.result = null;
    this.edits = 0; // model changes seen (markStale): a result is current if none came during its run
    this.model = null; // the model object the param rows are for (another one resets them)
    this.rows = []; // one per model param: {name, on, initial, min, max}
    this.entries = new Map(); // param → {on, initial, min, max}: the rows' texts, kept across redraws
    try {
      for (const [k, v] of Object.entries(JSON.parse(readKept(KEEP_ESTIMATE) ?? '{}') ?? {})) this.entries.set(k, v);
    } catch {
      // unreadable: the defaults
    }
    this.plots = [];
    this.fitCharts = []; // the result's autocorrelation boxes (fitBlock)
    this.build();
  }

  build() {
    this.method = select('id-method', METHODS, 'scoring');
    this.method.dataset.requestPath = 'method';
    this.maxIterations = input('id-max-iterations', '', { inputmode: 'numeric', placeholder: '100', 'data-request-path': 'max_iterations' });
    this.expected = select('id-expected', BOUND_CHOICES, 'no');
    this.expected.dataset.requestPath = 'expected_information';
    this.starts = el('textarea', {
      id: 'id-starts',
      rows: 3,
      spellcheck: 'false',
      autocomplete: 'off',
      placeholder: 'w=-0.5\nr=0.9, w=0.2',
      'data-request-path': 'starts',
    });
    this.formNote = el('p', { id: 'id-form-note', class: 'help id-form-note', hidden: true });
    this.exampleButton = el('button', { type: 'button', id: 'id-example', text: 'Load the example', title: 'The damped oscillator of examples/identification: its model into the editor, its data here', onclick: () => this.loadExample() });
    this.data = new DataBox({ probe: () => this.probe(), onChange: () => keep(KEEP_DATA, this.data.value()) });
    this.paramsBody = el('tbody');
    this.paramsTable = el(
      'table',
      { class: 'criteria id-params', id: 'id-params', 'data-request-path': 'estimate' },
      el('caption', { text: 'The params to estimate (an empty initial value is the model’s; empty bounds: none)' }),
      el('thead', {}, el('tr', {}, ...['param', 'estimate', 'initial', 'min', 'max'].map((t) => el('th', { scope: 'col', text: t })))),
      this.paramsBody,
    );
    const startsField = field(
      'More starts (optional)',
      this.starts,
      'Further starting points, one per line: NAME=x items of params estimated, split by commas (r=0.9, w=0.2); a param left out starts at its initial value; at most 100. The fit runs from each: the lowest J is the estimate, and every distinct optimum is listed with the starts that reached it.',
    );
    startsField.classList.add('wide', 'id-starts');
    this.form = el(
      'form',
      { class: 'view-form', novalidate: true, onsubmit: (e) => e.preventDefault(), oninput: (e) => recheckControl(e.target, () => requestErrors(() => this.request())) },
      el(
        'fieldset',
        { class: 'section' },
        el('legend', { text: 'Identification: the params of a model from measured data' }),
        this.formNote,
        this.data.root(this.exampleButton),
        el('div', { class: 'scroll' }, this.paramsTable),
        startsField,
        el(
          'div',
          { class: 'row' },
          field('Method', this.method),
          field('Max iterations', this.maxIterations),
          field('Cramér–Rao bound', this.expected, 'The expected information at the estimate (its expectation over data drawn from the model there, with the data’s missing measurements) and the bound √((I⁻¹)ᵢᵢ) on each estimate’s SKO: one more pass over the data.'),
        ),
        el('p', { class: 'help', text: 'Maximum likelihood by the square-root information filter (METHOD §3): J(θ) = −log-likelihood of the data, minimised within the bounds — scoring with a line search, gradient descent halving its step, or conjugate directions restarted every p iterations. Cost ∝ iterations × D × (N + L)³ × (1 + params).' }),
      ),
    );
    this.bar = new RunBar({ prefix: 'id', label: 'Run identification', op: 'identify', kind: 'identification', onRun: (where, exec) => this.run(where, exec), onResume: (model, exec) => this.resume(model, exec) });
    this.out = el('div', { id: 'id-result', class: 'view-result', hidden: true });
    this.paramSelect = el('select', { id: 'id-param' });
    this.paramSelect.addEventListener('change', () => this.draw());
    this.chartJ = el('div', { id: 'id-chart-j', class: 'id-chart' });
    this.chartParam = el('div', { id: 'id-chart-param', class: 'id-chart' });
    new ResizeObserver(() => this.plots.forEach((p) => p.setSize({ width: this.width(), height: CHART_HEIGHT }))).observe(this.out);
    this.root.append(this.form, this.bar.root, this.out);
    this.kept = new KeptFields('kea-identification', [[this.method], [this.maxIterations], [this.starts], [this.expected]]);
    this.kept.restore();
    for (const type of ['input', 'change']) this.form.addEventListener(type, (e) => e.target !== this.data.text && this.saveFields());
    const data = readKept(KEEP_DATA);
    if (data) this.data.set(data);
    else this.data.check();
    this.refreshParams();
  }

  saveFields() {
    this.kept.save();
    this.readRows();
    keep(KEEP_ESTIMATE, JSON.stringify(Object.fromEntries(this.entries)));
  }

  // ------------------------------------------------------------ the params

  /** The rows' texts into `entries` (by param name). */
  readRows() {
    for (const r of this.rows) this.entries.set(r.name, { on: r.on.checked, ...Object.fromEntries(BOUNDS.map((k) => [k, r[k].value])) });
  }

  /**
   * One row per param of the editor's model, with the texts each param had; another
   * model (a preset, an import, the example) starts from none estimated. The initial
   * value's placeholder is the param's value in the model, which an empty field means.
   */
  refreshParams({ fromEntries = false } = {}) {
    const model = this.ctx.model();
    if (!model) return;
    if (this.model && model !== this.model) this.entries.clear();
    else if (!fromEntries) this.readRows();
    this.model = model;
    const params = Object.entries(model.params ?? {});
    this.rows = params.map(([name, value], i) => {
      const kept = this.entries.get(name) ?? {};
      const path = memberPath('estimate', name);
      const row = {
        name,
        on: el('input', { type: 'checkbox', id: `id-est-${i}`, 'aria-label': `estimate ${name}`, checked: Boolean(kept.on) }),
        initial: input(`id-initial-${i}`, kept.initial ?? '', { inputmode: 'decimal', placeholder: shown(value), 'aria-label': `${name}: initial value`, 'data-request-path': `${path}.initial` }),
        min: input(`id-min-${i}`, kept.min ?? '', { inputmode: 'decimal', placeholder: '−∞', 'aria-label': `${name}: lower bound`, 'data-request-path': `${path}.min` }),
        max: input(`id-max-${i}`, kept.max ?? '', { inputmode: 'decimal', placeholder: '+∞', 'aria-label': `${name}: upper bound`, 'data-request-path': `${path}.max` }),
      };
      row.on.dataset.requestPath = path;
      return row;
    });
    this.paramsBody.replaceChildren(
      ...this.rows.map((r) =>
        el('tr', { 'data-param': r.name }, el('th', { scope: 'row', text: r.name }), el('td', {}, r.on), ...BOUNDS.map((k) => el('td', {}, r[k]))),
      ),
    );
    if (!this.rows.length) this.paramsBody.append(el('tr', {}, el('td', { colspan: 5, class: 'help', text: 'The model has no params: add one (Params, above) to estimate it.' })));
    const discrete = isDiscrete(model);
    this.formNote.hidden = discrete;
    this.formNote.textContent = discrete ? '' : 'The model in the editor is continuous (a): the identification discretises it as the analysis does — Φ = I + aΔt, u Δt and b Δt per step (METHOD §1.2) — and needs its entries constant in t and a fixed number of steps. Load the example for a discrete one (Φ, system.transition).';
  }

  /** A request's estimate, method and iterations (a server job opened, the example) in the fields. */
  fill(request) {
    this.entries.clear();
    for (const [name, spec] of Object.entries(request.estimate ?? {})) {
      this.entries.set(name, { on: true, ...Object.fromEntries(BOUNDS.map((k) => [k, shown(spec?.[k])])) });
    }
    this.model = this.ctx.model(); // the entries are for it
    this.refreshParams({ fromEntries: true });
    this.method.value = request.method ?? 'scoring';
    this.maxIterations.value = shown(request.max_iterations);
    this.starts.value = startsText(request.starts);
    this.expected.value = request.expected_information === true ? 'yes' : 'no';
    const data = request.data ?? {};
    if (typeof data.csv_text === 'string') this.data.set(data.csv_text, 'the request’s CSV');
    else if (Array.isArray(data.rows)) this.data.set(rowsToCsv(data.rows, this.ctx.model()?.measurement?.names ?? []), 'the request’s rows, as CSV');
    this.saveFields();
  }

  /** The oscillator example: its model into the editor (one Undo away), its request's fields and data here. */
  async loadExample() {
    this.exampleButton.disabled = true;
    try {
      const url = new URL(EXAMPLE, document.baseURI);
      const response = await fetch(url);
      if (!response.ok) throw new Error(`${url.pathname}: ${response.status} ${response.statusText}`);
      const request = await response.json();
      const csvUrl = new URL(request.data.csv, url); // as the CLI reads it: beside the request
      const csv = await fetch(csvUrl);
      if (!csv.ok) throw new Error(`${csvUrl.pathname}: ${csv.status} ${csv.statusText}`);
      const text = await csv.text();
      await this.ctx.loadModel(request.model, 'the identification example');
      this.fill({ ...request, data: {} });
      this.data.set(text, request.data.csv);
      this.saveFields();
      this.bar.setStatus('Loaded the example: its model is in the editor, its data and params here.');
    } catch (e) {
      this.bar.setStatus(`Could not load the example (${e.message ?? e}).`, true);
    } finally {
      this.exampleButton.disabled = false;
    }
  }

  // ------------------------------------------------------------ the request

  /** The request for the current model and form; throws {errors} for unreadable inputs. */
  request() {
    const errors = [];
    const estimate = {};
    for (const r of this.rows) {
      if (!r.on.checked) continue;
      const path = memberPath('estimate', r.name);
      const spec = {};
      for (const k of BOUNDS) {
        const text = r[k].value.trim();
        if (text === '') continue;
        const problem = numberProblem(text);
        if (problem) errors.push({ path: `${path}.${k}`, message: problem });
        else spec[k] = toNumber(text);
      }
      estimate[r.name] = spec;
    }
    if (!this.rows.some((r) => r.on.checked)) errors.push({ path: 'estimate', message: 'tick at least one param to estimate' });
    const text = this.data.value();
    if (text.trim() === '') errors.push({ path: 'data', message: 'no data: upload a CSV file, paste its text or load the example' });
    const request = { model: this.ctx.model(), data: { csv_text: text }, estimate, method: this.method.value };
    const iterations = this.maxIterations.value.trim();
    if (iterations !== '') {
      const problem = numberProblem(iterations, { integer: true, min: 1, max: MAX_ITERATIONS });
      if (problem) errors.push({ path: 'max_iterations', message: problem });
      else request.max_iterations = toNumber(iterations);
    }
    const starts = parseStarts(this.starts.value, Object.keys(estimate));
    errors.push(...starts.errors);
    if (starts.starts.length) request.starts = starts.starts;
    if (this.expected.value === 'yes') request.expected_information = true;
    if (errors.length) throw { kind: 'invalid', title: 'Invalid identification request', errors };
    return request;
  }

  /**
   * The request the data box reads its data with (DataBox.probe): the form's, or, when
   * the form's params cannot be read, one estimating the model's first param — the data
   * are read against the model's grid whatever is estimated.
   */
  probe() {
    const model = this.ctx.model();
    const first = Object.keys(model?.params ?? {})[0];
    if (!model || first === undefined || !isDiscrete(model)) return null;
    try {
      return this.request();
    } catch {
      return { model, data: { csv_text: this.data.value() }, estimate: { [first]: {} } };
    }
  }

  // run: RunView's — the model checked in its own form (a continuous one is discretised
  // by the core), then the run says what the identification needs of it.

  /** The tab is shown: the data read against the model as it is now. */
  shown() {
    this.data.check();
  }

  markStale() {
    super.markStale();
    this.refreshParams();
    this.data.check(); // read against the model as it is now
  }

  // ------------------------------------------------------------ the result

  /** Show a result; `current`: the model has not changed since the run started. */
  show(r, where, current = true) {
    this.result = r;
    this.out.hidden = false;
    this.out.classList.toggle('stale', !current);
    this.out.dataset.where = where;
    const iterations = Math.max(0, r.iterations.length - 1);
    const summary = el('p', {
      id: 'id-summary',
      text: [
        `J = ${fmt(r.neg_log_likelihood)} (−log-likelihood)`,
        `${r.method}, ${iterations} iteration${iterations === 1 ? '' : 's'}, ${r.evaluations} evaluations of J`,
        `D = ${r.steps.toLocaleString('en')} steps, ${r.measurements.toLocaleString('en')} measurements`,
        `${duration(r.timing.wall_ms)} on the ${where === 'browser' ? 'browser (wasm)' : 'server'}`,
        resumedText(r.timing),
      ]
        .filter(Boolean)
        .join(' · '),
    });
    const id = r.identifiability;
    const fit = fitBlock(r);
    this.fitCharts = fit.charts;
    const previous = this.paramSelect.value;
    this.paramSelect.replaceChildren(...r.parameters.map((p) => el('option', { value: p, text: p })));
    if (r.parameters.includes(previous)) this.paramSelect.value = previous;
    this.out.replaceChildren(
      summary,
      el('p', { class: 'stale-note', text: 'The model has changed since this run: run again to update.' }),
      el('p', { id: 'id-stop', class: `id-stop ${r.converged ? 'converged' : 'not-converged'}`, 'data-stop': r.stop, text: `${r.converged ? 'Converged' : 'Not converged'}: ${r.stop_reason}` }),
      el('p', { id: 'id-identifiability', class: `id-verdict ${id.identifiable ? 'identifiable' : 'not-identifiable'}`, 'data-identifiable': String(id.identifiable), text: id.verdict }),
      el('h3', { text: 'Estimates' }),
      this.estimatesTable(r),
      r.correlation ? this.correlationTable(r) : null,
      optimaTable(r),
      fit.root,
      el(
        'div',
        { class: 'downloads' },
        el('button', { type: 'button', id: 'id-download', text: 'Download result JSON', onclick: () => this.ctx.download(`${this.ctx.fileStem()}-identification.json`, 'application/json', JSON.stringify(this.result, null, 2) + '\n') }),
      ),
      el('h3', { text: 'Iterations' }),
      this.chartJ,
      el('div', { class: 'chart-controls' }, el('label', { for: 'id-param', text: 'Param' }), this.paramSelect),
      this.chartParam,
    );
    this.draw();
  }

  estimatesTable(r) {
    const table = el('table', { class: 'criteria id-estimates', id: 'id-estimates' });
    table.append(el('caption', { text: 'Maximum-likelihood estimates, their standard errors from the sample information and 95 % intervals (±1.96 standard errors)' + (r.expected_information ? '; the Cramér–Rao bound on each SKO from the expected information' : '') }));
    const bound = r.expected_information !== null && r.expected_information !== undefined;
    const heads = ['param', 'estimate', 'std error', '95 % interval', ...(bound ? ['Cramér–Rao SKO'] : []), 'initial', 'at a bound'];
    table.append(el('thead', {}, el('tr', {}, ...heads.map((t) => el('th', { scope: 'col', text: t })))));
    const body = el('tbody');
    const num = (key, x) => el('td', { class: 'num', 'data-key': key, 'data-value': x === null || x === undefined ? '' : String(x), title: x === null || x === undefined ? 'undefined' : String(x), text: fmt(x) });
    for (const name of r.parameters) {
      const e = r.estimate[name];
      const interval = e.interval ? `[${fmt(e.interval[0])}, ${fmt(e.interval[1])}]` : '—';
      const bounds = `[${e.min ?? '−∞'}, ${e.max ?? '+∞'}]`;
      body.append(
        el(
          'tr',
          { 'data-param': name },
          el('th', { scope: 'row', text: name }),
          num('value', e.value),
          num('std_error', e.std_error),
          el('td', { class: 'num', 'data-key': 'interval', 'data-value': e.interval ? JSON.stringify(e.interval) : '', text: interval }),
          bound ? num('cramer_rao_sko', e.cramer_rao_sko) : null,
          num('initial', e.initial),
          el('td', { 'data-key': 'at_bound', 'data-value': String(Boolean(e.at_bound)), class: e.at_bound ? 'at-bound' : null, title: `bounds ${bounds}`, text: e.at_bound ? `yes, ${bounds}` : 'no' }),
        ),
      );
    }
    table.append(body);
    return el('div', { class: 'scroll' }, table);
  }

  correlationTable(r) {
    const table = el('table', { class: 'criteria id-correlation', id: 'id-correlation' });
    table.append(el('caption', { text: 'Correlations of the estimates' }));
    table.append(el('thead', {}, el('tr', {}, el('th'), ...r.parameters.map((p) => el('th', { scope: 'col', text: p })))));
    const body = el('tbody');
    r.parameters.forEach((p, i) => {
      body.append(el('tr', {}, el('th', { scope: 'row', text: p }), ...r.correlation[i].map((x) => el('td', { class: 'num', 'data-value': String(x), text: fmt(x) }))));
    });
    table.append(body);
    return el('div', { class: 'scroll' }, table);
  }

  width() {
    return Math.max(320, (this.out.clientWidth || this.root.clientWidth) - 8);
  }

  /** The charts: J against the iteration, and the param chosen's path with its bounds and estimate. */
  draw() {
    const r = this.result;
    // Drawn when the tab is shown (tabs.js calls draw): a hidden chart would have no width.
    if (!r || this.out.hidden || this.root.hidden) return;
    for (const p of this.plots) p.destroy();
    const steps = r.iterations;
    const width = this.width();
    const j = iterationChart(this.chartJ, {
      title: 'J = −log-likelihood against the iteration',
      yLabel: 'J',
      width,
      columns: [{ label: 'J', values: steps.map((s) => s.neg_log_likelihood), stroke: '#1f77b4' }],
    });
    const name = this.paramSelect.value || r.parameters[0];
    const e = r.estimate[name];
    const flat = (x) => steps.map(() => x);
    const columns = [{ label: name, values: steps.map((s) => s.params[name] ?? null), stroke: '#d62728' }];
    if (e.interval) {
      for (const [k, end] of [[0, 'low'], [1, 'high']]) columns.push({ label: `95 % interval, ${end}`, values: flat(e.interval[k]), stroke: '#2ca02c', dash: [6, 4], width: 1 });
    }
    const path = iterationChart(this.chartParam, { title: `${name} against the iteration (estimate ${fmt(e.value)})`, yLabel: name, width, columns });
    this.plots = [j, path, ...this.fitCharts.map((c) => c.draw(width))];
  }
}
