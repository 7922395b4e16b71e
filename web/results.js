// Results: the criteria tables (bound and covariance side by side, per state and
// weighted), the final values, and plots of the SKO traces (uPlot).

import uPlot from './vendor/uplot/uPlot.esm.js';
import { tick, valueAxis } from './plot.js';

const CRITERIA = [
  ['yz', 'F_YZ', 'measured vs a-priori: > 1 when the measurements beat the model’s prediction'],
  ['zx', 'F_ZX', 'filtered vs measured: > 1 when the filter beats the raw measurements'],
  ['yx', 'F_YX', 'filtered vs a-priori: how many times the filter beats the prediction'],
];
const SETS = [
  ['bound', 'bound'],
  ['covariance', 'covariance'],
];
const SERIES = [
  ['eta', 'η a-priori (bound)', '#1f77b4'],
  ['zeta', 'ζ measured (bound)', '#ff7f0e'],
  ['chi', 'χ filtered (bound)', '#2ca02c'],
  ['potential_sko', 'potential SKO √R', '#9467bd'],
];

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k === 'class') e.className = v;
    else if (k === 'text') e.textContent = v;
    else e.setAttribute(k, v === true ? '' : v);
  }
  for (const c of children) if (c !== null && c !== undefined) e.append(c);
  return e;
}

/** A number for reading: 5 significant digits, exponent when very small or large. */
export function fmt(x) {
  if (x === null || x === undefined) return '—';
  if (x === 0) return '0';
  const a = Math.abs(x);
  if (a >= 1e-3 && a < 1e6) return Number(x.toPrecision(5)).toString();
  return x.toExponential(4);
}

/**
 * A number of a time taken, for reading: 3 significant digits, whole numbers from 100
 * up (13, 1.77, 0.25, 1234).
 */
export function took(x) {
  if (!Number.isFinite(x)) return '—';
  return x >= 100 ? String(Math.round(x)) : String(Number(x.toPrecision(3)));
}

/**
 * A time taken (`ms`), for reading: milliseconds below a second, seconds below a
 * minute (3 significant digits, as `took`), then minutes and seconds, hours and
 * minutes (7.12 ms, 345 ms, 1.77 s, 2 min 5 s, 1 h 52 min). One rule for every “computed
 * in” and “Done in”, in the browser and on the server alike (the server's clock is
 * finer: 1.77 ms beside 13 ms).
 */
export function duration(ms) {
  if (!Number.isFinite(ms) || ms < 0) return '—';
  if (Number(took(ms)) < 1000) return `${took(ms)} ms`;
  if (Number(took(ms / 1000)) < 60) return `${took(ms / 1000)} s`;
  const s = Math.round(ms / 1000);
  if (s < 3600) return `${Math.floor(s / 60)} min ${s % 60} s`;
  const min = Math.round(s / 60);
  return `${Math.floor(min / 60)} h${min % 60 ? ` ${min % 60} min` : ''}`;
}

/**
 * What a result's `timing` says of a server restart: a job it interrupted went on from
 * the state it had kept (its time is then from there). Null for a run from the start.
 */
export function resumedText(timing) {
  const k = timing?.resumed_from_step;
  return k ? `resumed from step ${k.toLocaleString('en')} after a server restart` : null;
}

/** A time stamp (RFC 3339) as "2026-11-24 14:05:09" in the browser's time zone. */
export function when(iso) {
  const d = new Date(iso);
  if (Number.isNaN(d.getTime())) return iso ?? '';
  const p = (x) => String(x).padStart(2, '0');
  return `${d.getFullYear()}-${p(d.getMonth() + 1)}-${p(d.getDate())} ${p(d.getHours())}:${p(d.getMinutes())}:${p(d.getSeconds())}`;
}

/** The hint a table's caption shows when its box scrolls sideways (style.css, `.grid-wrap`). */
export function scrollHintText() {
  return el('span', { class: 'scroll-hint', text: ' — scroll sideways for more ↔' });
}

/**
 * Mark a table's box that is wider than its room, as the model editor marks its grids
 * (the same classes, style.css): the caption's hint, and a faded edge on each side
 * with more columns.
 */
export function scrollHint(box) {
  const more = box.scrollWidth - box.clientWidth;
  box.classList.toggle('overflows', more > 1);
  box.classList.toggle('more-left', box.scrollLeft > 1);
  box.classList.toggle('more-right', more - box.scrollLeft > 1);
}

/** One criterion cell: the full-precision value in data-value, highlighted when > 1. */
function criterionCell(set, criterion, row, stateName, value, why) {
  const td = el('td', {
    class: `num${value !== null && value > 1 ? ' effect' : ''}`,
    'data-set': set,
    'data-criterion': criterion,
    'data-row': row,
    'data-state': stateName,
    'data-value': value === null ? '' : String(value),
    title: value === null ? why ?? 'undefined' : String(value),
  });
  td.textContent = fmt(value);
  return td;
}

export function criteriaTable(result) {
  const table = el('table', { class: 'criteria', id: 'criteria-table' });
  table.append(
    el('caption', { text: 'Criteria (averaged over the steps; > 1 = an effect, highlighted)' }, scrollHintText()),
  );
  const head1 = el('tr', {}, el('th', { rowspan: 2, scope: 'col', text: 'state' }));
  const head2 = el('tr');
  for (const [key, label, help] of CRITERIA) {
    head1.append(el('th', { colspan: 2, scope: 'colgroup', title: help, 'data-criterion': key, text: label }));
    for (const [, setLabel] of SETS) head2.append(el('th', { scope: 'col', text: setLabel }));
  }
  table.append(el('thead', {}, head1, head2));
  const body = el('tbody');
  const sets = result.criteria;
  sets.bound.per_state.forEach((ps, i) => {
    const label = el('th', { scope: 'row', text: ps.state });
    if (ps.measurement) label.append(el('span', { class: 'pair', text: ` ↔ ${ps.measurement}` }));
    const tr = el('tr', {}, label);
    for (const [key] of CRITERIA) {
      for (const [set] of SETS) {
        const s = sets[set].per_state[i];
        tr.append(criterionCell(set, key, String(i), s.state, s[key], s.undefined?.[key]));
      }
    }
    body.append(tr);
  });
  const tr = el('tr', { class: 'weighted' }, el('th', { scope: 'row', text: 'weighted' }));
  for (const [key] of CRITERIA) {
    for (const [set] of SETS) {
      const w = sets[set].weighted;
      tr.append(criterionCell(set, key, 'weighted', '', w[key], w.undefined?.[key]));
    }
  }
  body.append(tr);
  table.append(body);
  return table;
}

export function finalTable(result) {
  const f = result.final;
  const table = el('table', { class: 'final' });
  table.append(el('caption', { text: `Values at t_E = ${fmt(result.t_end)} (bound SKOs; ΔX = λχ, λ = ${fmt(result.lambda)} for P = ${result.confidence})` }, scrollHintText()));
  const cols = [
    ['eta', 'η'],
    ['zeta', 'ζ (paired measurement)'],
    ['chi', 'χ'],
    ['potential_sko', '√R'],
    ['delta_y', 'ΔY'],
    ['delta_x', 'ΔX'],
  ];
  table.append(el('thead', {}, el('tr', {}, el('th', { scope: 'col', text: 'state' }), ...cols.map(([, l]) => el('th', { scope: 'col', text: l })))));
  // ζ is one value per measurement: it goes on the row of the state the measurement is
  // paired with (result.pairs), "—" on a state no measurement is paired with.
  const measurements = result.measurements ?? [];
  const pairedWith = new Map((result.pairs ?? []).map((p) => [p.state, measurements.indexOf(p.measurement)]));
  const value = (k, name, i) => {
    if (k !== 'zeta') return f[k]?.[i] ?? null;
    const j = pairedWith.get(name);
    return j === undefined || j < 0 ? null : (f.zeta?.[j] ?? null);
  };
  const body = el('tbody');
  result.states.forEach((name, i) => {
    body.append(
      el('tr', {}, el('th', { scope: 'row', text: name }), ...cols.map(([k]) => el('td', { class: 'num', text: fmt(value(k, name, i)) }))),
    );
  });
  table.append(body);
  return table;
}

/** In place of a chart when the run kept no trace rows (trace points = 0). */
export function noTraces(text = 'No trace points requested (trace points = 0): there are no SKO traces to plot.') {
  return el('p', { class: 'no-traces', text });
}

/** The SKO-trace chart with a state selector and a log-scale toggle. */
export class TraceChart {
  constructor(root) {
    this.root = root;
    this.plot = null;
    this.result = null;
    this.observer = new ResizeObserver(() => this.fit());
    this.observer.observe(root);
  }

  show(result, controls) {
    this.result = result;
    this.controls = controls;
    this.draw();
  }

  width() {
    return Math.max(320, this.root.clientWidth - 8);
  }

  fit() {
    this.plot?.setSize({ width: this.width(), height: 320 });
  }

  draw() {
    const r = this.result;
    if (!r) return;
    this.plot?.destroy();
    this.plot = null;
    if (!r.traces.t.length) {
      this.root.replaceChildren(noTraces());
      return;
    }
    const i = Number(this.controls.state.value) || 0;
    const log = this.controls.log.checked;
    const trace = r.traces.states[i];
    const columns = SERIES.filter(([key]) => trace[key]).map(([key, label, stroke]) => ({ values: trace[key], label, stroke }));
    const x = valueAxis([r.traces.t]);
    const y = valueAxis(columns.map((c) => c.values), { log });
    const shown = (axis) => (_, v) => (v === null || v === undefined ? '—' : fmt(axis.value(v)));
    const data = [x.data(r.traces.t), ...columns.map((c) => y.data(c.values))];
    const series = [{ label: 't', value: shown(x) }, ...columns.map(({ label, stroke }) => ({ label, stroke, width: 1.5, value: shown(y) }))];
    this.root.replaceChildren();
    this.plot = new uPlot(
      {
        title: `SKOs of ${trace.state} over time`,
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
        hooks: { draw: [() => (this.root.dataset.yTicks = y.ticks().join(' | '))] },
      },
      data,
      this.root,
    );
  }
}
