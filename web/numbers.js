// Numbers typed into the page's fields, checked here so that a person reads what is
// wrong at the field (“0,5”: use a decimal point) instead of the JSON parser's words.

const NUMBER = /^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$/;
const COMMA_DECIMAL = /^[-+]?\d*,\d+([eE][-+]?\d+)?$/;

/** The largest whole number a JS number holds exactly: 2^53 − 1. */
export const MAX_SAFE = Number.MAX_SAFE_INTEGER;

/**
 * What is wrong with `text` as a number, or null when it reads as one. Options:
 * `integer` (a whole number), `min`, `max` (inclusive).
 */
export function numberProblem(text, { integer = false, min, max } = {}) {
  const s = String(text ?? '').trim();
  const kind = integer ? 'a whole number' : 'a number';
  if (s === '') return `give ${kind}`;
  if (COMMA_DECIMAL.test(s)) return `“${s}” — use a decimal point: ${s.replace(',', '.')}`;
  if (!NUMBER.test(s)) return `“${s}” is not ${kind}`;
  const x = Number(s);
  if (!Number.isFinite(x)) return `“${s}” is too large`;
  if (integer && !Number.isInteger(x)) return `“${s}” is not a whole number`;
  if (integer && Math.abs(x) > MAX_SAFE) {
    return `“${s}” is above 2^53 − 1 = ${MAX_SAFE}: the browser cannot hold larger whole numbers exactly`;
  }
  if (min !== undefined && x < min) return `must be ≥ ${min}, got ${s}`;
  if (max !== undefined && x > max) return `must be ≤ ${max}, got ${s}`;
  return null;
}

/** The number `text` reads as (NaN when it does not: never silently 0). */
export function toNumber(text) {
  const s = String(text ?? '').trim();
  return NUMBER.test(s) ? Number(s) : NaN;
}

/**
 * A cell's text as a model value: a number when it reads as one, else an expression.
 * A number too large for a double stays text (as Infinity it would be sent as JSON
 * null); `cellProblem` says what is wrong with it.
 */
export function parseCell(text) {
  const s = String(text).trim();
  return NUMBER.test(s) && Number.isFinite(Number(s)) ? Number(s) : s;
}

/**
 * What is wrong with a matrix cell's text, or null: a text that reads as a number must
 * be one a double holds (“1e400” is too large); expressions are the core's to check.
 */
export function cellProblem(text) {
  return NUMBER.test(String(text ?? '').trim()) ? numberProblem(text) : null;
}
