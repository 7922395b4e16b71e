// The Nonlinear tab's tables (web/nonlinear.js): the γ table of the procedure
// (γ_i^k, the residual weights and R_k), the filters — each iterate, the plain EKF and
// the EKF of the Q scale chosen by δ — with δ on the one-step predictions (the choice),
// δ on the posteriors, δ per measurement and, with a truth, the true RMS per state; i*
// and “stop at the first increase” marked; and the Q-scale grid.

import { sub } from './nonlinear_procedure.js';
import { el, fmt } from './views.js';

/** A number's cell: the value's digits in data-value (the tests read them), 5 digits shown. */
function num(x, attrs = {}) {
  const known = x !== null && x !== undefined;
  return el('td', { class: 'num', 'data-value': known ? String(x) : '', title: known ? String(x) : 'not known', text: fmt(x), ...attrs });
}

function table(id, caption, head, rows) {
  return el(
    'div',
    { class: 'scroll' },
    el('table', { class: `criteria ${id}`, id }, el('caption', { text: caption }), el('thead', {}, el('tr', {}, ...head.map((t) => el('th', { scope: 'col', text: t })))), el('tbody', {}, ...rows)),
  );
}

/** γ_i^k (row k: i = 1…k), α_(k−1), the diagonal of R_k = V/γ_k^k. */
export function gammaTable(r) {
  const K = r.gamma.length;
  const head = ['k', 'α_(k−1)', ...Array.from({ length: K }, (_, i) => `γ${sub(i + 1)}ᵏ`), ...r.measurements.map((m) => `R_k (${m})`)];
  const rows = r.gamma.map((g, k) =>
    el(
      'tr',
      { 'data-k': String(k + 1) },
      el('th', { scope: 'row', text: String(k + 1) }),
      num(r.alpha[k], { 'data-key': 'alpha' }),
      ...Array.from({ length: K }, (_, i) => (i < g.length ? num(g[i], { 'data-i': String(i + 1), title: `γ_${i + 1}^${k + 1} = ${g[i]}; weight of filter ${i + 1}’s residual w = ${r.weights[k][i]}` }) : el('td', { class: 'empty' }))),
      ...r.r[k].map((x, j) => num(x, { 'data-key': 'r', 'data-j': String(j) })),
    ),
  );
  return table('nl-gamma', 'The weights γ_i^k (row k: filter k’s, on the residuals of filters i = 1…k; a cell’s tooltip gives w = γ_i^k/γ_k^k) and R_k = V/γ_k^k', head, rows);
}

/** The marks of a filter's row, in words. */
function marks(r, s, key) {
  const out = [];
  if (key === 'iterate') {
    if (s.i === r.i_star) out.push('i* (least δ)');
    if (s.i === r.i_stop_first_increase) out.push('stop at the first increase');
    (r.best_rms ?? []).forEach((b, j) => b === s.i && out.push(`least RMS of ${r.states[j]}`));
  }
  return out;
}

/** Each filter's figures: the iterates, the EKF, the EKF of the Q scale chosen. */
export function filtersTable(r) {
  const truth = Boolean(r.ekf.rms);
  const perMeasurement = r.measurements.length > 1;
  const head = [
    'filter',
    'δ (predictions)',
    'δ (posteriors)',
    ...(perMeasurement ? r.measurements.map((m) => `δ ${m}`) : []),
    ...(truth ? r.states.map((s) => `RMS ${s}`) : []),
    '',
  ];
  const row = (s, key, label, extra = []) => {
    const m = key === 'iterate' ? marks(r, s, key) : extra;
    const tr = el(
      'tr',
      { 'data-row': key === 'iterate' ? `iterate-${s.i}` : key, class: [key === 'iterate' && s.i === r.i_star ? 'i-star' : '', key === 'iterate' && s.i === r.i_stop_first_increase ? 'stop-first' : '', key !== 'iterate' ? 'baseline' : ''].filter(Boolean).join(' ') || null },
      el('th', { scope: 'row', text: label }),
      num(s.delta, { 'data-key': 'delta' }),
      num(s.delta_posterior, { 'data-key': 'delta_posterior' }),
      ...(perMeasurement ? s.delta_by_measurement.map((d, j) => num(d, { 'data-key': 'delta_by_measurement', 'data-j': String(j) })) : []),
      ...(truth ? s.rms.map((x, j) => num(x, { 'data-key': 'rms', 'data-j': String(j), class: key === 'iterate' && r.best_rms?.[j] === s.i ? 'num best' : 'num' })) : []),
      el('td', { class: 'nl-marks', 'data-key': 'marks', text: m.join('; ') }),
    );
    return tr;
  };
  const rows = r.iterates.map((s) => row(s, 'iterate', `iterate ${s.i}`));
  rows.push(row(r.ekf, 'ekf', 'EKF (the model’s W)', ['baseline']));
  const c = r.q_scale.chosen;
  if (c !== null && c !== undefined) {
    const p = r.q_scale.grid[c];
    rows.push(row(p, 'q-scale', `EKF, W × ${fmt(p.scale)}`, [`baseline: the Q scale of least δ (of ${r.q_scale.grid.length})`]));
  }
  const caption = `The filters: δ = the mean of (y − h(x⁻))² on the one-step predictions — the choice, i* = ${r.i_star} — and on the posteriors (which falls with the gain: not a choice)${truth ? '; with the truth, the RMS of x⁺ − x_true per state (what no user can know)' : ''}`;
  return table('nl-iterates', caption, head, rows);
}

/** The Q-scale grid: each scale's δ (and RMS), the chosen marked. */
export function qScaleTable(r) {
  const g = r.q_scale;
  if (!g.grid.length) return null;
  const truth = Boolean(r.ekf.rms);
  const head = ['scale of W', 'δ (predictions)', 'δ (posteriors)', ...(truth ? r.states.map((s) => `RMS ${s}`) : [])];
  const rows = g.grid.map((p, k) =>
    el(
      'tr',
      { 'data-index': String(k), class: k === g.chosen ? 'chosen' : null },
      el('th', { scope: 'row', text: `${fmt(p.scale)}${k === g.chosen ? ' (chosen by δ)' : ''}` }),
      num(p.delta, { 'data-key': 'delta' }),
      num(p.delta_posterior, { 'data-key': 'delta_posterior' }),
      ...(truth ? p.rms.map((x, j) => num(x, { 'data-key': 'rms', 'data-j': String(j), class: g.best_rms?.[j] === k ? 'num best' : 'num' })) : []),
    ),
  );
  return el(
    'details',
    { class: 'nl-q-grid', id: 'nl-q-grid' },
    el('summary', { text: `The Q-scale grid: ${g.grid.length} EKFs with W scaled, the scale of least δ chosen` }),
    table('nl-q-table', 'Each scale’s EKF (the least true RMS per state in bold: what no user can know)', head, rows),
  );
}
