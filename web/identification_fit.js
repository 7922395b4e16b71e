// The Identification tab's (web/identification.js) "More starts" field read as the
// request's `starts`, and two parts of its result: whether the model fits the data
// (`innovations`: the NIS mean against its band, each measurement's whiteness test with
// its autocorrelations, drawn by identification_plots.js) and the distinct optima the
// starts reached (`optima`, lowest J first: the first is the estimate).

import { numberProblem, toNumber } from './numbers.js';
import { el, fmt } from './views.js';
import { autocorrelationChart, innovationsChart } from './identification_plots.js';

/** The request's limit on `starts` (openapi.yaml: IdentificationJobRequest.starts). */
export const MAX_STARTS = 100;

/**
 * A line's `NAME=x` items: split at commas, semicolons or spaces before the next
 * `NAME=` (so that a decimal comma, `r=0,9`, stays in its item and is named as one).
 */
const ITEM_SPLIT = /[,;\s]+(?=[^\s=,;]+\s*=)/;

/**
 * The text of the "More starts" field as `starts`: one start per line, `NAME=x` items
 * (`phi11=0.6, phi22=0.9`) naming params estimated (`names`); blank lines and lines
 * from `#` on are skipped. Returns {starts, errors}: errors {path: 'starts', message}
 * naming the line, so the field shows them before anything is sent.
 */
export function parseStarts(text, names) {
  const starts = [];
  const errors = [];
  const known = new Set(names);
  const fail = (message) => errors.push({ path: 'starts', message });
  String(text ?? '')
    .split('\n')
    .forEach((raw, i) => {
      const line = raw.replace(/#.*$/, '').trim().replace(/[,;\s]+$/, '');
      if (line === '') return;
      const where = `line ${i + 1}`;
      const start = {};
      const items = line.split(ITEM_SPLIT).map((s) => s.trim()).filter(Boolean);
      if (!items.length) return fail(`${where}: no NAME=value in “${line}” (one start per line: ${names[0] ?? 'NAME'}=0.5, …)`);
      let ok = true;
      for (const item of items) {
        const m = /^([^=\s]+)\s*=\s*(.*)$/.exec(item);
        if (!m) {
          fail(`${where}: “${item}” is not NAME=value (one start per line: ${names[0] ?? 'NAME'}=0.5, …)`);
          ok = false;
          continue;
        }
        const [, name, value] = m;
        if (!known.has(name)) {
          fail(`${where}: “${name}” is not a param estimated here (${names.length ? `estimated: ${names.join(', ')}` : 'tick the params to estimate above'})`);
          ok = false;
        } else if (name in start) {
          fail(`${where}: ${name} is given twice`);
          ok = false;
        } else {
          const problem = numberProblem(value);
          if (problem) {
            fail(`${where}, ${name}: ${problem}`);
            ok = false;
          } else start[name] = toNumber(value);
        }
      }
      if (ok) starts.push(start);
    });
  if (starts.length > MAX_STARTS) fail(`at most ${MAX_STARTS} starts, got ${starts.length}`);
  return { starts, errors };
}

/** `starts` as the field's text: one start per line. */
export function startsText(starts) {
  if (!Array.isArray(starts)) return '';
  return starts.map((s) => Object.entries(s ?? {}).map(([k, v]) => `${k}=${v}`).join(', ')).join('\n');
}

const cell = (key, x, attrs = {}) =>
  el('td', { class: 'num', 'data-key': key, 'data-value': x === null || x === undefined ? '' : String(x), title: x === null || x === undefined ? 'undefined' : String(x), text: fmt(x), ...attrs });

/**
 * The "Does the model fit?" block of a result `r`: the NIS mean against its 95 % band,
 * and per measurement the Ljung–Box test of its standardized innovations' whiteness.
 * Returns {root, charts: [{box, measurement, rho, count}]}, the boxes for the
 * autocorrelation charts the view draws when shown.
 */
export function fitBlock(r) {
  const inn = r.innovations;
  const root = el('section', { id: 'id-fit', class: 'id-fit' }, el('h3', { text: 'Does the model fit?' }));
  if (!inn) {
    root.append(el('p', { id: 'id-fit-verdict', class: 'help', text: 'No innovations: nothing was measured.' }));
    return { root, charts: [] };
  }
  const white = inn.whiteness.every((w) => w.white);
  const fits = inn.nis_consistent && white;
  const misses = [!inn.nis_consistent && 'the NIS is outside its band (noise levels that do not fit the data)', !white && 'the innovations are not white (dynamics the model misses)'].filter(Boolean);
  root.append(
    el('p', {
      id: 'id-fit-verdict',
      class: `id-verdict ${fits ? 'fits' : 'does-not-fit'}`,
      'data-fits': String(fits),
      text: fits ? 'Yes: the NIS is consistent and the innovations are white at 95 %.' : `No: ${misses.join('; ')}.`,
    }),
    el('p', {
      id: 'id-nis',
      class: `id-verdict ${inn.nis_consistent ? 'fits' : 'does-not-fit'}`,
      'data-consistent': String(inn.nis_consistent),
      'data-value': String(inn.nis_mean),
      text: `NIS mean ${fmt(inn.nis_mean)} ${inn.nis_consistent ? 'within' : 'outside'} its 95 % band [${fmt(inn.nis_band[0])}, ${fmt(inn.nis_band[1])}] (${inn.degrees_of_freedom.toLocaleString('en')} degrees of freedom): ${inn.nis_consistent ? 'consistent' : 'not consistent'}`,
    }),
  );
  const table = el('table', { class: 'criteria id-whiteness', id: 'id-whiteness' });
  table.append(el('caption', { text: 'Whiteness of each measurement’s standardized innovations ν/√S: the Ljung–Box Q of their autocorrelations against χ²’s 95 % quantile (their mean and variance: 0 and 1 for a model that fits)' }));
  table.append(el('thead', {}, el('tr', {}, ...['measurement', 'verdict', 'Q', 'critical', 'lags', 'n', 'mean', 'variance'].map((t) => el('th', { scope: 'col', text: t })))));
  const body = el('tbody');
  const charts = [];
  inn.whiteness.forEach((w, i) => {
    body.append(
      el(
        'tr',
        { 'data-measurement': w.measurement },
        el('th', { scope: 'row', text: w.measurement }),
        el('td', { class: `verdict ${w.white ? 'consistent' : 'optimistic'}`, 'data-key': 'white', 'data-value': String(w.white), text: w.white ? `white: Q ≤ ${fmt(w.critical)}` : `not white: Q > ${fmt(w.critical)}` }),
        cell('ljung_box', w.ljung_box),
        cell('critical', w.critical),
        cell('lags', w.lags, { text: String(w.lags) }),
        cell('count', w.count, { text: w.count.toLocaleString('en') }),
        cell('mean', w.mean),
        cell('variance', w.variance),
      ),
    );
    const acf = el('div', { id: `id-chart-acf-${i}`, class: 'id-chart', 'data-measurement': w.measurement });
    charts.push({ box: acf, draw: (width) => autocorrelationChart(acf, { title: `${w.measurement}: the innovations’ autocorrelations ρ(lag), ±1.96/√n`, rho: w.autocorrelation, count: w.count, width }) });
    const trace = inn.trace;
    if (trace && trace.t.length) {
      const over = el('div', { id: `id-chart-innovations-${i}`, class: 'id-chart', 'data-measurement': w.measurement, 'data-points': String(trace.t.length) });
      const every = trace.bucket > 1 ? ` (of each ${trace.bucket} steps the one with the largest NIS; every step is in the CSV)` : '';
      charts.push({ box: over, draw: (width) => innovationsChart(over, { title: `${w.measurement}: the standardized innovations ν/√S over time, ±1.96${every}`, t: trace.t, values: trace.innovations[i], width }) });
    }
  });
  table.append(body);
  root.append(el('div', { class: 'scroll' }, table), ...charts.map((c) => c.box));
  return { root, charts };
}

/** Who reached an optimum: start 0 is the initial values, i the i-th of More starts. */
const startName = (i) => (i === 0 ? 'the initial values' : `start ${i}`);

/** The table of the distinct optima of `r` (null when there is one): J, each param, the starts that reached it. */
export function optimaTable(r) {
  const optima = r.optima ?? [];
  if (optima.length < 2) return null;
  const best = optima[0].neg_log_likelihood;
  const table = el('table', { class: 'criteria id-optima', id: 'id-optima' });
  table.append(el('caption', { text: `The ${optima.length} distinct optima the starts reached, lowest J first: the first is the estimate (start i: the i-th start of More starts, blank lines and comments not counted)` }));
  table.append(el('thead', {}, el('tr', {}, ...['', 'J', 'J − J of the estimate', ...r.parameters, 'converged', 'reached from'].map((t) => el('th', { scope: 'col', text: t })))));
  const body = el('tbody');
  optima.forEach((o, i) => {
    body.append(
      el(
        'tr',
        { 'data-optimum': String(i), class: i === 0 ? 'estimate' : null },
        el('th', { scope: 'row', text: i === 0 ? 'the estimate' : `optimum ${i + 1}` }),
        cell('neg_log_likelihood', o.neg_log_likelihood),
        cell('delta', o.neg_log_likelihood - best),
        ...r.parameters.map((p) => cell('param', o.params[p], { 'data-param': p })),
        el('td', { 'data-key': 'converged', 'data-value': String(o.converged), text: o.converged ? 'yes' : 'no' }),
        el('td', { 'data-key': 'starts', 'data-value': JSON.stringify(o.starts), text: o.starts.map(startName).join(', ') }),
      ),
    );
  });
  table.append(body);
  return el('div', { class: 'scroll' }, el('h3', { text: 'Optima' }), table);
}
