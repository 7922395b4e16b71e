// The Monte Carlo tab (docs/monte-carlo.md): R simulated runs of the current model,
// in this browser (wasm, the core's Sequential executor: bit-identical to the server
// for the same seed) or as a server job of kind `monte_carlo`; the potential SKO √R_ii
// against the sample SKO of the filtered error (and the bound χ) per state, the
// consistency verdicts (NEES, NIS, per state), and the criteria sets side by side.
// With "Truth params" (NAME=VALUE, as beside Run; docs/mismatch.md) the runs imitate
// the truth and the filter stays the model's: the actual SKO of that mismatched filter
// is drawn beside, and judged against the sample in the consistency table.

import uPlot from './vendor/uplot/uPlot.esm.js';
import { MAX_SAFE, numberProblem, toNumber } from './numbers.js';
import { valueAxis } from './plot.js';
import { parseTruth } from './mismatch.js';
import { noTraces, resumedText } from './results.js';
import { KeptFields, RunBar, RunView, duration, el, field, fmt, input, recheckControl, requestErrors, select, wasmCall } from './views.js';

const SETS = ['bound', 'covariance', 'monte_carlo'];
const CRITERIA = [
  ['yz', 'F_YZ'],
  ['zx', 'F_ZX'],
  ['yx', 'F_YX'],
];
const SERIES = [
  ['potential_sko', 'potential SKO √R_ii', '#9467bd', []],
  ['filtered_sko', 'real: sample SKO of X − truth', '#d62728', []],
  ['actual_sko', 'actual SKO (the model’s filter in the truth)', '#ff7f0e', [2, 3]],
  ['chi', 'bound χ', '#2ca02c', [6, 4]],
];

export class MonteCarloView extends RunView {
  /** `ctx`: {model(), showModelErrors(errors), download(name, type, text), fileStem()}. */
  constructor(root, ctx) {
    super();
    this.root = root;
    this.ctx = ctx;
    this.result = null;
    this.edits = 0; // model changes seen (markStale): a result is current if none came during its run
    this.plot = null;
    this.build();
  }

  build() {
    this.runs = input('mc-runs', '200', { inputmode: 'numeric', 'data-request-path': 'runs' });
    this.seed = input('mc-seed', '1', { inputmode: 'numeric', 'data-request-path': 'seed' });
    this.truth = select('mc-truth', [['process', 'process: Y (Kalman reading)'], ['mean', 'mean: y (the seed’s reading)']], 'process');
    this.truth.dataset.requestPath = 'truth';
    this.truthSet = input('mc-truth-set', '', { placeholder: 'e.g. sd=10, f_f=0.3', 'data-request-path': 'truth.set' });
    this.modelError = select('mc-model-error', [['white', 'white (drawn every step)'], ['constant', 'constant (once per run)']], 'white');
    this.modelError.dataset.requestPath = 'model_error';
    this.tracePoints = input('mc-trace-points', '', { inputmode: 'numeric', placeholder: 'model’s', 'data-request-path': 'trace_points' });
    this.form = el(
      'form',
      { class: 'view-form', novalidate: true, onsubmit: (e) => e.preventDefault(), oninput: (e) => recheckControl(e.target, () => requestErrors(() => this.request())) },
      el(
        'fieldset',
        { class: 'section' },
        el('legend', { text: 'Monte Carlo: real against potential accuracy' }),
        el(
          'div',
          { class: 'row' },
          field('Runs R', this.runs),
          field('Seed', this.seed),
          field('Truth', this.truth),
          field('Truth params', this.truthSet),
          field('Model error F', this.modelError),
          field('Trace points', this.tracePoints),
        ),
        el('p', { class: 'help', text: 'Each run draws its own ChaCha8 stream of the seed: the same seed gives bit-identical results in the browser and on the server. Cost ∝ R × D × N². Truth params (NAME=VALUE, …): the runs imitate the model with these values, the filter stays designed on the model — a mismatched filter, whose actual SKO is drawn beside.' }),
      ),
    );
    this.bar = new RunBar({ prefix: 'mc', label: 'Run Monte Carlo', op: 'simulate', kind: 'monte_carlo', onRun: (where, exec) => this.run(where, exec), onResume: (model, exec) => this.resume(model, exec) });
    this.out = el('div', { id: 'mc-result', class: 'view-result', hidden: true });
    this.stateSelect = el('select', { id: 'mc-state' });
    this.log = el('input', { type: 'checkbox', id: 'mc-log' });
    this.chart = el('div', { id: 'mc-chart', class: 'mc-chart' });
    this.stateSelect.addEventListener('change', () => this.draw());
    this.log.addEventListener('change', () => this.draw());
    new ResizeObserver(() => this.plot?.setSize({ width: this.width(), height: 320 })).observe(this.chart);
    this.root.append(this.form, this.bar.root, this.out);
    // The fields as they were before a reload (they do not depend on the model).
    this.kept = new KeptFields('kea-monte-carlo', [[this.runs], [this.seed], [this.truth], [this.truthSet], [this.modelError], [this.tracePoints]]);
    this.kept.restore();
    for (const type of ['input', 'change']) this.form.addEventListener(type, () => this.kept.save());
  }

  /** A request's settings (a server job opened) in the fields. */
  fill(request) {
    this.runs.value = String(request.runs ?? '');
    this.seed.value = String(request.seed ?? 1); // the defaults of the request format
    const mismatched = typeof request.truth === 'object' && request.truth !== null;
    this.truth.value = mismatched ? 'process' : request.truth ?? 'process';
    const set = mismatched && !request.truth.model ? request.truth.set ?? {} : {};
    this.truthSet.value = Object.entries(set).map(([k, v]) => `${k}=${v}`).join(', ');
    this.modelError.value = request.model_error ?? 'white';
    this.tracePoints.value = request.trace_points === undefined ? '' : String(request.trace_points);
    this.kept.save();
  }

  /** The request for the current model and form; throws {errors} for unreadable inputs. */
  request() {
    const errors = [];
    // `below`: the message for a whole number under `min`.
    const whole = (control, path, { optional = false, min = 0, seed = false, below } = {}) => {
      if (optional && control.value.trim() === '') return undefined;
      const problem = numberProblem(control.value, { integer: true, min });
      if (problem) {
        const x = toNumber(control.value);
        const why =
          below && Number.isInteger(x) && x < min ? `${below}, got ${x}`
          : seed && /2\^53/.test(problem) ? problem
          : seed ? `${problem}; a seed is a whole number from 0 to 2^53 − 1 = ${MAX_SAFE}`
          : problem;
        errors.push({ path, message: why });
      }
      return toNumber(control.value);
    };
    const request = {
      model: this.ctx.model(),
      // The core's rule and words (sample SKOs need two runs), here before a request.
      runs: whole(this.runs, 'runs', { min: 2, below: 'at least 2 runs are needed for sample SKOs' }),
      seed: whole(this.seed, 'seed', { seed: true }),
      truth: this.truth.value,
      model_error: this.modelError.value,
    };
    try {
      const truth = parseTruth(this.truthSet.value);
      if (truth && this.truth.value === 'mean') errors.push({ path: 'truth', message: 'truth params imitate the truth’s process: choose Truth = process' });
      else if (truth) request.truth = truth;
    } catch (message) {
      errors.push({ path: 'truth.set', message: String(message) });
    }
    const tp = whole(this.tracePoints, 'trace_points', { optional: true });
    if (tp !== undefined) request.trace_points = tp;
    if (errors.length) throw { kind: 'invalid', title: 'Invalid Monte Carlo request', errors };
    return request;
  }


  /** Show a result; `current`: the model has not changed since the run started. */
  show(r, where, current = true) {
    this.result = r;
    this.out.hidden = false;
    this.out.classList.toggle('stale', !current);
    this.out.dataset.where = where;
    const q = r.request;
    const summary = el('p', {
      id: 'mc-summary',
      text: [
        `R = ${q.runs.toLocaleString('en')} runs, seed ${q.seed}, truth ${r.final.actual_sko ? 'the truth params’ process' : q.truth}, model error ${q.model_error}`,
        `D = ${r.steps.toLocaleString('en')} steps, Δt = ${fmt(r.dt)}, t ∈ [${fmt(r.t0)}, ${fmt(r.t_end)}]`,
        `${duration(r.timing.wall_ms)} on the ${where === 'browser' ? 'browser (wasm)' : 'server'}`,
        resumedText(r.timing),
      ]
        .filter(Boolean)
        .join(' · '),
    });
    const warnings = el('ul', { class: 'mc-warnings' }, ...r.warnings.map((w) => el('li', { text: w })));
    const previous = this.stateSelect.value;
    this.stateSelect.replaceChildren(...r.states.map((s, i) => el('option', { value: String(i), text: s })));
    if (previous && Number(previous) < r.states.length) this.stateSelect.value = previous;
    const parts = [
      summary,
      el('p', { class: 'stale-note', text: 'The model has changed since this run: run again to update.' }),
      r.warnings.length ? warnings : null,
      el('h3', { text: 'Potential against real' }),
      el('div', { class: 'chart-controls' }, el('label', { for: 'mc-state', text: 'State' }), this.stateSelect, el('label', {}, this.log, ' log scale')),
      this.chart,
      el('h3', { text: 'Consistency' }),
      this.consistencyTable(r.consistency),
      el('h3', { text: 'Criteria: bound, covariance, Monte Carlo' }),
      this.criteriaTable(r),
      el(
        'div',
        { class: 'downloads' },
        el('button', { type: 'button', id: 'mc-download', text: 'Download result JSON', onclick: () => this.ctx.download(`${this.ctx.fileStem()}-monte-carlo.json`, 'application/json', JSON.stringify(this.result, null, 2) + '\n') }),
        el('button', { type: 'button', id: 'mc-download-csv', text: 'Download traces CSV', onclick: () => this.downloadCsv() }),
      ),
    ];
    this.out.replaceChildren(...parts.filter(Boolean));
    this.draw();
  }

  /** The traces as CSV, the same text as `kea monte-carlo --csv` (the core's, via wasm). */
  async downloadCsv() {
    const csv = await wasmCall('monte_carlo_csv', { result: JSON.stringify(this.result) });
    this.ctx.download(`${this.ctx.fileStem()}-monte-carlo-traces.csv`, 'text/csv', csv);
  }

  consistencyTable(c) {
    const pct = (x) => (x === null || x === undefined ? '—' : `${fmt(100 * x)} %`);
    const band = (b) => `[${fmt(b[0])}, ${fmt(b[1])}]`;
    const verdict = (v) => el('td', { class: `verdict ${v}`, 'data-verdict': v, text: v });
    const table = el('table', { class: 'criteria mc-consistency', id: 'mc-consistency' });
    table.append(el('caption', { text: `Time averages against the ${fmt(100 * c.band_probability)} % χ² band of one step for R runs (optimistic: real errors larger than the potential ones)` }));
    table.append(
      el('thead', {}, el('tr', {}, ...['statistic', 'time average', 'band', 'steps in band', 'verdict'].map((t) => el('th', { scope: 'col', text: t })))),
    );
    const body = el('tbody');
    for (const [key, label] of [['nees', 'NEES'], ['nis', 'NIS']]) {
      const s = c[key];
      body.append(
        el(
          'tr',
          { 'data-stat': key },
          el('th', { scope: 'row', text: `${label} (dof ${fmt(s.dof)})` }),
          el('td', { class: 'num', 'data-value': s.time_average ?? '', text: fmt(s.time_average) }),
          el('td', { class: 'num', text: band(s.band) }),
          el('td', { class: 'num', text: pct(s.fraction_in_band) }),
          verdict(s.verdict),
        ),
      );
    }
    c.per_state.forEach((s, i) => {
      const bias = s.normalised_bias === null || s.normalised_bias === undefined ? '' : `; mean error / SKO ${fmt(s.normalised_bias)}`;
      body.append(
        el(
          'tr',
          { 'data-stat': `state-${i}`, class: i === 0 ? 'sep' : null },
          el('th', { scope: 'row', text: `${s.state}: s² / R_ii`, title: `sample variance of the filtered error over the potential one${bias}` }),
          el('td', { class: 'num', 'data-value': s.variance_ratio ?? '', text: fmt(s.variance_ratio) }),
          el('td', { class: 'num', text: band(s.band) }),
          el('td', { class: 'num', text: pct(s.fraction_in_band) }),
          verdict(s.verdict),
        ),
      );
    });
    (c.per_state_actual ?? []).forEach((s, i) => {
      body.append(
        el(
          'tr',
          { 'data-stat': `actual-${i}`, class: i === 0 ? 'sep' : null },
          el('th', { scope: 'row', text: `${s.state}: s² / actual σ²`, title: `sample variance of the filtered error about its mean over the actual one of the model’s filter in the truth; mean error less the actual bias / SKO ${fmt(s.normalised_bias)}` }),
          el('td', { class: 'num', 'data-value': s.variance_ratio ?? '', text: fmt(s.variance_ratio) }),
          el('td', { class: 'num', text: band(s.band) }),
          el('td', { class: 'num', text: pct(s.fraction_in_band) }),
          verdict(s.verdict),
        ),
      );
    });
    table.append(body);
    return el('div', { class: 'scroll' }, table);
  }

  criteriaTable(r) {
    const table = el('table', { class: 'criteria', id: 'mc-criteria' });
    table.append(el('caption', { text: 'Criteria (> 1 = an effect, highlighted) from the bound, the covariance (cov.) and the sample SKOs of the runs (MC)' }));
    const head1 = el('tr', {}, el('th', { rowspan: 2, scope: 'col', text: 'state' }));
    const head2 = el('tr');
    for (const [, label] of CRITERIA) {
      head1.append(el('th', { colspan: 3, scope: 'colgroup', text: label }));
      for (const set of SETS) head2.append(el('th', { scope: 'col', title: set, text: { bound: 'bound', covariance: 'cov.', monte_carlo: 'MC' }[set] }));
    }
    table.append(el('thead', {}, head1, head2));
    const body = el('tbody');
    const cell = (set, key, row, value) =>
      el('td', {
        class: `num${value !== null && value > 1 ? ' effect' : ''}${set === 'monte_carlo' ? ' mc' : ''}`,
        'data-set': set,
        'data-criterion': key,
        'data-row': row,
        'data-value': value === null || value === undefined ? '' : String(value),
        title: value === null || value === undefined ? 'undefined' : String(value),
        text: fmt(value),
      });
    r.criteria.bound.per_state.forEach((ps, i) => {
      const tr = el('tr', {}, el('th', { scope: 'row', text: ps.state }));
      for (const [key] of CRITERIA) for (const set of SETS) tr.append(cell(set, key, String(i), r.criteria[set]?.per_state[i]?.[key] ?? null));
      body.append(tr);
    });
    const tr = el('tr', { class: 'weighted' }, el('th', { scope: 'row', text: 'weighted' }));
    for (const [key] of CRITERIA) for (const set of SETS) tr.append(cell(set, key, 'weighted', r.criteria[set]?.weighted?.[key] ?? null));
    body.append(tr);
    table.append(body);
    return el('div', { class: 'scroll' }, table);
  }

  width() {
    return Math.max(320, (this.chart.clientWidth || this.root.clientWidth) - 8);
  }

  draw() {
    const r = this.result;
    if (!r) return;
    this.plot?.destroy();
    this.plot = null;
    // The model's trace points = 0 leave the final row alone: nothing to draw over time.
    if (r.traces.t.length < 2) {
      this.chart.replaceChildren(
        noTraces('No trace points requested: the model’s trace points are 0 (give Trace points above to plot the runs over time).'),
      );
      return;
    }
    const i = Number(this.stateSelect.value) || 0;
    const log = this.log.checked;
    const trace = r.traces.states[i];
    // On a linear scale the axis fits potential and real; a much larger χ (|A| makes it
    // grow fast for oscillating blocks) runs off the top instead of flattening them.
    const top = (key) => Math.max(0, ...(trace[key] ?? []).filter((v) => v !== null && Number.isFinite(v)));
    const fitted = Math.max(top('potential_sko'), top('filtered_sko'), top('actual_sko'));
    const clipChi = !log && fitted > 0 && top('chi') > 3 * fitted;
    const yTop = clipChi ? fitted * 1.15 : null;
    // A χ (nearly) all beyond the top is not drawn: its few first points inside (a
    // growing bound starts small) made a stroke up the left edge that read as a marker.
    // Its legend says where it is, and its value at the cursor is still given.
    const under = clipChi ? (trace.chi ?? []).filter((v) => v !== null && v <= yTop).length : 0;
    const chiGone = clipChi && under < 0.02 * trace.chi.length;
    const columns = SERIES.filter(([key]) => trace[key]).map(([key, label, stroke, dash]) => ({ key, values: trace[key], label, stroke, dash }));
    const x = valueAxis([r.traces.t]);
    const y = valueAxis(columns.map((c) => c.values), { log, top: yTop });
    const shown = (axis) => (_, v) => (v === null || v === undefined ? '—' : fmt(axis.value(v)));
    const gone = (c) => c.key === 'chi' && chiGone;
    const data = [x.data(r.traces.t), ...columns.map((c) => (gone(c) ? c.values.map(() => null) : y.data(c.values)))];
    const series = [{ label: 't', value: shown(x) }];
    for (const c of columns) {
      const { key, label, stroke, dash, values } = c;
      const text = key !== 'chi' || !clipChi ? label : chiGone ? `${label} (beyond the top; log scale shows it)` : `${label} (runs off the top)`;
      const value = gone(c) ? (_, __, ___, i) => (i === null || i === undefined ? '—' : fmt(values[i])) : shown(y);
      series.push({ label: text, stroke, width: key === 'filtered_sko' ? 1.2 : 2, dash, value });
    }
    this.chart.replaceChildren();
    this.plot = new uPlot(
      {
        title: `${trace.state}: potential SKO √R_ii against the real one (R = ${r.request.runs} runs)`,
        width: this.width(),
        height: 320,
        scales: { x: { time: false, ...x.scale }, y: y.scale },
        axes: [
          { label: 't', ...x.axis },
          { label: 'SKO', size: 70, ...y.axis },
        ],
        series,
        legend: { live: true },
        // The tick labels drawn, for a reader of the page's text (and its tests).
        hooks: { draw: [() => (this.chart.dataset.yTicks = y.ticks().join(' | '))] },
      },
      data,
      this.chart,
    );
  }
}
