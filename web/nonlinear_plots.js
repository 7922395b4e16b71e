// The Nonlinear tab's charts (web/nonlinear.js), uPlot on the page's readable axes
// (plot.js): a state over time — truth, measurements, the EKF, an iterate, the Q-scaled
// EKF, and filter 1's ±2σ band (the only band: P of iterates k ≥ 2 is not the error
// covariance of their estimate) — the errors against the truth over time, and a figure
// (δ, the true RMS) against the iterate i with i* marked.

import uPlot from './vendor/uplot/uPlot.esm.js';
import { valueAxis } from './plot.js';
import { fmt } from './results.js';

export const CHART_HEIGHT = 300;
const BAND_FILL = 'rgba(31, 119, 180, 0.13)';

/**
 * `lines` ([{label, values, stroke, dash, width, points}], nulls for gaps; `points`:
 * 'only' drawn as dots only, false never with dots) against `x` into `box`, with `band` ({label, lo, hi}) shaded between its
 * two edges. Returns the uPlot (destroy() before drawing anew).
 */
function chart(box, { title, xLabel, yLabel, x: xs, lines, band, width, markers = false, whole = false }) {
  const columns = [...lines.map((l) => l.values), ...(band ? [band.hi, band.lo] : [])];
  const x = valueAxis([xs]);
  const y = valueAxis(columns);
  const shown = (_, v) => (v === null || v === undefined ? '—' : fmt(y.value(v)));
  const series = [{ label: xLabel, value: (_, v) => (v === null || v === undefined ? '—' : fmt(x.value(v))) }];
  for (const l of lines) {
    const dots = l.points === 'only';
    series.push({
      label: l.label,
      stroke: l.stroke,
      width: l.width ?? 1.5,
      dash: l.dash ?? [],
      value: shown,
      ...(dots ? { paths: () => null, points: { show: true, size: l.size ?? 3, space: 0, fill: l.stroke, stroke: l.stroke } } : { points: { show: markers && l.points !== false } }),
    });
  }
  const bands = [];
  if (band) {
    const hi = series.length;
    for (const edge of ['+2σ', '−2σ']) series.push({ label: `${band.label} ${edge}`, stroke: 'rgba(31, 119, 180, 0.45)', width: 1, value: shown, points: { show: false } });
    bands.push({ series: [hi, hi + 1], fill: BAND_FILL });
  }
  box.replaceChildren();
  return new uPlot(
    {
      title,
      width,
      height: CHART_HEIGHT,
      scales: { x: { time: false, ...x.scale }, y: y.scale },
      axes: [
        { label: xLabel, ...x.axis, ...(whole ? { splits: () => x.data(xs) } : {}) },
        { label: yLabel, size: 70, ...y.axis },
      ],
      series,
      bands,
      legend: { live: true },
      // The tick labels drawn, for a reader of the page's text (and its tests).
      hooks: { draw: [() => (box.dataset.yTicks = y.ticks().join(' | '))] },
    },
    [x.data(xs), ...columns.map((c) => y.data(c))],
    box,
  );
}

const COLOURS = { truth: '#000000', measurement: '#7f7f7f', ekf: '#d62728', iterate: '#1f77b4', q: '#2ca02c' };

/**
 * State `i` over time: the truth, the measurements of it (those whose h, of the model's
 * `h`, is the state's name), the EKF, iterate `k` (from 1), the Q-scaled EKF, and
 * filter 1's ±2σ band.
 */
export function stateChart(box, r, i, k, width, h = []) {
  const tr = r.traces;
  const state = r.states[i];
  const lines = [];
  if (tr.truth) lines.push({ label: `${state} true`, values: tr.truth[i], stroke: COLOURS.truth, width: 1 });
  r.measurements.forEach((m, j) => {
    if (h[j] === state) lines.push({ label: `${m} (measured)`, values: tr.measurements[j], stroke: COLOURS.measurement, points: 'only', size: 2.5 });
  });
  lines.push({ label: 'EKF', values: tr.ekf[i], stroke: COLOURS.ekf });
  lines.push({ label: `iterate ${k}${k === r.i_star ? ' (i*)' : ''}`, values: tr.iterates[k - 1][i], stroke: COLOURS.iterate, width: 2 });
  if (tr.q_scaled) lines.push({ label: 'EKF, Q scale by δ', values: tr.q_scaled[i], stroke: COLOURS.q, dash: [6, 4] });
  const centre = tr.iterates[0][i];
  const sko = tr.iterate_1_sko[i];
  const band = { label: 'filter 1', hi: centre.map((c, p) => c + 2 * sko[p]), lo: centre.map((c, p) => c - 2 * sko[p]) };
  return chart(box, { title: `${state} over time: the estimates x⁺, filter 1’s ±2σ band`, xLabel: 't', yLabel: state, x: tr.t, lines, band, width });
}

/** The errors x⁺ − x_true of state `i` over time, with filter 1's ±2σ about 0. */
export function errorChart(box, r, i, k, width) {
  const tr = r.traces;
  const truth = tr.truth[i];
  const error = (est) => est.map((v, p) => (truth[p] === null ? null : v - truth[p]));
  const lines = [
    { label: 'EKF', values: error(tr.ekf[i]), stroke: COLOURS.ekf },
    { label: `iterate ${k}${k === r.i_star ? ' (i*)' : ''}`, values: error(tr.iterates[k - 1][i]), stroke: COLOURS.iterate, width: 2 },
  ];
  if (tr.q_scaled) lines.push({ label: 'EKF, Q scale by δ', values: error(tr.q_scaled[i]), stroke: COLOURS.q, dash: [6, 4] });
  if (k !== 1) lines.push({ label: 'filter 1', values: error(tr.iterates[0][i]), stroke: '#9467bd', width: 1 });
  const sko = tr.iterate_1_sko[i];
  const band = { label: 'filter 1', hi: sko.map((s) => 2 * s), lo: sko.map((s) => -2 * s) };
  return chart(box, { title: `${r.states[i]}: the errors x⁺ − x_true over time, filter 1’s ±2σ`, xLabel: 't', yLabel: `error of ${r.states[i]}`, x: tr.t, lines, band, width });
}

/**
 * A figure against the iterate i = 1…K (`values`), with i* marked and the baselines'
 * values (`flat`: [{label, value, stroke}]) as level lines.
 */
export function iterateChart(box, r, { title, yLabel, values, flat = [], width }) {
  const is = r.iterates.map((s) => s.i);
  const star = is.map((i, p) => (i === r.i_star ? values[p] : null));
  const lines = [
    { label: yLabel, values, stroke: '#1f77b4', width: 2 },
    { label: `i* = ${r.i_star}`, values: star, stroke: '#d62728', points: 'only', size: 11 },
    ...flat.map((f) => ({ label: f.label, values: is.map(() => f.value), stroke: f.stroke, dash: [6, 4], width: 1, points: false })),
  ];
  return chart(box, { title, xLabel: 'iterate i', yLabel, x: is, lines, width, markers: true, whole: true });
}
