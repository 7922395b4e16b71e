// The Nonlinear tab's procedure (web/nonlinear.js): the regularisation steps α_0 …
// α_(K−1) as an editable list (K filters; sent as `procedure.alpha`, over the model's
// own `procedure`), which residuals of the earlier filters enter a later one, and the
// two baselines' settings: the Q-scale grid (`q_scale`; [] for none) and the trace
// points.

import { numberProblem, toNumber } from './numbers.js';
import { el, field, input, select } from './views.js';

const DEFAULT_ALPHA = [1, 0.8, 0.6, 0.5, 0.4, 0.3]; // the core's (nonlinear::request::DEFAULT_ALPHA)
const MAX_FILTERS = 16; // nonlinear::request::MAX_FILTERS
const MAX_Q_SCALES = 64;
const MAX_TRACE_POINTS = 100000;
const RESIDUALS = [
  ['posterior', 'posterior, y − h(x_i⁺)'],
  ['prior', 'prior, y − h(x_i⁻)'],
];

/** k as a subscript: α₀, α₁₂. */
export function sub(k) {
  return String(k).replace(/\d/g, (d) => '₀₁₂₃₄₅₆₇₈₉'[d]);
}

export class Procedure {
  /** `onChange()`: a field changed (a row added or removed too). */
  constructor({ onChange }) {
    this.onChange = onChange;
    this.list = el('ol', { class: 'nl-alpha', id: 'nl-alpha', 'data-request-path': 'procedure.alpha', start: 0 });
    this.add = el('button', { type: 'button', id: 'nl-alpha-add', text: '+ α', title: 'Another filter: one more regularisation step', onclick: () => this.addRow('') });
    this.fromModel = el('button', { type: 'button', id: 'nl-alpha-model', text: 'Reset to the model’s', title: 'The α schedule and residuals of the model’s procedure (or the core’s defaults)', onclick: () => this.load(this.model, true) });
    this.residuals = select('nl-residuals', RESIDUALS, 'posterior');
    this.residuals.dataset.requestPath = 'procedure.earlier_residuals';
    this.qOn = el('input', { type: 'checkbox', id: 'nl-q-on', checked: true, 'data-request-path': 'q_scale' });
    this.qScales = input('nl-q-scales', '', { placeholder: '10^−2 … 10^3, 21 scales', 'data-request-path': 'q_scale' });
    this.qOn.addEventListener('change', () => (this.qScales.disabled = !this.qOn.checked));
    this.tracePoints = input('nl-trace-points', '', { inputmode: 'numeric', placeholder: '1000', 'data-request-path': 'trace_points' });
    this.model = null;
    this.load(null);
  }

  root() {
    const qField = el(
      'div',
      { class: 'field nl-q' },
      el('label', { for: 'nl-q-scales', text: 'Q-scale baseline: scales of W' }),
      el('div', { class: 'row' }, el('label', { class: 'check' }, this.qOn, ' run it'), this.qScales),
      el('small', { class: 'help', id: 'nl-q-scales-help', text: 'EKFs with W × each scale (comma-separated; empty: the default grid), the scale chosen by the same δ — a fair baseline, that needs no truth either.' }),
    );
    this.qScales.setAttribute('aria-describedby', 'nl-q-scales-help');
    return el(
      'div',
      { class: 'nl-procedure' },
      el(
        'div',
        { class: 'field wide' },
        el('span', { class: 'label', id: 'nl-alpha-label', text: 'Regularisation steps α₀ … α_(K−1) (one filter each)' }),
        el('div', { class: 'row' }, this.list, this.add, this.fromModel),
        el('small', { class: 'help', text: 'Filter k’s measurement noise is V/γ_k^k, with γ_i^k = α_(i−1)(1 − α_i²)…(1 − α_(k−1)²); α₀ = 1 makes filter 1 the EKF; 0 < α_j < 1 for j ≥ 1. Sent as procedure.alpha, over the model’s own.' }),
      ),
      el('div', { class: 'row' }, field('Earlier filters’ residuals', this.residuals), qField, field('Trace points', this.tracePoints)),
    );
  }

  /** A row of the list: α's field and its ×. */
  addRow(value) {
    const k = this.list.children.length;
    const alpha = input(`nl-alpha-${k}`, value, { inputmode: 'decimal', 'data-request-path': `procedure.alpha[${k}]` });
    const remove = el('button', { type: 'button', class: 'nl-alpha-remove', text: '×', title: `Remove α${k}`, 'aria-label': `Remove α${k}` });
    const item = el('li', {}, el('label', { for: alpha.id, text: `α${sub(k)}` }), alpha, remove);
    remove.addEventListener('click', () => {
      item.remove();
      this.renumber();
      this.onChange?.();
    });
    this.list.append(item);
    this.add.disabled = this.list.children.length >= MAX_FILTERS;
    if (value === '') {
      alpha.focus();
      this.onChange?.();
    }
  }

  /** Each row's ids and paths after a removal. */
  renumber() {
    [...this.list.children].forEach((item, k) => {
      const [label, alpha, remove] = item.children;
      alpha.id = `nl-alpha-${k}`;
      alpha.dataset.requestPath = `procedure.alpha[${k}]`;
      label.htmlFor = alpha.id;
      label.textContent = `α${sub(k)}`;
      remove.title = `Remove α${k}`;
      remove.setAttribute('aria-label', `Remove α${k}`);
    });
    this.add.disabled = this.list.children.length >= MAX_FILTERS;
  }

  /** The schedule and the residuals of `model`'s procedure (the core's defaults without it). */
  load(model, changed = false) {
    this.model = model;
    const p = model?.procedure ?? {};
    const alpha = Array.isArray(p.alpha) ? p.alpha : DEFAULT_ALPHA;
    this.setAlpha(alpha.map((a) => String(a)));
    this.residuals.value = p.earlier_residuals === 'prior' ? 'prior' : 'posterior';
    if (changed) this.onChange?.();
  }

  setAlpha(texts) {
    this.list.replaceChildren();
    for (const t of texts) this.addRow(t);
  }

  alphaTexts() {
    return [...this.list.querySelectorAll('input')].map((i) => i.value);
  }

  /** The request's members: {procedure, q_scale?, trace_points?, errors}. */
  request() {
    const errors = [];
    const alpha = this.alphaTexts().map((text, k) => {
      const problem = numberProblem(text);
      if (problem) errors.push({ path: `procedure.alpha[${k}]`, message: problem });
      return toNumber(text);
    });
    if (!alpha.length) errors.push({ path: 'procedure.alpha', message: 'give at least one α (α₀ = 1: filter 1 is the EKF)' });
    const out = { procedure: { alpha, earlier_residuals: this.residuals.value }, errors };
    if (!this.qOn.checked) out.q_scale = [];
    else if (this.qScales.value.trim() !== '') {
      const items = this.qScales.value.split(',').map((s) => s.trim());
      const bad = items.map((s) => [s, numberProblem(s)]).find(([, p]) => p);
      if (bad) errors.push({ path: 'q_scale', message: `“${bad[0]}”: ${bad[1]}` });
      else if (items.length > MAX_Q_SCALES) errors.push({ path: 'q_scale', message: `${items.length} scales; at most ${MAX_Q_SCALES}` });
      out.q_scale = items.map(toNumber);
    }
    if (this.tracePoints.value.trim() !== '') {
      const problem = numberProblem(this.tracePoints.value, { integer: true, min: 0, max: MAX_TRACE_POINTS });
      if (problem) errors.push({ path: 'trace_points', message: problem });
      out.trace_points = toNumber(this.tracePoints.value);
    }
    return out;
  }

  /** A request's members (a server job opened) in the fields. */
  fill(request) {
    const p = request.procedure ?? {};
    const alpha = Array.isArray(p.alpha) ? p.alpha : Array.isArray(request.model?.procedure?.alpha) ? request.model.procedure.alpha : DEFAULT_ALPHA;
    this.setAlpha(alpha.map(String));
    this.residuals.value = (p.earlier_residuals ?? request.model?.procedure?.earlier_residuals) === 'prior' ? 'prior' : 'posterior';
    const q = request.q_scale;
    this.qOn.checked = !(Array.isArray(q) && q.length === 0);
    this.qScales.disabled = !this.qOn.checked;
    this.qScales.value = Array.isArray(q) && q.length ? q.join(', ') : '';
    this.tracePoints.value = request.trace_points === undefined ? '' : String(request.trace_points);
  }

  kept() {
    return { alpha: this.alphaTexts(), residuals: this.residuals.value, qOn: this.qOn.checked, qScales: this.qScales.value, tracePoints: this.tracePoints.value };
  }

  restore(k) {
    if (!k || typeof k !== 'object') return;
    if (Array.isArray(k.alpha) && k.alpha.every((a) => typeof a === 'string')) this.setAlpha(k.alpha);
    if (k.residuals === 'prior' || k.residuals === 'posterior') this.residuals.value = k.residuals;
    if (typeof k.qOn === 'boolean') this.qOn.checked = k.qOn;
    this.qScales.disabled = !this.qOn.checked;
    if (typeof k.qScales === 'string') this.qScales.value = k.qScales;
    if (typeof k.tracePoints === 'string') this.tracePoints.value = k.tracePoints;
  }
}
