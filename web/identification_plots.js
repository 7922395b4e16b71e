// The Identification tab's charts (web/identification.js): a value against the
// minimiser's iteration — J, or one param's path from its initial value to its estimate
// (with the param's bounds, where it has them) — on the page's readable axes (plot.js).

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
