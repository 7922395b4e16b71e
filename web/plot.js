// Axes that stay readable for any magnitude. uPlot draws no ticks once values pass
// ~1e17 (its tick search allows 17 integer digits) and its log scale puts a gridline at
// every 1…9 × 10^k, grey bands over many decades. So the charts hand uPlot values it
// handles — a linear axis's values divided by a power of ten, a log axis's as log10 —
// and label the ticks with the values they stand for (exponent form outside
// [1e-3, 1e5)). A log axis has a labelled line per decade (or per few decades), and
// 2× and 5× lines only where they have room.

/** An axis tick: short, exponent form outside [1e-3, 1e5). */
export function tick(x) {
  if (x === null || x === undefined || !Number.isFinite(x)) return '';
  if (x === 0) return '0';
  const a = Math.abs(x);
  if (a >= 1e-3 && a < 1e5) return String(Number(x.toPrecision(4)));
  return x.toExponential(2).replace(/\.?0+e/, 'e');
}

const finite = (v) => v !== null && v !== undefined && Number.isFinite(v);

/** 10^k for any k a double can hold (10 ** -320 is subnormal but fine). */
const pow10 = (k) => 10 ** k;

/** The smallest of 1, 2, 2.5, 5 × 10^k that is ≥ x. */
function niceStep(x) {
  const k = Math.floor(Math.log10(x));
  for (const m of [1, 2, 2.5, 5, 10]) if (m * pow10(k) >= x * (1 - 1e-9)) return m * pow10(k);
  return 10 * pow10(k);
}

/**
 * A value axis for the columns `columns` (arrays with nulls for gaps). `log`: a log
 * scale (values ≤ 0 are gaps); `top`: a fixed top of a linear axis (bottom 0).
 * Returns {data(column) → uPlot's column, value(v) → the value it stands for,
 * scale, axis (splits and values), ticks(): the labels drawn last}.
 */
export function valueAxis(columns, { log = false, top = null } = {}) {
  return log ? logAxis(columns) : linearAxis(columns, top);
}

/** The axis options labelling each split with the value it stands for, and the labels drawn. */
function labelled(value, axis = {}) {
  let shown = [];
  const values = (_, splits) => (shown = splits.map((s) => tick(value(s))));
  return { axis: { ...axis, values }, ticks: () => shown };
}

function linearAxis(columns, top) {
  // The unit: the power of ten of the largest value shown (the top, when fixed).
  let big = top ?? 0;
  if (top === null) for (const c of columns) for (const v of c) if (finite(v)) big = Math.max(big, Math.abs(v));
  const k = big > 0 ? Math.floor(Math.log10(big)) : 0;
  const unit = pow10(k);
  const data = (c) => c.map((v) => (finite(v) ? v / unit : null));
  const value = (s) => s * unit;
  const scale = top !== null ? { range: () => [0, top / unit] } : {};
  return {
    data,
    value,
    scale,
    ...labelled(value),
  };
}

function logAxis(columns) {
  let lo = Infinity;
  let hi = -Infinity;
  for (const c of columns) {
    for (const v of c) {
      if (finite(v) && v > 0) {
        const e = Math.log10(v);
        lo = Math.min(lo, e);
        hi = Math.max(hi, e);
      }
    }
  }
  if (lo > hi) [lo, hi] = [0, 1];
  const data = (c) => c.map((v) => (finite(v) && v > 0 ? Math.log10(v) : null));
  const value = (s) => pow10(s);
  // Whole decades when the data spans one or more; a little margin otherwise.
  const range = () => {
    const span = hi - lo;
    if (span >= 1) return [Math.floor(lo), Math.ceil(hi)];
    const pad = span > 0 ? span * 0.1 : 0.1;
    return [lo - pad, hi + pad];
  };
  /** Ticks: `incr` is uPlot's spacing for the plotted log10 values (in decades). */
  const splits = (_, __, min, max, incr) => {
    const out = [];
    if (incr >= 1) {
      const every = Math.ceil(incr);
      for (let d = Math.ceil(min / every - 1e-9) * every; d <= max + 1e-9; d += every) out.push(d);
    } else {
      const mults = incr > 0.35 ? [1] : incr > 0.15 ? [1, 2, 5] : [1, 2, 3, 4, 5, 6, 7, 8, 9];
      for (let d = Math.floor(min); d <= Math.ceil(max); d++) {
        for (const m of mults) {
          const s = d + Math.log10(m);
          if (s >= min - 1e-9 && s <= max + 1e-9) out.push(s);
        }
      }
    }
    if (out.length >= 2) return out;
    // Within one decade: evenly spaced values, placed on the log axis.
    const [a, b] = [pow10(min), pow10(max)];
    const step = niceStep((b - a) / 4);
    const first = Math.ceil(a / step - 1e-9) * step;
    const even = [];
    for (let v = first; v <= b * (1 + 1e-12); v += step) even.push(Math.log10(v));
    return even;
  };
  return {
    data,
    value,
    scale: { range },
    ...labelled(value, { splits }),
  };
}
