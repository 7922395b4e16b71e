// The mismatched filter of an analysis (result.mismatch, docs/mismatch.md): per state
// the SKO the filter believes, the actual one in the truth's world and the optimal one
// (the filter designed on the truth), at t_D in a table and over time in a chart; the
// actual criteria beside the optimal filter's.

import uPlot from './vendor/uplot/uPlot.esm.js';
import { valueAxis } from './plot.js';
import { fmt } from './results.js';

const SERIES = [
  ['believed_sko', 'believed (the model’s potential SKO)', '#9467bd', [6, 4]],
  ['actual_sko', 'actual (the filter in the truth)', '#d62728', []],
  ['optimal_sko', 'optimal (designed on the truth)', '#2ca02c', []],
];

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k in e) e[k] = v;
    else e.setAttribute(k, v);
  }
  e.append(...children);
  return e;
}

/**
 * The truth as the run bar's field gives it — `sd=10, f_f=0.3` — as a request's
 * `truth` ({set}); null for an empty field; throws a message for anything else.
 */
export function parseTruth(text) {
  const parts = text.split(/[,;\s]+/).filter(Boolean);
  if (!parts.length) return null;
  const set = {};
  for (const p of parts) {
    const m = /^([A-Za-z_][A-Za-z0-9_]*)=(.+)$/.exec(p);
    const v = m ? Number(m[2]) : NaN;
    if (!m || !Number.isFinite(v)) throw `Truth: expected NAME=VALUE (such as sd=10), got "${p}"`;
    set[m[1]] = v;
  }
  return { set };
}

export class MismatchView {
  constructor(root) {
    this.root = root;
    this.plot = null;
    this.state = 0;
  }

  /** Show `result.mismatch`, or hide the section when the run gave no truth. */
  show(r) {
    const m = r.mismatch;
    this.plot?.destroy();
    this.plot = null;
    this.root.hidden = !m;
    if (!m) return this.root.replaceChildren();
    const rows = m.states.map((s) =>
      el(
        'tr',
        { 'data-state': s.state },
        el('th', { scope: 'row', textContent: s.state }),
        ...[s.actual_sko, s.believed_sko, s.optimal_sko, s.loss, s.actual_over_believed, s.bias].map((x) => el('td', { className: 'num', textContent: fmt(x) })),
      ),
    );
    const head = ['state', 'actual SKO', 'believed SKO', 'optimal SKO', 'loss (actual / optimal)', 'actual / believed', 'bias'];
    const table = el(
      'table',
      { className: 'criteria', id: 'mismatch-table' },
      el('caption', { textContent: `At t_D; the truth differs in ${m.differs_in}` }),
      el('thead', {}, el('tr', {}, ...head.map((h) => el('th', { scope: 'col', textContent: h })))),
      el('tbody', {}, ...rows),
    );
    const a = r.criteria.actual.weighted;
    const o = m.optimal.weighted;
    const criteria = el(
      'p',
      { id: 'mismatch-criteria' },
      `Weighted criteria, actual (optimal): F_YZ ${fmt(a.yz)} (${fmt(o.yz)}), F_ZX ${fmt(a.zx)} (${fmt(o.zx)}), F_YX ${fmt(a.yx)} (${fmt(o.yx)}).`,
    );
    const select = el('select', { id: 'mismatch-state' }, ...m.states.map((s, i) => el('option', { value: String(i), textContent: s.state })));
    if (this.state < m.states.length) select.value = String(this.state);
    this.chart = el('div', { id: 'mismatch-chart', className: 'mc-chart' });
    select.addEventListener('change', () => {
      this.state = Number(select.value);
      this.draw(m);
    });
    this.root.replaceChildren(
      el('h3', { textContent: 'Mismatched filter: believed against actual' }),
      el('div', { className: 'grid-wrap' }, table),
      criteria,
      el('div', { className: 'chart-controls' }, el('label', { htmlFor: 'mismatch-state', textContent: 'State' }), select),
      this.chart,
    );
    this.draw(m);
  }

  draw(m) {
    this.plot?.destroy();
    this.plot = null;
    const t = m.traces.t;
    if (t.length < 2) return this.chart.replaceChildren(el('p', { className: 'no-traces', textContent: 'No trace points: nothing to plot over time.' }));
    const trace = m.traces.states[this.state] ?? m.traces.states[0];
    const x = valueAxis([t]);
    const y = valueAxis(SERIES.map(([key]) => trace[key]));
    const shown = (axis) => (_, v) => (v === null || v === undefined ? '—' : fmt(axis.value(v)));
    this.chart.replaceChildren();
    this.plot = new uPlot(
      {
        title: `${trace.state}: the SKO the filter believes, the actual one, the optimal one`,
        width: Math.max(320, (this.chart.clientWidth || this.root.clientWidth) - 8),
        height: 300,
        scales: { x: { time: false, ...x.scale }, y: y.scale },
        axes: [
          { label: 't', ...x.axis },
          { label: 'SKO', size: 70, ...y.axis },
        ],
        series: [{ label: 't', value: shown(x) }, ...SERIES.map(([, label, stroke, dash]) => ({ label, stroke, dash, width: 2, value: shown(y) }))],
        legend: { live: true },
      },
      [x.data(t), ...SERIES.map(([key]) => y.data(trace[key]))],
      this.chart,
    );
  }
}
