// The Identification tab's charts (web/identification.js): a value against the
// minimiser's iteration — J, or one param's path from its initial value to its estimate
// (with the param's bounds, where it has them) —, and the innovations at the estimate
// (over time, and their autocorrelations), on the page's readable axes (plot.js).

import uPlot from './vendor/uplot/uPlot.esm.js';
import { valueAxis } from './plot.js';
import { fmt } from './results.js';

const HEIGHT = 260;

/**
 * A chart of `columns` ([{label, values, stroke, dash, width}], one value per
 * iteration, nulls for gaps) against the iteration 0, 1, …, into `box`; `title` and
 * `yLabel` say what is drawn. Returns the uPlot (destroy() before drawing anew).
 */
export function iterationChart(box, { title, yLabel, columns, width }) {
  const n = columns[0]?.values.length ?? 0;
  const k = Array.from({ length: n }, (_, i) => i);
  const x = valueAxis([k]);
  const y = valueAxis(columns.map((c) => c.values));
  const shown = (axis) => (_, v) => (v === null || v === undefined ? '—' : fmt(axis.value(v)));
  const series = [
    { label: 'iteration', value: (_, v) => (v === null || v === undefined ? '—' : String(Math.round(x.value(v)))) },
    ...columns.map((c) => ({ label: c.label, stroke: c.stroke, width: c.width ?? 2, dash: c.dash ?? [], value: shown(y), points: { show: n <= 60 } })),
  ];
  box.replaceChildren();
  return new uPlot(
    {
      title,
      width,
      height: HEIGHT,
      scales: { x: { time: false, ...x.scale }, y: y.scale },
      axes: [
        { label: 'iteration', ...x.axis },
        { label: yLabel, size: 70, ...y.axis },
      ],
      series,
      legend: { live: true },
      // The tick labels drawn, for a reader of the page's text (and its tests).
      hooks: { draw: [() => (box.dataset.yTicks = y.ticks().join(' | '))] },
    },
    [x.data(k), ...columns.map((c) => y.data(c.values))],
    box,
  );
}

/** The chart's height, for the box that holds it. */
export const CHART_HEIGHT = HEIGHT;

/**
 * The autocorrelations ρ_1…ρ_L of a measurement's standardized innovations as bars
 * against the lag, with the band ±1.96/√n (`count` = n) a white sequence keeps 95 % of
 * them within, into `box`. Returns the uPlot.
 */
export function autocorrelationChart(box, { title, rho, count, width }) {
  const lags = rho.map((_, i) => i + 1);
  const band = 1.96 / Math.sqrt(Math.max(1, count));
  const x = valueAxis([lags]);
  const y = valueAxis([rho, [band, -band]]);
  // Symmetric about 0, the band inside: ρ's sign is read at a glance.
  let top = band;
  for (const v of rho) if (Number.isFinite(v)) top = Math.max(top, Math.abs(v));
  const unit = y.value(1);
  const range = (1.15 * top) / unit;
  const pad = 0.6 / x.value(1); // half a lag and a little, in the axis's units
  const flat = (v) => lags.map(() => v);
  const shown = (_, v) => (v === null || v === undefined ? '—' : fmt(y.value(v)));
  box.replaceChildren();
  return new uPlot(
    {
      title,
      width,
      height: HEIGHT,
      scales: { x: { time: false, range: (_, lo, hi) => [lo - pad, hi + pad] }, y: { range: () => [-range, range] } },
      axes: [
        { label: 'lag', ...x.axis },
        { label: 'ρ', size: 70, ...y.axis },
      ],
      series: [
        { label: 'lag', value: (_, v) => (v === null || v === undefined ? '—' : String(Math.round(x.value(v)))) },
        { label: 'ρ', stroke: '#1f77b4', fill: 'rgba(31, 119, 180, 0.45)', width: 1, paths: uPlot.paths.bars({ size: [0.6, 40] }), points: { show: false }, value: shown },
        { label: '+1.96/√n', stroke: '#d62728', dash: [6, 4], width: 1, points: { show: false }, value: shown },
        { label: '−1.96/√n', stroke: '#d62728', dash: [6, 4], width: 1, points: { show: false }, value: shown },
      ],
      legend: { live: true },
      hooks: { draw: [() => (box.dataset.yTicks = y.ticks().join(' | '))] },
    },
    [x.data(lags), y.data(rho), y.data(flat(band)), y.data(flat(-band))],
    box,
  );
}

/**
 * A measurement's standardized innovations ν/√S at the estimate against t, as points
 * (the result's trace: of each run of `bucket` steps, the step with the largest NIS),
 * with ±1.96, the band 95 % of them keep under the model, into `box`. Returns the uPlot.
 */
export function innovationsChart(box, { title, t, values, width }) {
  const x = valueAxis([t]);
  const y = valueAxis([values, [1.96, -1.96]]);
  const shown = (axis) => (_, v) => (v === null || v === undefined ? '—' : fmt(axis.value(v)));
  const flat = (v) => t.map(() => v);
  box.replaceChildren();
  return new uPlot(
    {
      title,
      width,
      height: HEIGHT,
      scales: { x: { time: false, ...x.scale }, y: y.scale },
      axes: [
        { label: 't', ...x.axis },
        { label: 'ν/√S', size: 70, ...y.axis },
      ],
      series: [
        { label: 't', value: shown(x) },
        { label: 'ν/√S', stroke: '#1f77b4', width: 0, paths: () => null, points: { show: true, size: 3, fill: '#1f77b4' }, value: shown(y) },
        { label: '+1.96', stroke: '#d62728', dash: [6, 4], width: 1, points: { show: false }, value: shown(y) },
        { label: '−1.96', stroke: '#d62728', dash: [6, 4], width: 1, points: { show: false }, value: shown(y) },
      ],
      legend: { live: true },
      hooks: { draw: [() => (box.dataset.yTicks = y.ticks().join(' | '))] },
    },
    [x.data(t), y.data(values), y.data(flat(1.96)), y.data(flat(-1.96))],
    box,
  );
}
