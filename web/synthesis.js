// The Synthesis tab (docs/synthesis.md): for the current model, a target (criterion,
// criteria set, weighted or one state, threshold) and a mode (bisect, grid, seed_search), run in
// this browser (wasm, the core's Sequential executor) or as a server job of kind
// `synthesis`; the result as grid tables or as the answer with its verification.

import { numberProblem, toNumber } from './numbers.js';
import { KeptFields, RunBar, RunView, checkOverrides, duration, el, field, fmt, input, recheckControl, requestErrors, scrollHint, scrollHintText, select, uiWords } from './views.js';

const CRITERIA = [
  ['yz', 'F_YZ (measured vs a-priori)'],
  ['zx', 'F_ZX (filtered vs measured)'],
  ['yx', 'F_YX (filtered vs a-priori)'],
];
const LABEL = { yz: 'F_YZ', zx: 'F_ZX', yx: 'F_YX' };

/**
 * A target's criteria set: `criteria`, or `set`, the member's former name (a request or
 * a result of an earlier kea); `bound` when it names none, as the core reads it.
 */
function criteriaOf(target) {
  return target.criteria ?? target.set ?? 'bound';
}
const MODES = [
  ['grid', 'grid — criteria tables over up to 3 params'],
  ['bisect', 'bisect — the loosest value of one param'],
  ['seed_search', 'seed_search — the seed’s search from the upper bounds'],
];
const ROWS = 3; // grid params and seed-search params

/**
 * The items of a values field: separated by commas, semicolons or spaces (a comma with
 * spaces around it is one separator). Two separators in a row, or one at an end
 * (`1,,2`), give an empty item (''): refused at the field (EMPTY_ITEM), not skipped.
 */
function listItems(text) {
  const s = text.trim();
  return s === '' ? [] : s.split(/\s*[,;]\s*|\s+/);
}

const EMPTY_ITEM = 'a value is missing: two separators in a row, or one at an end (separate the values with one comma)';

/** Numbers for an input: short and exact enough (`1e-05`, `0.25`). */
function show(x) {
  return Number.isFinite(x) ? String(Number(x.toPrecision(6))) : '';
}

function paramValue(model, name) {
  const v = Number(model.params?.[name]);
  return Number.isFinite(v) && v > 0 ? v : 1;
}

export class SynthesisView extends RunView {
  /**
   * `ctx`: {model() → the editor's model object, example() → the loaded preset's
   * synthesis example ({preset, target, mode}) or null, showModelErrors(errors),
   * download(name, type, text), fileStem()}.
   */
  constructor(root, ctx) {
    super();
    this.root = root;
    this.ctx = ctx;
    this.result = null;
    this.edits = 0; // model changes seen (markStale): a result is current if none came during its run
    this.resized = new ResizeObserver((entries) => entries.forEach((e) => scrollHint(e.target))); // the grid tables' boxes
    this.build();
  }

  // ------------------------------------------------------------ form

  build() {
    const id = (s) => `syn-${s}`;
    this.criterion = select(id('criterion'), CRITERIA, 'yx');
    this.criterion.dataset.requestPath = 'target.criterion';
    this.criteria = select(id('criteria'), [['bound', 'bound (the seed’s modulus)'], ['covariance', 'covariance']], 'bound');
    this.criteria.dataset.requestPath = 'target.criteria';
    this.state = select(id('state'), [['', 'weighted (all states)']], '');
    this.state.dataset.requestPath = 'target.state';
    this.threshold = input(id('threshold'), '14', { inputmode: 'decimal', 'data-request-path': 'target.threshold' });
    const target = el(
      'fieldset',
      { class: 'section' },
      el('legend', { text: 'Target: criterion ≥ threshold' }),
      el(
        'div',
        { class: 'row' },
        field('Criterion', this.criterion),
        field('Criteria set', this.criteria),
        field('Of', this.state),
        field('Threshold F*', this.threshold),
      ),
    );

    this.mode = select(id('mode'), MODES, 'grid');
    this.mode.dataset.requestPath = 'mode';
    this.mode.addEventListener('change', () => this.showMode());

    // bisect
    this.bisect = {
      param: select(id('bisect-param'), []),
      low: input(id('bisect-low'), '', { inputmode: 'decimal', 'data-request-path': 'mode.bisect.low' }),
      high: input(id('bisect-high'), '', { inputmode: 'decimal', 'data-request-path': 'mode.bisect.high' }),
      rel_tol: input(id('bisect-rel-tol'), '0.001', { inputmode: 'decimal', 'data-request-path': 'mode.bisect.rel_tol' }),
      probes: input(id('bisect-probes'), '9', { inputmode: 'numeric', 'data-request-path': 'mode.bisect.probes' }),
    };
    this.bisect.param.dataset.requestPath = 'mode.bisect.param';
    this.bisect.param.addEventListener('change', () => this.defaultsBisect());
    const bisectPanel = el(
      'div',
      { class: 'mode-panel', 'data-mode': 'bisect' },
      el(
        'div',
        { class: 'row' },
        field('Param', this.bisect.param),
        field('Low', this.bisect.low),
        field('High', this.bisect.high),
        field('Rel. tolerance', this.bisect.rel_tol),
        field('Probes', this.bisect.probes),
      ),
      el('p', { class: 'help', text: 'Log-scale bisection over [low, high] (0 < low < high); refuses non-monotonic criteria. The answer is re-analysed, and a point 1 % looser must miss.' }),
    );

    // grid
    this.grid = [];
    const gridBody = el('tbody');
    for (let i = 0; i < ROWS; i++) {
      const row = {
        param: select(id(`grid-param-${i}`), []),
        values: input(id(`grid-values-${i}`), '', { 'data-request-path': `mode.grid.params[${i}].values`, class: 'values' }),
        cheaper: select(id(`grid-cheaper-${i}`), [['', 'no cost order'], ['higher', 'higher is cheaper'], ['lower', 'lower is cheaper']], ''),
      };
      row.param.dataset.requestPath = `mode.grid.params[${i}].name`;
      row.cheaper.dataset.requestPath = `mode.grid.cost_order[${i}]`;
      row.param.addEventListener('change', () => {
        this.defaultsGrid(i);
        this.gridSummary();
      });
      row.values.addEventListener('input', () => this.gridSummary());
      const label = ['rows', 'columns', 'pages'][i];
      row.param.setAttribute('aria-label', `Grid ${label}: param`);
      row.values.setAttribute('aria-label', `Grid ${label}: values, comma-separated, with a decimal point`);
      row.cheaper.setAttribute('aria-label', `Grid ${label}: cost order`);
      gridBody.append(el('tr', {}, el('th', { scope: 'row', text: label }), el('td', {}, row.param), el('td', {}, row.values), el('td', {}, row.cheaper)));
      this.grid.push(row);
    }
    const gridPanel = el(
      'div',
      { class: 'mode-panel', 'data-mode': 'grid' },
      el(
        'table',
        { class: 'grid syn-rows' },
        el('caption', { text: 'Grid params (up to 3)' }),
        el('thead', {}, el('tr', {}, el('th'), el('th', { scope: 'col', text: 'param' }), el('th', { scope: 'col', text: 'values (comma-separated, decimal point)' }), el('th', { scope: 'col', text: 'cost' }))),
        gridBody,
      ),
      el('p', { class: 'help', text: 'Rows × columns × pages, every cell re-analysed. With a cost order (top row most important) the cheapest cell meeting the target is the answer.' }),
    );
    // What the values fields read as, while they are typed: `0,5` is two values here.
    this.gridCount = el('p', { class: 'help', id: id('grid-count'), 'aria-live': 'polite' });
    gridPanel.append(this.gridCount);

    // seed_search
    this.seed = [];
    const seedBody = el('tbody');
    for (let i = 0; i < ROWS; i++) {
      const base = `mode.seed_search.params[${i}]`;
      const row = {
        param: select(id(`seed-param-${i}`), []),
        high: input(id(`seed-high-${i}`), '', { inputmode: 'decimal', 'data-request-path': `${base}.high` }),
        low: input(id(`seed-low-${i}`), '', { inputmode: 'decimal', 'data-request-path': `${base}.low` }),
        shrink: input(id(`seed-shrink-${i}`), '0.5', { inputmode: 'decimal', 'data-request-path': `${base}.shrink` }),
      };
      row.param.dataset.requestPath = `${base}.name`;
      row.param.addEventListener('change', () => this.defaultsSeed(i));
      for (const [k, text] of [['param', 'param'], ['high', 'high'], ['low', 'low'], ['shrink', 'shrink factor']]) {
        row[k].setAttribute('aria-label', `Search param ${i + 1}: ${text}`);
      }
      seedBody.append(el('tr', {}, el('th', { scope: 'row', text: String(i + 1) }), ...['param', 'high', 'low', 'shrink'].map((k) => el('td', {}, row[k]))));
      this.seed.push(row);
    }
    this.batch = input(id('seed-batch'), '4', { inputmode: 'numeric', 'data-request-path': 'mode.seed_search.batch' });
    const seedPanel = el(
      'div',
      { class: 'mode-panel', 'data-mode': 'seed_search' },
      el(
        'table',
        { class: 'grid syn-rows' },
        el('caption', { text: 'Search params (the first outermost)' }),
        el('thead', {}, el('tr', {}, el('th'), ...['param', 'high', 'low', 'shrink'].map((t) => el('th', { scope: 'col', text: t })))),
        seedBody,
      ),
      el('div', { class: 'row' }, field('Batch', this.batch, 'points analysed at once; fixed, so the answer is reproducible')),
      el('p', { class: 'help', text: 'From high down, multiplied by shrink (0 < shrink < 1) while ≥ low; stops at the first point meeting the target.' }),
    );

    const modeSet = el(
      'fieldset',
      { class: 'section' },
      el('legend', { text: 'Mode' }),
      el('div', { class: 'row' }, field('Mode', this.mode)),
      gridPanel,
      bisectPanel,
      seedPanel,
    );

    this.bar = new RunBar({
      prefix: 'syn',
      label: 'Run synthesis',
      op: 'synthesize',
      kind: 'synthesis',
      onRun: (where, exec) => this.run(where, exec),
      onResume: (model, exec) => this.resume(model, exec),
    });
    // Which preset's example the fields hold (applyExample), until they are changed.
    this.exampleNote = el('p', { class: 'help', id: id('example'), hidden: true });
    this.form = el('form', { class: 'view-form', novalidate: true, onsubmit: (e) => e.preventDefault(), oninput: (e) => recheckControl(e.target, () => requestErrors(() => this.request())) }, this.exampleNote, target, modeSet);
    this.out = el('div', { id: 'syn-result', class: 'view-result', hidden: true });
    this.root.append(this.form, this.bar.root, this.out);
    // The fields as they were before a reload, put back once the model's params are
    // choices (refreshChoices); a param and its values go together.
    const one = (c) => [c];
    const b = this.bisect;
    this.kept = new KeptFields('kea-synthesis', [
      ...[this.criterion, this.criteria, this.state, this.threshold, this.mode].map(one),
      [b.param, b.low, b.high],
      ...[b.rel_tol, b.probes].map(one),
      ...this.grid.map((row) => [row.param, row.values, row.cheaper]),
      ...this.seed.map((row) => [row.param, row.high, row.low, row.shrink]),
      [this.batch],
    ]);
    this.restorePending = true;
    for (const type of ['input', 'change']) {
      this.form.addEventListener(type, () => {
        this.kept.save();
        this.exampleNote.hidden = true;
      });
    }
    this.refreshChoices();
    this.showMode();
  }

  showMode() {
    for (const p of this.form.querySelectorAll('.mode-panel')) p.hidden = p.dataset.mode !== this.mode.value;
  }

  /**
   * The model's params and states changed: update the choices. A new model (another
   * object: a preset, an import) also resets the params and their ranges — to the
   * preset's synthesis example where it is a preset's.
   */
  refreshChoices() {
    const model = this.ctx.model();
    if (!model) return;
    const fresh = model !== this.model;
    this.model = model;
    const params = Object.keys(model.params ?? {});
    const preferred = errorParams(model);
    const states = model.system?.states ?? [];
    const fill = (sel, options, pick) => {
      const before = sel.value;
      sel.replaceChildren(...options.map(([v, t]) => el('option', { value: v, text: t })));
      const values = options.map(([v]) => v);
      sel.value = fresh ? pick ?? values[0] ?? '' : values.includes(before) ? before : values[0] ?? '';
      return fresh || before !== sel.value;
    };
    fill(this.state, [['', 'weighted (all states)'], ...states.map((s) => [s, `state ${s}`])], '');
    const ps = params.map((p) => [p, p]);
    if (fill(this.bisect.param, ps, preferred[0])) this.defaultsBisect();
    this.grid.forEach((row, i) => {
      if (fill(row.param, i === 0 ? ps : [['', '(none)'], ...ps], i < 2 ? preferred[i] ?? '' : '')) this.defaultsGrid(i);
    });
    this.seed.forEach((row, i) => {
      if (fill(row.param, i === 0 ? ps : [['', '(none)'], ...ps], i === 0 ? preferred[0] : '')) this.defaultsSeed(i);
    });
    if (fresh) {
      const example = this.ctx.example?.();
      if (example) this.applyExample(example);
      this.exampleNote.hidden = !example;
      const name = example?.preset;
      this.exampleNote.replaceChildren(...(example ? [`Example for preset ${name}: its synthesis question, as `, el('code', { text: `kea synthesize --preset ${name}` }), ' asks it.'] : []));
    }
    this.gridSummary();
    if (this.restorePending) {
      this.restorePending = false;
      if (this.kept.restore()) this.exampleNote.hidden = true; // the fields as they were edited
      this.showMode();
      this.gridSummary();
    }
    this.kept.save(); // the choices (and a new model's defaults) as they are now
  }

  /**
   * A preset's synthesis example ({target, mode}, as presets/synthesis/NAME.json has it)
   * in the fields; a target's criteria set may be under `set`, its former name (a job
   * stored by an earlier kea).
   */
  applyExample({ target: t, mode }) {
    this.criterion.value = t.criterion;
    this.criteria.value = criteriaOf(t);
    this.state.value = t.state ?? '';
    this.threshold.value = String(t.threshold);
    const [kind, m] = Object.entries(mode)[0];
    this.mode.value = kind;
    if (kind === 'bisect') {
      const b = this.bisect;
      b.param.value = m.param;
      b.low.value = String(m.low);
      b.high.value = String(m.high);
      b.rel_tol.value = String(m.rel_tol ?? 1e-3); // the core's defaults
      b.probes.value = String(m.probes ?? 9);
    } else if (kind === 'grid') {
      this.grid.forEach((row, i) => {
        const p = m.params[i];
        row.param.value = p?.name ?? '';
        if (p) row.values.value = p.values.map(String).join(', ');
        else this.defaultsGrid(i);
        row.cheaper.value = m.cost_order?.find((c) => c.name === p?.name)?.cheaper ?? '';
      });
    } else if (kind === 'seed_search') {
      this.seed.forEach((row, i) => {
        const p = m.params[i];
        row.param.value = p?.name ?? '';
        if (p) for (const k of ['high', 'low', 'shrink']) row[k].value = String(p[k]);
        else this.defaultsSeed(i);
      });
      this.batch.value = String(m.batch ?? 4);
    }
    this.showMode();
  }

  /** A request's target and mode (a server job opened) in the fields. */
  fill(request) {
    this.exampleNote.hidden = true;
    this.applyExample(request);
    this.gridSummary();
    this.kept.save();
  }

  /** The grid's cells as the values fields read now: "f: 3 values (2, 4, 8) × … = 6 cells". */
  gridSummary() {
    const parts = [];
    let cells = 1;
    for (const row of this.grid) {
      if (!row.param.value) continue;
      const items = listItems(row.values.value);
      if (items.some((s) => s === '' || numberProblem(s))) {
        this.gridCount.textContent = '';
        return;
      }
      cells *= items.length;
      const word = items.length === 1 ? 'value' : 'values';
      parts.push(`${row.param.value}: ${items.length} ${word} (${items.map(toNumber).join(', ')})`);
    }
    this.gridCount.textContent = parts.length ? `${parts.join(' × ')} = ${cells} ${cells === 1 ? 'cell' : 'cells'}` : '';
  }

  defaultsBisect() {
    const v = paramValue(this.ctx.model(), this.bisect.param.value);
    this.bisect.low.value = show(v / 10);
    this.bisect.high.value = show(v * 10);
  }

  defaultsGrid(i) {
    const row = this.grid[i];
    if (!row.param.value) {
      row.values.value = '';
      return;
    }
    const v = paramValue(this.ctx.model(), row.param.value);
    row.values.value = [v / 2, v, v * 2].map(show).join(', ');
  }

  defaultsSeed(i) {
    const row = this.seed[i];
    if (!row.param.value) {
      row.high.value = row.low.value = '';
      return;
    }
    const v = paramValue(this.ctx.model(), row.param.value);
    row.high.value = show(v);
    row.low.value = show(v / 8);
  }

  // ------------------------------------------------------------ request

  /** The request for the current model and form; throws {errors} for unreadable inputs. */
  request() {
    const errors = [];
    const number = (control, path, options) => {
      const problem = numberProblem(control.value, options);
      if (problem) errors.push({ path, message: problem });
      return toNumber(control.value);
    };
    const target = {
      criterion: this.criterion.value,
      criteria: this.criteria.value,
      threshold: number(this.threshold, 'target.threshold'),
    };
    if (this.state.value) target.state = this.state.value;
    let mode;
    if (this.mode.value === 'bisect') {
      const b = this.bisect;
      mode = {
        bisect: {
          param: b.param.value,
          low: number(b.low, 'mode.bisect.low'),
          high: number(b.high, 'mode.bisect.high'),
          rel_tol: number(b.rel_tol, 'mode.bisect.rel_tol'),
          probes: number(b.probes, 'mode.bisect.probes', { integer: true, min: 1 }),
        },
      };
    } else if (this.mode.value === 'grid') {
      const params = [];
      const cost = [];
      this.grid.forEach((row) => {
        const k = params.length;
        // Paths as the request will have them (rows left empty are skipped).
        row.param.dataset.requestPath = `mode.grid.params[${k}].name`;
        row.values.dataset.requestPath = `mode.grid.params[${k}].values`;
        if (!row.param.value) return;
        const items = listItems(row.values.value);
        if (items.includes('')) errors.push({ path: `mode.grid.params[${k}].values`, message: EMPTY_ITEM });
        const values = items.filter((s) => s !== '').map((s) => {
          const problem = numberProblem(s);
          if (problem) errors.push({ path: `mode.grid.params[${k}].values`, message: problem });
          return toNumber(s);
        });
        params.push({ name: row.param.value, values });
        if (row.cheaper.value) cost.push({ name: row.param.value, cheaper: row.cheaper.value });
      });
      mode = { grid: { params } };
      if (cost.length) mode.grid.cost_order = cost;
    } else {
      const params = [];
      for (const row of this.seed) {
        const base = `mode.seed_search.params[${params.length}]`;
        for (const k of ['low', 'high', 'shrink']) row[k].dataset.requestPath = `${base}.${k}`;
        row.param.dataset.requestPath = `${base}.name`;
        if (!row.param.value) continue;
        params.push({
          name: row.param.value,
          low: number(row.low, `${base}.low`),
          high: number(row.high, `${base}.high`),
          shrink: number(row.shrink, `${base}.shrink`),
        });
      }
      mode = { seed_search: { params, batch: number(this.batch, 'mode.seed_search.batch', { integer: true, min: 1 }) } };
    }
    if (errors.length) throw { kind: 'invalid', title: 'Invalid synthesis request', errors };
    return { model: this.ctx.model(), target, mode };
  }

  /**
   * The values the request gives each param, with the control that gives them: a value
   * that makes the model invalid (a negative SKO) is reported there, not at the model
   * cell it reaches.
   */
  overrides(request) {
    const m = request.mode;
    if (m.bisect) {
      const b = m.bisect;
      return [
        { name: b.param, values: [b.low], path: 'mode.bisect.low' },
        { name: b.param, values: [b.high], path: 'mode.bisect.high' },
      ];
    }
    if (m.grid) return m.grid.params.map((p, k) => ({ name: p.name, values: p.values, path: `mode.grid.params[${k}].values` }));
    return m.seed_search.params.flatMap((p, k) => [
      { name: p.name, values: [p.high], path: `mode.seed_search.params[${k}].high` },
      { name: p.name, values: [p.low], path: `mode.seed_search.params[${k}].low` },
    ]);
  }

  /** The model with each override the synthesis will try, checked before a run. */
  async checkRequest(request) {
    const overridden = await checkOverrides(request.model, this.overrides(request));
    if (overridden.length) throw { kind: 'invalid', title: 'Invalid synthesis request', errors: overridden };
  }


  // ------------------------------------------------------------ result

  /** Show a result; `current`: the model has not changed since the run started. */
  show(r, where, current = true) {
    this.result = r;
    this.resized.disconnect(); // the boxes of the tables shown before
    this.out.hidden = false;
    this.out.classList.toggle('stale', !current);
    this.out.dataset.where = where;
    this.out.dataset.status = r.status;
    const t = r.target;
    const what = `${LABEL[t.criterion]} (${criteriaOf(t)}${t.state ? `, state ${t.state}` : ', weighted'}) ≥ ${fmt(t.threshold)}`;
    const parts = [
      el('p', { class: `syn-status status-${r.status}`, id: 'syn-message' }, el('strong', { text: `${r.status.replaceAll('_', ' ')}: ` }), uiWords(r.message)),
      el('p', { class: 'syn-summary', id: 'syn-summary' }, `Target ${what} · `, el('span', { id: 'syn-analyses', 'data-value': String(r.analyses), text: `${r.analyses} analyses` }), r.recalled_analyses ? ` (${r.recalled_analyses} of them kept from before a server restart)` : '', ` of D = ${r.steps.toLocaleString('en')} steps · ${duration(r.timing.wall_ms)} on the ${where === 'browser' ? 'browser (wasm)' : 'server'}`),
      el('p', { class: 'stale-note', text: 'The model has changed since this run: run again to update.' }),
      this.pointWarnings(r),
    ];
    const d = r.details;
    if (d.grid) parts.push(this.gridTables(r, d.grid));
    if (r.answer) parts.push(this.pointsTable(r));
    if (d.bisect) parts.push(this.bisectDetails(r, d.bisect));
    if (d.seed_search) parts.push(this.seedDetails(r, d.seed_search));
    parts.push(
      el('div', { class: 'downloads' }, el('button', {
        type: 'button',
        id: 'syn-download',
        text: 'Download result JSON',
        onclick: () => this.ctx.download(`${this.ctx.fileStem()}-synthesis.json`, 'application/json', JSON.stringify(this.result, null, 2) + '\n'),
      })),
    );
    this.out.replaceChildren(...parts.filter(Boolean));
  }

  /**
   * The warnings of the answer's analysis (the verification's, as `kea analyze` of that
   * point gives them), under the message: on the bound set its figures may describe
   * the bound's growth rather than the filter (|A| taken element-wise grows where A
   * does not), which the analysis warns of. Returns the element they go in (or null).
   */
  pointWarnings(r) {
    const v = r.verification;
    if (!v?.warnings?.length) return null;
    const which = `the answer (${paramsText(v.point.params)})`;
    const caution = criteriaOf(r.target) === 'bound' ? ' — these bound figures may not describe the filter' : '';
    return el(
      'div',
      { class: 'syn-warnings', id: 'syn-warnings', 'data-state': 'warned' },
      el('p', { text: `The analysis of ${which} warns${caution}:` }),
      el('ul', {}, ...v.warnings.map((w) => el('li', { text: uiWords(w) }))),
    );
  }


  /** Grid tables: rows × columns, one table per page; cells F_YZ / F_ZX / F_YX. */
  gridTables(r, g) {
    const crit = r.target.criterion;
    const [rows, cols, pages] = [g.params[0], g.params[1], g.params[2]];
    const cheapest = g.cheapest ? g.cheapest.join(',') : null;
    const byIndex = new Map(g.cells.map((c) => [c.index.join(','), c]));
    const wrap = el('div', { class: 'syn-grid', id: 'syn-grid' });
    const meets = g.cells.filter((c) => c.point.meets).length;
    wrap.append(
      el('p', { class: 'help', text: `Each cell: F_YZ / F_ZX / F_YX (${criteriaOf(r.target)} set, ${r.target.state ? `state ${r.target.state}` : 'weighted'}); ✓ marks the ${meets} of ${g.cells.length} cells with ${LABEL[crit]} ≥ ${fmt(r.target.threshold)}${cheapest ? ', the outlined one is the cheapest' : ''}.` }),
    );
    const pageValues = pages ? pages.values : [null];
    pageValues.forEach((pv, k) => {
      const table = el('table', { class: 'criteria syn-table' });
      const title = pages ? `${pages.name} = ${fmt(pv)}` : `${rows.name}${cols ? ` × ${cols.name}` : ''}`;
      table.append(el('caption', {}, title, scrollHintText()));
      const colValues = cols ? cols.values : [null];
      table.append(
        el('thead', {}, el('tr', {}, el('th', { scope: 'col', text: cols ? `${rows.name} \\ ${cols.name}` : rows.name }), ...colValues.map((cv) => el('th', { scope: 'col' }, ...(cols ? valueLabel(cols.name, cv) : [LABEL.yz + ' / ' + LABEL.zx + ' / ' + LABEL.yx]))))),
      );
      const body = el('tbody');
      rows.values.forEach((rv, i) => {
        const tr = el('tr', {}, el('th', { scope: 'row' }, ...valueLabel(rows.name, rv)));
        colValues.forEach((_, j) => {
          const index = [i, ...(cols ? [j] : []), ...(pages ? [k] : [])];
          const key = index.join(',');
          const cell = byIndex.get(key);
          const p = cell?.point;
          const td = el('td', {
            class: `num syn-cell${p?.meets ? ' meets' : ''}${key === cheapest ? ' cheapest' : ''}`,
            'data-index': key,
            'data-yz': p?.yz ?? '',
            'data-zx': p?.zx ?? '',
            'data-yx': p?.yx ?? '',
            'data-meets': String(!!p?.meets),
            title: p ? `${Object.entries(p.params).map(([n, v]) => `${n} = ${v}`).join(', ')}: F_YZ ${p.yz}, F_ZX ${p.zx}, F_YX ${p.yx}${p.note ? ` (${p.note})` : ''}` : '',
          });
          if (p) {
            // Each number with the “/” or the ✓ after it: a cell wraps between them (style.css).
            for (const [n, c] of [['yz', 'F_YZ'], ['zx', 'F_ZX'], ['yx', 'F_YX']]) {
              if (n !== 'yz') td.append(' ');
              const after = n !== 'yx' ? ' /' : p.meets ? el('span', { class: 'mark', 'aria-label': 'meets the target', text: ' ✓' }) : null;
              td.append(el('span', {}, el('span', { class: n === crit ? 'target-crit' : null, title: c, text: fmt(p[n]) }), after));
            }
          }
          tr.append(td);
        });
        body.append(tr);
      });
      table.append(body);
      // Too many columns to fit even with the cells wrapped: scrolled, and said so.
      const box = el('div', { class: 'grid-wrap' }, table);
      box.addEventListener('scroll', () => scrollHint(box), { passive: true });
      this.resized.observe(box);
      wrap.append(box);
    });
    if (cheapest) {
      const c = byIndex.get(cheapest);
      wrap.append(el('p', { id: 'syn-cheapest', class: 'syn-answer', text: `Cheapest qualifying cell: ${paramsText(c.point.params)} — ${LABEL[crit]} = ${fmt(c.point.value)}.` }));
    }
    return wrap;
  }

  /** The answer and its verification (re-analysed point, and the looser one for bisect). */
  pointsTable(r) {
    const names = Object.keys(r.answer.params);
    const table = el('table', { class: 'criteria syn-points', id: 'syn-points' });
    table.append(el('caption', { text: r.verification ? `Answer and verification (${r.verification.passed ? 'passed' : 'FAILED'})` : 'Answer' }));
    table.append(
      el('thead', {}, el('tr', {}, el('th', { scope: 'col', text: 'point' }), ...names.map((n) => el('th', { scope: 'col', text: n })), ...['F_YZ', 'F_ZX', 'F_YX'].map((c) => el('th', { scope: 'col', text: c })), el('th', { scope: 'col', text: 'meets' }))),
    );
    const body = el('tbody');
    const row = (label, key, p) => {
      const tr = el('tr', { 'data-point': key }, el('th', { scope: 'row', text: label }));
      for (const n of names) tr.append(el('td', { class: 'num', 'data-param': n, 'data-value': String(p.params[n]), text: fmt(p.params[n]) }));
      for (const c of ['yz', 'zx', 'yx']) {
        tr.append(el('td', { class: `num${c === r.target.criterion ? ' target-crit' : ''}`, 'data-criterion': c, 'data-value': p[c] ?? '', text: fmt(p[c]) }));
      }
      tr.append(el('td', { class: p.meets ? 'meets' : 'misses', text: p.meets ? 'yes ✓' : 'no' }));
      body.append(tr);
    };
    row('answer', 'answer', r.answer);
    if (r.verification) {
      row('re-analysed', 'verified', r.verification.point);
      if (r.verification.looser) row('1 % looser', 'looser', r.verification.looser);
    }
    table.append(body);
    return table;
  }

  bisectDetails(r, b) {
    const list = el('table', { class: 'criteria syn-evals' });
    list.append(el('thead', {}, el('tr', {}, el('th', { scope: 'col', text: b.param }), el('th', { scope: 'col', text: `${LABEL[r.target.criterion]}` }), el('th', { scope: 'col', text: 'meets' }))));
    const body = el('tbody');
    for (const p of [...b.evaluations].sort((x, y) => x.params[b.param] - y.params[b.param])) {
      body.append(el('tr', {}, el('td', { class: 'num', text: fmt(p.params[b.param]) }), el('td', { class: 'num', text: fmt(p.value) }), el('td', { text: p.meets ? '✓' : '' })));
    }
    list.append(body);
    const [lo, hi] = b.bracket ? [...b.bracket].sort((x, y) => x - y) : [];
    const bracket = b.bracket ? `bracket [${fmt(lo)}, ${fmt(hi)}], ` : '';
    return el('details', { class: 'syn-details' }, el('summary', { text: `${b.evaluations.length} evaluations of ${b.param} (${bracket}${b.iterations} bisection steps)` }), list);
  }

  seedDetails(r, s) {
    const list = el('table', { class: 'criteria syn-evals' });
    const names = s.levels.map((l) => l.name);
    list.append(el('thead', {}, el('tr', {}, ...names.map((n) => el('th', { scope: 'col', text: n })), el('th', { scope: 'col', text: LABEL[r.target.criterion] }), el('th', { scope: 'col', text: 'meets' }))));
    const body = el('tbody');
    for (const p of s.visited) {
      body.append(el('tr', {}, ...names.map((n) => el('td', { class: 'num', text: fmt(p.params[n]) })), el('td', { class: 'num', text: fmt(p.value) }), el('td', { text: p.meets ? '✓' : '' })));
    }
    list.append(body);
    return el('details', { class: 'syn-details' }, el('summary', { text: `${s.visited.length} of ${s.points_total} points visited (levels: ${s.levels.map((l) => `${l.name} ${l.values.map(fmt).join(', ')}`).join('; ')})` }), list);
  }
}

/** The params, those that the error levels (φ, W, ψ, V, η₀) use first — but one that both the model's and the sensor's use, last (see below). */
function errorParams(model) {
  const uses = (values) => {
    const text = JSON.stringify(values);
    return (n) => new RegExp(`(^|[^A-Za-z0-9_])${n.replace(/[^A-Za-z0-9_]/g, '')}($|[^A-Za-z0-9_])`).test(text);
  };
  const inModel = uses([model.system?.phi, model.system?.W, model.system?.eta0]);
  const inSensor = uses([model.measurement?.psi, model.measurement?.V]);
  const names = Object.keys(model.params ?? {});
  // A param in both the model's errors and the sensor's scales them together, which
  // the criteria do not see (the seed example's psi, with phi = f*psi): last.
  const both = names.filter((n) => inModel(n) && inSensor(n));
  const used = names.filter((n) => (inModel(n) || inSensor(n)) && !both.includes(n));
  return [...used, ...names.filter((n) => !used.includes(n) && !both.includes(n)), ...both];
}

/** `name = value` for a grid's heading: it may wrap after the “=”, not inside the number (`1e-6`). */
function valueLabel(name, value) {
  return [`${name} = `, el('span', { class: 'value', text: fmt(value) })];
}

function paramsText(params) {
  return Object.entries(params)
    .map(([n, v]) => `${n} = ${fmt(v)}`)
    .join(', ');
}
