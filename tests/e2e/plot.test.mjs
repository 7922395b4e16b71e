// The charts' axes (web/plot.js) without a browser: values of any magnitude get ticks
// that uPlot can place and labels that say what they stand for.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { tick, valueAxis } from '../../web/plot.js';

/** The ticks a log axis draws over the plotted range [min, max], given uPlot's spacing. */
function logTicks(columns, incr) {
  const axis = valueAxis(columns, { log: true });
  const [min, max] = axis.scale.range();
  const splits = axis.axis.splits(null, 1, min, max, incr);
  return axis.axis.values(null, splits);
}

test('tick labels: short, exponent form outside [1e-3, 1e5)', () => {
  assert.deepEqual([0, 0.5, 1234.5678, 1e5, 2.5e32, -3e-7, null].map(tick), ['0', '0.5', '1235', '1e+5', '2.5e+32', '-3e-7', '']);
});

test('a linear axis plots values near 1e32 in units of their power of ten', () => {
  const axis = valueAxis([[0, 1e32, 3.2e32, null]]);
  assert.deepEqual(axis.data([0, 1e32, null]), [0, 1, null]);
  assert.equal(axis.value(2), 2e32);
  assert.deepEqual(axis.axis.values(null, [0, 1, 2, 3]), ['0', '1e+32', '2e+32', '3e+32']);
  assert.deepEqual(axis.ticks(), ['0', '1e+32', '2e+32', '3e+32'], 'the labels drawn last');
  // A fixed top (the Monte Carlo's clipped χ) sets the unit, whatever runs beyond it.
  const clipped = valueAxis([[0.5, 1e40]], { top: 2 });
  assert.deepEqual(clipped.scale.range(), [0, 2]);
});

test('a log axis: one labelled line per decade or few decades, never a band of minor lines', () => {
  const wide = logTicks([[1e-3, 1, null, 0, 1e60]], 10);
  assert.deepEqual(wide, ['1', '1e+10', '1e+20', '1e+30', '1e+40', '1e+50', '1e+60']);
  const few = logTicks([[1, 50]], 0.25);
  assert.deepEqual(few, ['1', '2', '5', '10', '20', '50', '100']);
});

test('a log axis within one decade gets evenly spaced values', () => {
  const ticks = logTicks([[1.2e32, 1.8e32]], 0.05);
  assert.ok(ticks.length >= 3, ticks.join(' '));
  for (const t of ticks) assert.match(t, /^\d(\.\d+)?e\+32$/);
});
