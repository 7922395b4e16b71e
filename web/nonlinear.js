// The Nonlinear tab (METHOD §4, seed 002): the extended Kalman filter and the
// iterative regularised procedure of K filters on a nonlinear model of its own (the
// tab's model box, nonlinear_model.js: the JSON, loaded with the seed-002 preset, and
// fields for the time grid, f and h), on data simulated from a truth or measured
// (nonlinear_data.js), with the α schedule (nonlinear_procedure.js) — in this browser
// (wasm, the core's Sequential executor: the same bits as the server) or as a server
// job of kind `nonlinear`. The result: the γ table, the filters' δ (and true RMS) with
// i* and “stop at the first increase” marked beside the two baselines
// (nonlinear_tables.js), and the charts over time and against i (nonlinear_plots.js).

import { ModelBox, modelText } from './nonlinear_model.js';
import { NonlinearData } from './nonlinear_data.js';
import { Procedure } from './nonlinear_procedure.js';
import { filtersTable, gammaTable, qScaleTable } from './nonlinear_tables.js';
import { CHART_HEIGHT, errorChart, iterateChart, stateChart } from './nonlinear_plots.js';
import { resumedText } from './results.js';
import { RunBar, RunView, duration, el, fmt, markControls, recheckControl, requestErrors, runError, wasmCall } from './views.js';

const KEEP = 'kea-nonlinear';
const KEEP_CSV = 'kea-nonlinear-data'; // apart: written when the data change, not at every key
const CHECK_MS = 400;

/** The control a request path is shown at: the deepest one named by the path or a parent of it. */
function controlFor(root, path) {
  let p = path ?? '';
  while (p) {
    const c = root.querySelector(`[data-request-path="${CSS.escape(p)}"]`);
    if (c) return c;
    p = p.endsWith(']') ? p.slice(0, p.lastIndexOf('[')) : p.slice(0, Math.max(0, p.lastIndexOf('.')));
  }
  return null;
}

/**
 * Mark `errors` at the controls of `root` (markControls); those whose place is the
 * model's text — a member without a field of its own (`model.system.P0[1]`) — are
 * listed under the text with their paths. Returns the errors no control shows.
 */
function placeErrors(root, errors, text) {
  const fields = [];
  const inText = [];
  for (const e of errors) (e.path && e.path !== 'model' && controlFor(root, e.path) === text ? inText : fields).push(e);
  const unplaced = markControls(root, fields);
  if (inText.length) {
    text.setAttribute('aria-invalid', 'true');
    text.classList.add('invalid');
    text.parentElement.append(
      el('ul', { class: 'control-error nl-text-errors', role: 'alert' }, ...inText.map((e) => el('li', { class: 'cell-error', 'data-error-path': e.path, text: `${e.path}: ${e.message}` }))),
    );
  }
  return unplaced;
}

function readKept() {
  try {
    return JSON.parse(sessionStorage.getItem(KEEP) ?? 'null');
  } catch {
    return null;
  }
}

function keep(key, value) {
  try {
    sessionStorage.setItem(key, value);
  } catch {
    // storage off or full: not kept
  }
}

export class NonlinearView extends RunView {
  /** `ctx`: {download(name, type, text)}. */
  constructor(root, ctx) {
    super();
    this.root = root;
    this.ctx = ctx;
    this.result = null;
    this.edits = 0; // the form's changes: a result is current if none came during its run
    this.h = []; // the h of the model the result is of (its measurements drawn with the state they measure)
    this.plots = [];
    this.checkSeq = 0;
    this.build();
  }

  build() {
    this.modelBox = new ModelBox({ onChange: () => this.modelChanged() });
    this.data = new NonlinearData({
      probe: () => this.probe(),
      onChange: () => {
        if (!this.restoring) keep(KEEP_CSV, this.data.csv.value());
        this.changed();
      },
    });
    this.procedure = new Procedure({ onChange: () => this.changed() });
    this.form = el(
      'form',
      {
        class: 'view-form',
        novalidate: true,
        onsubmit: (e) => e.preventDefault(),
        oninput: (e) => recheckControl(e.target, () => requestErrors(() => this.request())),
      },
      el(
        'fieldset',
        { class: 'section' },
        el('legend', { text: 'Nonlinear: the EKF and the iterative regularised procedure (METHOD §4)' }),
        el('p', { class: 'help', text: 'This tab runs a nonlinear model of its own — dx/dt = f(x, t), y = h(x, t), here — not the linear model of the editor.' }),
        this.modelBox.root(),
      ),
      el('fieldset', { class: 'section' }, el('legend', { text: 'Data' }), this.data.root()),
      el(
        'fieldset',
        { class: 'section' },
        el('legend', { text: 'Procedure' }),
        this.procedure.root(),
        el('p', { class: 'help', text: 'K filters over the same data, stepped together (Euler map at Δt, Joseph form): filter k an EKF with R_k = V/γ_k^k, driven also by the earlier filters’ residuals; δ(i), the mean square of the one-step prediction residuals, chooses i*. Beside them the plain EKF and the Q-scale EKFs. Cost ∝ D × (K + 1 + scales) × N³.' }),
      ),
    );
    for (const type of ['input', 'change']) this.form.addEventListener(type, () => this.changed());
    this.bar = new RunBar({ prefix: 'nl', label: 'Run nonlinear', op: 'nonlinear', kind: 'nonlinear', onRun: (where, exec) => this.run(where, exec), onResume: (model, exec) => this.resume(model, exec) });
    this.out = el('div', { id: 'nl-result', class: 'view-result', hidden: true });
    this.stateSelect = el('select', { id: 'nl-state' });
    this.iterateSelect = el('select', { id: 'nl-iterate' });
    for (const s of [this.stateSelect, this.iterateSelect]) s.addEventListener('change', () => this.draw());
    this.charts = Object.fromEntries(['states', 'errors', 'delta', 'rms'].map((k) => [k, el('div', { id: `nl-chart-${k}`, class: 'id-chart' })]));
    new ResizeObserver(() => this.plots.forEach((p) => p.setSize({ width: this.width(), height: CHART_HEIGHT }))).observe(this.out);
    this.root.append(this.form, this.bar.root, this.out);
    this.start();
  }

  /** The fields as they were before a reload, or the preset. */
  async start() {
    const kept = readKept();
    this.restoring = true;
    if (kept && typeof kept === 'object') {
      let csv = null;
      try {
        csv = sessionStorage.getItem(KEEP_CSV);
      } catch {
        // storage off: none
      }
      this.data.restore({ ...kept.data, csv });
      this.procedure.restore(kept.procedure);
    }
    if (typeof kept?.model === 'string' && kept.model.trim() !== '') {
      this.modelBox.set(kept.model);
      this.procedure.model = this.modelBox.model();
    } else {
      try {
        await this.modelBox.loadPreset();
        if (!kept?.procedure) this.procedure.load(this.modelBox.model());
      } catch (e) {
        this.bar.setStatus(`Could not load the preset (${e?.title ?? e?.message ?? e}).`, true);
      }
    }
    this.restoring = false;
    this.root.dataset.ready = 'true';
  }

  /** Keep the fields for this browser tab (over a reload). */
  save() {
    if (this.restoring) return;
    keep(KEEP, JSON.stringify({ model: this.modelBox.value(), data: this.data.kept(), procedure: this.procedure.kept() }));
  }

  changed() {
    this.edits++;
    if (!this.out.hidden) this.out.classList.add('stale');
    this.save();
  }

  modelChanged() {
    const model = this.modelBox.model();
    this.procedure.model = model;
    if (model) this.data.setStates(this.modelBox.states, model);
    this.changed();
    clearTimeout(this.checkTimer);
    this.checkTimer = setTimeout(() => this.checkModel(), CHECK_MS);
    if (this.data.mode() === 'csv') this.data.csv.check();
  }

  /**
   * The core's reading of the model (the wasm module's work estimate of a request with
   * it), marked at the model's fields and under its text as it is typed; the rest of a
   * request is checked by Run.
   */
  async checkModel() {
    const seq = ++this.checkSeq;
    if (this.root.hidden) return; // checked when the tab is shown
    const model = this.modelBox.model();
    let errors = this.modelBox.localErrors();
    if (model) {
      try {
        await wasmCall('nonlinear_work', { request: JSON.stringify({ model, procedure: { alpha: [1] }, data: { truth: { seed: 1 } }, q_scale: [] }) });
      } catch (e) {
        errors = (e?.errors ?? []).filter((x) => x.path === 'model' || x.path?.startsWith('model.') || x.path?.startsWith('model['));
      }
    }
    if (seq !== this.checkSeq) return; // edited since
    placeErrors(this.modelBox.box, errors, this.modelBox.text);
  }

  // ------------------------------------------------------------ the request

  /** The request of the form; throws {errors} for fields that do not read. */
  request() {
    const errors = [...this.modelBox.localErrors()];
    const p = this.procedure.request();
    const d = this.data.request();
    errors.push(...p.errors, ...d.errors);
    if (errors.length) throw { kind: 'invalid', title: 'Invalid nonlinear request', errors };
    const request = { model: this.modelBox.model(), data: d.data, procedure: p.procedure };
    if (p.q_scale) request.q_scale = p.q_scale;
    if (p.trace_points !== undefined) request.trace_points = p.trace_points;
    return request;
  }

  /** The request a CSV is read with (DataBox.probe): the model's, without baselines. */
  probe() {
    const model = this.modelBox.model();
    return model ? { model, data: { csv_text: this.data.csv.value() }, q_scale: [] } : null;
  }

  /** The request, its model's text read as the core reads JSON (a key twice, 1e400: refused). */
  async strictRequest() {
    const request = this.request();
    try {
      await wasmCall('parse', { bytes: new TextEncoder().encode(this.modelBox.value()) });
    } catch (e) {
      throw { kind: 'invalid', title: 'Invalid nonlinear model', errors: [{ path: 'model', message: `the model’s text: ${e?.title ?? e}` }] };
    }
    return request;
  }

  /** Not RunView's: this tab's model is its own, so the editor's changes leave its result current. */
  markStale() {}

  async run(where, exec) {
    try {
      const request = await this.strictRequest();
      markControls(this.form, []);
      return await this.follow(where, () => exec(request), request.model); // exec serialises the request at once
    } catch (e) {
      throw this.failed(e);
    }
  }

  /** A run's errors: every one of this tab's (the model is its own), at its field or under the model's text. */
  failed(e) {
    const errors = e?.errors ?? [];
    const unplaced = placeErrors(this.form, errors, this.modelBox.text);
    return runError(e, errors, [], unplaced);
  }

  /** Wait for a run's result and show it: current if the form has not changed since. Returns the job's id. */
  async follow(where, exec, model) {
    const edits = this.edits;
    const { result, job } = await exec();
    this.h = Array.isArray(model?.measurement?.h) ? model.measurement.h : [];
    this.show(result, where, this.edits === edits);
    return job;
  }

  /** A server job opened from the Server tab: its request in the fields, then the job followed. */
  async openJob(id, request, model, body) {
    await this.fill(request);
    return this.bar.open(id, model, body);
  }

  /** A request (a server job opened) in the fields: its model (a preset's by name), data and procedure. */
  async fill(request) {
    let model = request.model;
    if (typeof model === 'string' && model.startsWith('preset:')) {
      const text = await wasmCall('nonlinear_preset', { name: model.slice('preset:'.length) });
      model = text ? JSON.parse(text) : null;
    }
    if (model && typeof model === 'object') {
      if (request.set && typeof request.set === 'object') model = { ...model, params: { ...(model.params ?? {}), ...request.set } };
      this.modelBox.set(`${modelText(model)}\n`);
    }
    this.procedure.fill({ ...request, model });
    this.data.fill(request.data);
    keep(KEEP_CSV, this.data.csv.value());
    this.save();
  }

  /** The tab is shown: the model checked as it is now, and the CSV read against it. */
  shown() {
    clearTimeout(this.checkTimer);
    this.checkModel();
    if (this.data.mode() === 'csv') this.data.csv.check();
  }

  // ------------------------------------------------------------ the result

  /** Show a result; `current`: the form has not changed since the run started. */
  show(r, where, current = true) {
    this.result = r;
    this.out.hidden = false;
    this.out.classList.toggle('stale', !current);
    this.out.dataset.where = where;
    const K = r.iterates.length;
    const measured = r.measured.reduce((a, b) => a + b, 0);
    const summary = el('p', {
      id: 'nl-summary',
      text: [
        `K = ${K} filter${K === 1 ? '' : 's'} (${r.earlier_residuals} residuals of the earlier ones)`,
        `D = ${r.steps.toLocaleString('en')} steps of Δt = ${fmt(r.dt)}, ${measured.toLocaleString('en')} measured values`,
        `${duration(r.timing.wall_ms)} on the ${where === 'browser' ? 'browser (wasm)' : 'server'}`,
        resumedText(r.timing),
      ]
        .filter(Boolean)
        .join(' · '),
    });
    const choice = el(
      'p',
      { id: 'nl-choice', class: 'nl-choice', 'data-i-star': String(r.i_star), 'data-i-stop': String(r.i_stop_first_increase) },
      el('strong', { text: `i* = ${r.i_star}` }),
      ` (least δ on the one-step predictions); stop at the first increase of δ: iterate ${r.i_stop_first_increase}${r.i_stop_first_increase === K ? ' (δ never increases)' : ''}`,
      r.best_rms ? `; least true RMS: ${r.states.map((s, j) => `${s} at iterate ${r.best_rms[j] ?? '—'}`).join(', ')}` : '',
      '.',
    );
    const fill = (select, options, value) => {
      const previous = select.value;
      select.replaceChildren(...options.map(([v, text]) => el('option', { value: v, text })));
      select.value = options.some(([v]) => v === previous) && value === null ? previous : value ?? options[0][0];
    };
    fill(this.stateSelect, r.states.map((s, i) => [String(i), s]), null);
    fill(this.iterateSelect, r.iterates.map((s) => [String(s.i), `iterate ${s.i}${s.i === r.i_star ? ' (i*)' : ''}`]), String(r.i_star));
    const truth = Boolean(r.traces.truth);
    const parts = [
      summary,
      el('p', { class: 'stale-note', text: 'The fields have changed since this run: run again to update.' }),
      choice,
      r.ignored_columns?.length ? el('p', { class: 'help', id: 'nl-ignored', text: `Columns not used: ${r.ignored_columns.join(', ')}.` }) : null,
      el('h3', { text: 'The filters' }),
      filtersTable(r),
      qScaleTable(r),
      el('h3', { text: 'The weights γ' }),
      gammaTable(r),
      el(
        'div',
        { class: 'downloads' },
        el('button', { type: 'button', id: 'nl-download', text: 'Download result JSON', onclick: () => this.ctx.download('nonlinear-result.json', 'application/json', JSON.stringify(this.result, null, 2) + '\n') }),
      ),
      el('h3', { text: 'Over time' }),
      el('div', { class: 'chart-controls' }, el('label', { for: 'nl-state', text: 'State' }), this.stateSelect, el('label', { for: 'nl-iterate', text: 'Iterate shown' }), this.iterateSelect),
      el('p', { class: 'help nl-band-note', id: 'nl-band-note', text: 'The shaded band is filter 1’s ±2σ (√P⁺ of iterate 1, the EKF when α₀ = 1). No band is drawn for the iterates k ≥ 2: their P is not the error covariance of their estimate (METHOD §4).' }),
      this.charts.states,
      truth ? this.charts.errors : el('p', { class: 'help', text: 'No truth in the data (a CSV without STATE_true columns): no errors to draw.' }),
      el('h3', { text: 'Against the iterate' }),
      this.charts.delta,
      truth ? this.charts.rms : null,
    ];
    this.out.replaceChildren(...parts.filter(Boolean));
    this.draw();
  }

  width() {
    return Math.max(320, (this.out.clientWidth || this.root.clientWidth) - 8);
  }

  draw() {
    const r = this.result;
    // Drawn when the tab is shown (tabs.js calls draw): a hidden chart would have no width.
    if (!r || this.out.hidden || this.root.hidden) return;
    for (const p of this.plots) p.destroy();
    this.plots = [];
    const width = this.width();
    const i = Number(this.stateSelect.value) || 0;
    const k = Number(this.iterateSelect.value) || r.i_star;
    if (r.traces.t.length >= 2) {
      this.plots.push(stateChart(this.charts.states, r, i, k, width, this.h));
      if (r.traces.truth) this.plots.push(errorChart(this.charts.errors, r, i, k, width));
    } else this.charts.states.replaceChildren(el('p', { class: 'help', text: 'No trace points (trace points 0): nothing to draw over time.' }));
    const chosen = r.q_scale.chosen;
    const q = chosen === null || chosen === undefined ? null : r.q_scale.grid[chosen];
    this.plots.push(
      iterateChart(this.charts.delta, r, {
        title: `δ(i), the mean square of the one-step prediction residuals, against the iterate (i* = ${r.i_star})`,
        yLabel: 'δ',
        values: r.iterates.map((s) => s.delta),
        flat: [{ label: 'EKF', value: r.ekf.delta, stroke: '#d62728' }, ...(q ? [{ label: `EKF, W × ${fmt(q.scale)}`, value: q.delta, stroke: '#2ca02c' }] : [])],
        width,
      }),
    );
    if (r.traces.truth && r.ekf.rms) {
      const s = r.states[i];
      this.plots.push(
        iterateChart(this.charts.rms, r, {
          title: `${s}: the true RMS of x⁺ − x_true against the iterate (what no user can know)`,
          yLabel: `RMS ${s}`,
          values: r.iterates.map((it) => it.rms[i]),
          flat: [{ label: 'EKF', value: r.ekf.rms[i], stroke: '#d62728' }, ...(q ? [{ label: `EKF, W × ${fmt(q.scale)}`, value: q.rms[i], stroke: '#2ca02c' }] : [])],
          width,
        }),
      );
    }
  }
}
