// The Sensitivity tab (docs/sensitivity.md): which param of the current model moves
// the filtering effect most — d ln F / d ln p of every weighted criterion by central
// differences at p e^±h, in this browser (wasm) or as a server job of kind
// `sensitivity`; a tornado chart of one criterion (a bar per param, left for a
// criterion that falls as the param grows, right for one that rises) and the table of
// all six. The bars are plain elements sized in percent, as the error budget's.

import { KeptFields, RunBar, RunView, duration, el, field, fmt, input, recheckControl, requestErrors, select } from './views.js';
import { resumedText } from './results.js';

/** The criteria a ranking may name, as the core lists them, with their labels. */
const CRITERIA = [
  ['covariance.yx', 'F_YX (covariance)'],
  ['covariance.zx', 'F_ZX (covariance)'],
  ['covariance.yz', 'F_YZ (covariance)'],
  ['bound.yx', 'F_YX (bound)'],
  ['bound.zx', 'F_ZX (bound)'],
  ['bound.yz', 'F_YZ (bound)'],
];

const value = (s, key) => {
  const [set, c] = key.split('.');
  return s?.[set]?.[c] ?? null;
};

export class SensitivityView extends RunView {
  /** `ctx`: as the Monte Carlo view's. */
  constructor(root, ctx) {
    super();
    this.root = root;
    this.ctx = ctx;
    this.result = null;
    this.edits = 0;
    this.build();
  }

  build() {
    this.params = input('sens-params', '', { placeholder: 'every param', 'data-request-path': 'params' });
    this.step = input('sens-step', '0.001', { inputmode: 'decimal', 'data-request-path': 'relative_step' });
    this.rankBy = select('sens-rank-by', CRITERIA, 'covariance.yx');
    this.rankBy.dataset.requestPath = 'rank_by';
    this.form = el(
      'form',
      { class: 'view-form', novalidate: true, onsubmit: (e) => e.preventDefault(), oninput: (e) => recheckControl(e.target, () => requestErrors(() => this.request())) },
      el(
        'fieldset',
        { class: 'section' },
        el('legend', { text: 'Sensitivity: which param moves the effect most' }),
        el('div', { class: 'row' }, field('Params (comma-separated)', this.params), field('Relative step h', this.step), field('Rank by', this.rankBy)),
        el('p', { class: 'help', text: 'S = d ln F / d ln p by central differences at p·e^±h: a 1 % larger param changes the criterion by about S %. Two analyses a param beside the base one.' }),
      ),
    );
    this.bar = new RunBar({ prefix: 'sens', label: 'Run sensitivity', op: 'sensitivity', kind: 'sensitivity', onRun: (where, exec) => this.run(where, exec), onResume: (model, exec) => this.resume(model, exec) });
    this.out = el('div', { id: 'sens-result', class: 'view-result', hidden: true });
    this.root.append(this.form, this.bar.root, this.out);
    this.kept = new KeptFields('kea-sensitivity', [[this.params], [this.step], [this.rankBy]]);
    this.kept.restore();
    for (const type of ['input', 'change']) this.form.addEventListener(type, () => this.kept.save());
  }

  /** A request's settings (a server job opened) in the fields. */
  fill(request) {
    this.params.value = (request.params ?? []).join(', ');
    this.step.value = String(request.relative_step ?? 0.001);
    this.rankBy.value = request.rank_by ?? 'covariance.yx';
    this.kept.save();
  }

  /** The request for the current model and form; throws {errors} for unreadable inputs. */
  request() {
    const request = { model: this.ctx.model(), rank_by: this.rankBy.value };
    const names = this.params.value.split(/[\s,]+/).filter(Boolean);
    if (names.length) request.params = names;
    const h = Number(this.step.value.trim());
    if (this.step.value.trim() === '' || !Number.isFinite(h)) {
      throw { kind: 'invalid', title: 'Invalid sensitivity request', errors: [{ path: 'relative_step', message: `expected a number, got "${this.step.value}"` }] };
    }
    request.relative_step = h;
    return request;
  }


  /** Show a result; `current`: the model has not changed since the run started. */
  show(r, where, current = true) {
    this.result = r;
    this.out.hidden = false;
    this.out.classList.toggle('stale', !current);
    this.out.dataset.where = where;
    const summary = el('p', {
      id: 'sens-summary',
      text: [
        `h = ${fmt(r.relative_step)}, ${r.analyses} analyses of D = ${r.steps.toLocaleString('en')} steps`,
        `${duration(r.timing.wall_ms)} on the ${where === 'browser' ? 'browser (wasm)' : 'server'}`,
        resumedText(r.timing),
      ]
        .filter(Boolean)
        .join(' · '),
    });
    const shownBy = select('sens-chart-criterion', CRITERIA, r.rank_by);
    const chart = el('div', { id: 'sens-tornado', class: 'tornado' });
    const draw = () => chart.replaceChildren(...this.tornado(r, shownBy.value));
    shownBy.addEventListener('change', draw);
    this.out.replaceChildren(
      summary,
      el('p', { class: 'stale-note', text: 'The model has changed since this run: run again to update.' }),
      r.warnings.length ? el('ul', { class: 'mc-warnings' }, ...r.warnings.map((w) => el('li', { text: w }))) : '',
      el('div', { class: 'chart-controls' }, el('label', { for: 'sens-chart-criterion', text: 'S of' }), shownBy),
      chart,
      this.table(r),
      el(
        'div',
        { class: 'downloads' },
        el('button', { type: 'button', id: 'sens-download', text: 'Download result JSON', onclick: () => this.ctx.download(`${this.ctx.fileStem()}-sensitivity.json`, 'application/json', JSON.stringify(this.result, null, 2) + '\n') }),
      ),
    );
    draw();
  }

  /** The tornado: params by |S| of `key`, largest on top, bars from the middle. */
  tornado(r, key) {
    const rows = r.params.map((p) => ({ p, s: value(p.sensitivity, key) }));
    rows.sort((a, b) => (b.s === null ? -1 : Math.abs(b.s)) - (a.s === null ? -1 : Math.abs(a.s)));
    const top = Math.max(...rows.map((x) => (x.s === null ? 0 : Math.abs(x.s))), 0);
    return rows.map(({ p, s }) => {
      const width = top > 0 && s !== null ? (50 * Math.abs(s)) / top : 0;
      const bar = el('span', { class: `tornado-bar ${s < 0 ? 'negative' : 'positive'}`, title: `${p.name}: S = ${s === null ? 'undefined' : fmt(s)}` });
      bar.style.width = `${width}%`;
      bar.style[s < 0 ? 'right' : 'left'] = '50%';
      return el(
        'div',
        { class: 'tornado-row', 'data-param': p.name, 'data-value': s === null ? '' : String(s) },
        el('span', { class: 'tornado-name', text: `${p.name} = ${fmt(p.value)}` }),
        el('span', { class: 'tornado-track' }, bar),
        el('span', { class: 'tornado-value', text: s === null ? (p.undefined ? 'undefined (0)' : '—') : fmt(s) }),
      );
    });
  }

  table(r) {
    const table = el('table', { class: 'criteria', id: 'sens-table' });
    table.append(el('caption', { text: `S = d ln F / d ln p, ranked by |S| of ${r.rank_by}; the first row is the base analysis's F` }));
    table.append(el('thead', {}, el('tr', {}, el('th', { scope: 'col', text: 'param' }), el('th', { scope: 'col', text: 'value' }), ...CRITERIA.map(([, label]) => el('th', { scope: 'col', text: label })))));
    const num = (x, k) => el('td', { class: 'num', 'data-criterion': k, text: fmt(x) });
    const body = el('tbody', {}, el('tr', { class: 'base' }, el('th', { scope: 'row', text: 'base F' }), el('td'), ...CRITERIA.map(([k]) => num(value(r.base, k), k))));
    for (const p of r.params) {
      body.append(el('tr', { 'data-param': p.name }, el('th', { scope: 'row', text: p.name, title: p.undefined ?? '' }), num(p.value, 'value'), ...CRITERIA.map(([k]) => num(value(p.sensitivity, k), k))));
    }
    table.append(body);
    return el('div', { class: 'scroll' }, table);
  }
}
