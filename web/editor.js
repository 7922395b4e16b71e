// The model editor: params, time, dimensions, and every matrix as a grid of cells
// that accept a number or an expression in t and the params; the members without a
// grid (schedule, pairs, weights, a misspelt member) as JSON text. Edits change the
// model object in place, and the core's validation messages are shown at the cell or
// field their path names. Fields that take only a number (params, t₀, t_E, P, N, …) are
// also checked here, so their messages say what to type rather than what the JSON
// parser expected. A change of dimension goes through dimensions.js, which keeps every
// member consistent and what a smaller dimension removed for Undo.

import { cellProblem, numberProblem, parseCell } from './numbers.js';
import { MAX_DIMENSION, Shelf, dimensions, membersAlong, removeAt, removedOnlyDefaults, resize, restoreAt } from './dimensions.js';
import { History, apply, diff, pathText } from './history.js';

export { parseCell };

/**
 * Whether `model` is in the discrete form (`system.transition`, Φ per step), which only
 * the identification reads (METHOD §3); the analysis's form has the continuous `a`.
 */
export function isDiscrete(model) {
  return model?.system?.transition !== undefined;
}

function showValue(v) {
  return v === undefined || v === null ? '' : String(v);
}

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k === 'class') e.className = v;
    else if (k === 'text') e.textContent = v;
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v === true ? '' : v);
  }
  for (const c of children) if (c !== null && c !== undefined) e.append(c);
  return e;
}

/**
 * A cell's full text as its tooltip: a narrow cell shows `sqrt(2*alph`, and the rest
 * could be read only by clicking in.
 */
function showTitle(input) {
  if (input.value) input.title = input.value;
  else input.removeAttribute('title');
}

/** A selector that finds `control` again in a redrawn editor: its path, id or focus key. */
function focusSelector(control) {
  const d = control.dataset ?? {};
  if (d.path) return `${control.tagName.toLowerCase()}[data-path="${CSS.escape(d.path)}"]`; // not its cell's <td>, which has the path too
  if (control.id) return `#${CSS.escape(control.id)}`;
  if (d.focus) return `[data-focus="${CSS.escape(d.focus)}"]`;
  return null;
}

const byFocusKey = (key) => `[data-focus="${CSS.escape(key)}"]`;

/** `text` as HTML text or an attribute's value (the grids are written as HTML). */
const escapeHtml = (text) => String(text).replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);

/**
 * A grid of more than this many cells is drawn as rows of blocks of SEGMENT cells that
 * the browser skips while they are far from the window (see `grid`); a smaller one is a
 * table. At 1000 cells a table's frame after a keystroke takes a few milliseconds.
 */
const LARGE_GRID = 1000;
const SEGMENT = 10;

const zeros = (n) => Array.from({ length: n }, () => 0);
const resizeVec = (v, n, fill = () => 0) =>
  Array.from({ length: n }, (_, i) => (v && i < v.length ? v[i] : fill(i)));
const resizeMat = (m, r, c) =>
  Array.from({ length: r }, (_, i) => resizeVec(m?.[i], c));

// ------------------------------------------------------------ form conversions
// Switching a quantity's form (φ ↔ W, ψ ↔ V, g ↔ Γ) converts its values: a model
// switched must mean what it meant (zeros would run it with no noise). Numbers are
// computed; expressions become the formula's text. What cannot be converted is named
// in the conversion's note, and left 0.

/** A name an expression can use (the core's `is_identifier`). */
const IDENTIFIER = /^[\p{L}_][\p{L}\p{N}_]*$/u;
const UNSIGNED = /^(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$/;

/** A cell as a number or an expression text (a missing entry is the 0 its cell shows); null when it is neither. */
function asCell(v) {
  if (v === undefined) return 0;
  if (typeof v === 'number') return Number.isFinite(v) ? v : null;
  if (typeof v !== 'string' || v.trim() === '') return null;
  return parseCell(v);
}

/** A cell as a factor or a power's base: a name or an unsigned number as it is, anything else in parentheses. */
function group(x) {
  const s = String(x);
  return IDENTIFIER.test(s) || UNSIGNED.test(s) ? s : `(${s})`;
}

/** a·b of two cells, as a cell. */
function times(a, b) {
  if (a === 0 || b === 0) return 0;
  if (typeof a === 'number' && typeof b === 'number') return a * b;
  if (a === 1) return b;
  if (b === 1) return a;
  return `${group(a)}*${group(b)}`;
}

/** a/d of two cells, as a cell (d ≠ 0). */
function over(a, d) {
  if (a === 0) return 0;
  if (typeof a === 'number' && typeof d === 'number') return a / d;
  if (d === 1) return a;
  return `${group(a)}/${group(d)}`;
}

/** A sum of cells, as a cell: the numbers added, the texts joined by +. */
function sum(terms) {
  const number = terms.filter((x) => typeof x === 'number').reduce((a, x) => a + x, 0);
  const texts = terms.filter((x) => typeof x === 'string');
  if (!texts.length) return number;
  if (number !== 0) texts.push(group(number));
  return texts.join(' + ');
}

/** A computed cell, or null when a number came out too large for a double. */
const finite = (x) => (typeof x === 'number' && !Number.isFinite(x) ? null : x);

/** A model path as the grids name it: `measurement.g[0][1]` → “g [1, 2]”. */
const placeName = (path) => modelPlace(path).replace(/: $/, '');

/** The note on what a conversion could not carry over: [{path, why}]. */
function lostNote(lost) {
  if (!lost.length) return null;
  return `Not converted, left 0: ${lost.map(({ path, why }) => `${placeName(path)} (${why})`).join('; ')}`;
}

/** W = diag φ² (or V = diag ψ²) from the SKOs `sko` at `path`, as an L×L matrix. */
function squares(sko, L, path) {
  const value = resizeMat([], L, L);
  const lost = [];
  for (let l = 0; l < L; l++) {
    const x = asCell(sko?.[l]);
    const square = x === null ? null : finite(typeof x === 'number' ? x * x : `${group(x)}^2`);
    if (square === null) lost.push({ path: `${path}[${l}]`, why: x === null ? 'not a number or an expression' : 'its square is too large' });
    else value[l][l] = square;
  }
  return { value, note: lostNote(lost) };
}

/** The SKOs φ = √diag W (or ψ from V) from the covariance `cov` at `path`; its off-diagonal entries have no SKO. */
function roots(cov, L, path) {
  const value = zeros(L);
  const lost = [];
  for (let i = 0; i < L; i++) {
    for (let j = 0; j < L; j++) {
      const x = asCell(cov?.[i]?.[j]);
      if (i !== j) {
        if (x !== 0) lost.push({ path: `${path}[${i}][${j}]`, why: 'SKOs give a diagonal covariance' });
      } else if (x === null || (typeof x === 'number' && x < 0)) {
        lost.push({ path: `${path}[${i}][${i}]`, why: x === null ? 'not a number or an expression' : 'a negative variance has no SKO' });
      } else {
        value[i] = typeof x === 'number' ? Math.sqrt(x) : `sqrt(${x})`;
      }
    }
  }
  return { value, note: lostNote(lost) };
}

/** Γ = C g (the seed's Z = c(y + gΦ) is Z = c y + c g Φ), n×M. */
function gammaFromG(c, g, { N, n, M }) {
  const lost = [];
  const value = resizeMat([], n, M);
  for (let j = 0; j < n; j++) {
    for (let l = 0; l < M; l++) {
      const terms = [];
      const unreadable = [];
      for (let k = 0; k < N; k++) {
        const [a, b] = [asCell(c?.[j]?.[k]), asCell(g?.[k]?.[l])];
        if (a === null) unreadable.push(`measurement.c[${j}][${k}]`);
        if (b === null) unreadable.push(`measurement.g[${k}][${l}]`);
        terms.push(a === null || b === null ? null : finite(times(a, b)));
      }
      const x = terms.includes(null) ? null : finite(sum(terms));
      if (x !== null) value[j][l] = x;
      else {
        const why = unreadable.length ? `${unreadable.map(placeName).join(', ')}: not a number or an expression` : 'C g is too large';
        lost.push({ path: `measurement.gamma[${j}][${l}]`, why });
      }
    }
  }
  return { value, note: lostNote(lost) };
}

/**
 * g from Γ = C g: one g gives Γ only when C is diagonal (square, its diagonal not 0,
 * 0 elsewhere): then g = Γ / C row by row. Otherwise g starts at 0, and the note says why.
 */
function gFromGamma(c, gamma, { N, n, M }) {
  const value = resizeMat([], N, M);
  const diagonal =
    n === N &&
    Array.from({ length: N }, (_, j) => Array.from({ length: N }, (_, k) => asCell(c?.[j]?.[k]))).every((row, j) =>
      row.every((x, k) => (j === k ? x !== null && x !== 0 : x === 0)),
    );
  if (!diagonal) {
    return { value, note: 'g is 0: Γ = C g gives g only when C is diagonal (then g = Γ / C); enter g' };
  }
  const lost = [];
  for (let k = 0; k < N; k++) {
    for (let l = 0; l < M; l++) {
      const x = asCell(gamma?.[k]?.[l]);
      const y = x === null ? null : finite(over(x, asCell(c[k][k])));
      if (y === null) lost.push({ path: `measurement.gamma[${k}][${l}]`, why: x === null ? 'not a number or an expression' : 'Γ / C is too large' });
      else value[k][l] = y;
    }
  }
  return { value, note: lostNote(lost) };
}

// ------------------------------------------------------------ renaming a parameter

/** The model's matrices and vectors whose cells may be expressions in the params. */
const EXPRESSION_PATHS = [
  'system.a', 'system.transition', 'system.b', 'system.u', 'system.y0', 'system.eta0', 'system.phi', 'system.W',
  'measurement.c', 'measurement.g', 'measurement.gamma', 'measurement.psi', 'measurement.V',
];

/**
 * Names an expression reads as something else: the time variable, and the language's
 * constants and functions (the operator table of src/expr_block.rs; the core refuses
 * them as parameter names). A rename to or from one leaves the expressions alone:
 * `s/m` renamed to `s/e` would quietly mean Euler's number.
 */
const RESERVED = new Set(
  ('t atan2 min max abs signum sin cos tan asin acos atan sinh cosh tanh asinh acosh atanh ' +
    'floor round ceil trunc fract exp sqrt cbrt ln log2 log10 log PI π E e TAU τ').split(' '),
);

/** Whether expressions can use `name` as a parameter. */
const usableName = (name) => IDENTIFIER.test(name) && !RESERVED.has(name);

/**
 * `text` with the name `old` (an identifier) renamed `wanted`: whole identifiers only
 * (`m` in `s/m`, not in `m_g`, `sum` or the exponent of `2e5`).
 */
function renameIdentifier(text, old, wanted) {
  return text.replace(new RegExp(`(?<![\\p{L}\\p{N}_.])${old}(?![\\p{L}\\p{N}_])`, 'gu'), () => wanted);
}

/** `value` with `f` applied to every text in it (nested arrays). */
function mapTexts(value, f) {
  if (Array.isArray(value)) return value.map((v) => mapTexts(v, f));
  return typeof value === 'string' ? f(value) : value;
}

/** Calls `f(path, text)` for every text cell of the model's expression matrices; the cell becomes what it returns. */
function eachExpression(model, f) {
  const walk = (array, path) =>
    array.forEach((v, i) => {
      if (Array.isArray(v)) walk(v, `${path}[${i}]`);
      else if (typeof v === 'string') array[i] = f(`${path}[${i}]`, v);
    });
  for (const path of EXPRESSION_PATHS) {
    const [part, key] = path.split('.');
    if (Array.isArray(model[part]?.[key])) walk(model[part][key], path);
  }
}

/**
 * Why `value` cannot be loaded as a model, or null when it can: it must be a JSON
 * object with at least one of a model's parts (the core's validation names the rest).
 */
export function modelProblem(value) {
  if (value === null || typeof value !== 'object' || Array.isArray(value)) {
    const what = Array.isArray(value) ? 'an array' : value === null ? 'null' : `a ${typeof value}`;
    return `it is ${what}, not a model (a JSON object with system, measurement, time, …)`;
  }
  const parts = ['system', 'measurement', 'time', 'params'];
  if (!parts.some((k) => k in value)) return `it has none of a model's parts (${parts.join(', ')})`;
  const notObject = parts.find((k) => k in value && (value[k] === null || typeof value[k] !== 'object' || Array.isArray(value[k])));
  if (notObject) return `its ${notObject} is not a JSON object`;
  return null;
}

/** The path one level up: `system.a[1][2]` → `system.a[1]` → `system.a` → `system`. */
function parentPath(path) {
  if (path.endsWith(']')) return path.slice(0, path.lastIndexOf('['));
  const dot = path.lastIndexOf('.');
  return dot < 0 ? '' : path.slice(0, dot);
}

/** The path of param `name`, as the core writes it: `params.q`, or `params["a.b"]` for a name that is not an identifier. */
function paramPath(name) {
  return IDENTIFIER.test(name) ? `params.${name}` : `params[${JSON.stringify(name)}]`;
}

/** `{param, name}` for a path at a param's value (`params.q`, `params["a.b"]`) or, name true, its name cell (`….name`); else null. */
function paramOf(path) {
  const m = path.match(/^params(?:\.([^.[]+)|\[("(?:[^"\\]|\\.)*")\])(\.name)?$/);
  if (!m) return null;
  return { param: m[1] ?? JSON.parse(m[2]), name: Boolean(m[3]) };
}

/** A core error at `params.X` that is about the name X (not its value) belongs to the name cell. */
function namePath(error) {
  const path = error.path ?? '';
  const param = paramOf(path);
  if (param && !param.name && /parameter name|cannot be a parameter/.test(error.message)) return `${path}.name`;
  return path;
}

/** The labels of the editor's single fields, by path: the fields and `modelPlace` name them so. */
const FIELD_LABELS = {
  name: 'Name',
  description: 'Description',
  'time.t0': 't₀',
  'time.t_end': 't_E',
  'time.steps': 'Steps D',
  'criteria.confidence': 'Confidence P',
  'options.trace_points': 'Trace points',
  'options.steady_state_shortcut': 'Steady-state shortcut',
  'dimensions.N': 'States N',
  'dimensions.n': 'Measurements n',
  'dimensions.L': 'Model errors L',
  'dimensions.M': 'Meas. errors M',
};

/** The dimensions' words: what one index is, and the names of the indices of a model. */
const DIMENSIONS = {
  N: { one: 'state', many: 'states', help: 'state dimension', names: (m) => m.system?.states ?? [] },
  n: { one: 'measurement', many: 'measurements', help: 'number of measurements', names: (m) => m.measurement?.names ?? [] },
  L: {
    one: 'model-error source',
    many: 'model-error sources',
    help: 'model-error sources F (columns of b)',
    names: (m) => Array.from({ length: dimensions(m).L }, (_, l) => `F${l + 1}`),
  },
  M: {
    one: 'measurement-error source',
    many: 'measurement-error sources',
    help: 'measurement-error sources Φ',
    names: (m) => Array.from({ length: dimensions(m).M }, (_, k) => `Φ${k + 1}`),
  },
};

/**
 * Why the text of dimension `key`'s field cannot be applied (null: it can): a whole
 * number from 1 to 200 (kea's limits), and n ≤ N. `badInput`: the browser could not
 * read the text as a number.
 */
function dimensionProblem(key, text, badInput, dims) {
  const max = key === 'n' ? Math.min(dims.N, MAX_DIMENSION) : MAX_DIMENSION;
  const range = `enter a whole number from 1 to ${max}; ${key} stays ${dims[key]}`;
  if (badInput) return `not a number: ${range}`;
  if (text.trim() === '') return `empty: ${range}`;
  const value = Number(text);
  if (!Number.isInteger(value)) return `${text} is not a whole number: ${range}`;
  if (value < 1) return `the model needs at least one ${DIMENSIONS[key].one}: ${range}`;
  if (value <= max) return null;
  if (key === 'n' && value <= MAX_DIMENSION) return `${value} measurements of ${dims.N} states: kea needs n ≤ N; ${range}`;
  return `${value} is more than kea's limit of ${MAX_DIMENSION}: ${range}`;
}

/** The members of `model` indexed by dimension `axis`, as the editor names them: “a, b, u, y₀, C”. */
function memberList(model, axis) {
  const names = membersAlong(model, axis)
    .filter((path) => path !== 'system.states' && path !== 'measurement.names')
    .map((path) => (path.startsWith('criteria.weights') ? 'weights' : placeName(path)));
  return [...new Set(names)].join(', ');
}

// ------------------------------------------------------------ members without a grid

/** The members each part's section shows with a field or grid of its own ('': the top level). */
function shownMembers(model) {
  const s = model.system ?? {};
  const m = model.measurement ?? {};
  return {
    '': ['kea_model', 'name', 'description', 'params', 'time', 'system', 'measurement', 'criteria', 'options'],
    time: ['t0', 't_end', 'steps'],
    // A discrete model (isDiscrete) shows Φ and where its prior is in place of a.
    system: ['states', s.transition !== undefined ? 'transition' : 'a', 'b', 'u', 'y0', 'eta0', s.W ? 'W' : 'phi', ...(s.transition !== undefined ? ['prior_at'] : [])],
    measurement: ['names', 'c', m.g ? 'g' : 'gamma', m.V ? 'V' : 'psi'],
    criteria: ['confidence'],
    options: ['trace_points', 'steady_state_shortcut'],
  };
}

/** Optional members shown as JSON whether the model has them or not (empty: absent, the default). */
const OPTIONAL_MEMBERS = {
  measurement: {
    schedule: {
      label: 'Schedule (measurement.schedule)',
      help: 'one entry per measurement: null (always), {"every": k, "offset": j}, {"when": "expr in t"} or {"unavailable": [[t1, t2], …]}; empty: every measurement at every step',
      empty: 'none: every measurement at every step',
      summary: scheduleSummary,
    },
    pairs: {
      label: 'Pairs (measurement.pairs)',
      help: '[{"state": "…", "measurement": "…"}, …], each measurement measuring its state; empty: the default pairing (a row of C with one non-zero pairs its state)',
      empty: 'none: the default pairing',
    },
  },
  criteria: {
    weights: {
      label: 'Weights (criteria.weights)',
      help: '{"yz": [N weights ≥ 0 summing to 1], "zx": […], "yx": […]}, each optional; empty: equal weights over the states where the criterion is defined',
      empty: 'none: equal weights',
    },
  },
};

/** Members kea knows that have no field: shown as JSON when the model has them. */
const OTHER_MEMBERS = {
  'time.auto': {
    label: 'Step-size selection (time.auto)',
    help: '{"tolerance": 1e-9, "initial_steps": 1000, "max_steps": 4096000}; used when Steps D is auto',
  },
  'system.a': { label: 'a (system.a) beside Φ', help: 'the model is discrete (transition Φ, per step): give Φ or the continuous a, not both; remove the one not wanted' },
  'system.prior_at': {
    label: 'Prior at (system.prior_at)',
    help: 'where the prior (y₀, η₀) is: "t0" (the default) or, for a discrete model only, "first_measurement"',
  },
  'system.phi': { label: 'φ (system.phi) beside W', help: 'the model errors are given as W: give φ or W, not both; remove the one not wanted' },
  'system.W': { label: 'W (system.W) beside φ', help: 'the model errors are given as φ: give φ or W, not both; remove the one not wanted' },
  'measurement.gamma': { label: 'Γ (measurement.gamma) beside g', help: 'the noise matrix is given as g: give Γ or g, not both; remove the one not wanted' },
  'measurement.g': { label: 'g (measurement.g) beside Γ', help: 'the noise matrix is given as Γ: give Γ or g, not both; remove the one not wanted' },
  'measurement.psi': { label: 'ψ (measurement.psi) beside V', help: 'the measurement errors are given as V: give ψ or V, not both; remove the one not wanted' },
  'measurement.V': { label: 'V (measurement.V) beside ψ', help: 'the measurement errors are given as ψ: give ψ or V, not both; remove the one not wanted' },
};

/** The label and help of a member the format does not have. */
function unknownMember(part, key) {
  const where = part ? `${part}` : 'a model';
  return {
    label: `“${key}” (${part ? `${part}.${key}` : key})`,
    help: `kea's model format has no member “${key}” in ${where} (a misspelling?): remove it, or write its value into the right field`,
  };
}

/** A member's value as the JSON text its field shows: one entry (or key) per line for arrays of objects and for objects. */
function showJson(value) {
  if (value === undefined) return '';
  if (Array.isArray(value) && value.some((x) => x !== null && typeof x === 'object')) {
    return `[\n${value.map((x) => `  ${JSON.stringify(x)}`).join(',\n')}\n]`;
  }
  if (value !== null && typeof value === 'object' && !Array.isArray(value) && Object.keys(value).length) {
    return `{\n${Object.entries(value).map(([k, v]) => `  ${JSON.stringify(k)}: ${JSON.stringify(v)}`).join(',\n')}\n}`;
  }
  return JSON.stringify(value);
}

/** A schedule in words: “z2: unavailable in [8, 14]; the others at every step”. */
function scheduleSummary(schedule, model) {
  if (!Array.isArray(schedule)) return '';
  const names = model.measurement?.names ?? [];
  const say = (entry) => {
    if (entry === null) return null;
    if (typeof entry !== 'object') return JSON.stringify(entry);
    if ('every' in entry) return `every ${entry.every} steps (offset ${entry.offset ?? 0})`;
    if ('when' in entry) return `where ${entry.when} > 0`;
    if (Array.isArray(entry.unavailable)) {
      return `unavailable in ${entry.unavailable.map((iv) => (Array.isArray(iv) ? `[${iv.join(', ')}]` : JSON.stringify(iv))).join(', ')}`;
    }
    return JSON.stringify(entry);
  };
  const said = schedule.map((entry, j) => [names[j] ?? `measurement ${j + 1}`, say(entry)]).filter(([, text]) => text !== null);
  if (!said.length) return 'every measurement at every step';
  const rest = said.length < schedule.length ? '; the others at every step' : '';
  return `${said.map(([name, text]) => `${name}: ${text}`).join('; ')}${rest}`;
}

/** A number field's check (null: fine). */
const aNumber = (text) => numberProblem(text);
const wholeAtLeast = (min) => (text) => numberProblem(text, { integer: true, min });

export class ModelEditor {
  /** `onChange()` is called after every edit of the model. */
  constructor(root, onChange) {
    this.root = root;
    this.onChange = onChange;
    this.model = null;
    this.fields = new Map(); // path → {input, holder}
    this.marks = new Map(); // the messages shown at fields: key → {message, holder} (mark)
    this.invalid = new Set(); // the controls marked invalid (mark)
    this.local = new Map(); // path → message: this editor's own checks of the shown texts
    this.core = []; // the core's last validation errors, kept across redraws
    this.previous = new Map(); // form choice → {form, texts, made}: the form a switch left (switchForm)
    this.notes = new Map(); // form choice → what its last switch could not convert; 'params': the last rename
    this.shelf = new Shelf(); // what smaller dimensions removed, for larger ones to restore (dimensions.js)
    this.undo = null; // the last removal (a smaller N, n, L or M, or a ×): {where, text, dims, focus, apply()} (undoNote)
    this.pendingDims = new Map(); // dimension → a text typed in its field that is not applied (dimensionProblem)
    this.focusNext = null; // a selector of the control to focus after the next render, if not the focused one's
    this.general = el('ul', { class: 'general-errors', 'aria-live': 'polite' });
    new ResizeObserver(() => this.updateScrollHints()).observe(root);
    // Undo and Redo (history.js). `baseline` is the model as of the last committed edit
    // (a JSON copy): a commit records the difference from it. Typing commits when its
    // field changes (Enter, leaving the field), and before anything else is done.
    this.history = new History();
    this.baseline = null;
    this.kept = null; // the editor's state besides the model at the last commit (keptState)
    this.dirty = false; // typed into since the last commit
    this.typedIn = null; // the field typed into
    this.committedText = new WeakMap(); // a field → its text when it took the focus or its edit was committed
    this.historyButtons = null;
    root.addEventListener('input', (e) => {
      this.dirty = true;
      this.typedIn = e.target;
    });
    root.addEventListener('change', () => this.commitPending());
    root.addEventListener('focusout', () => this.commitPending());
    root.addEventListener('paste', () => this.commitPending(), true); // before a block's paste, one edit of its own
    root.addEventListener('focusin', (e) => this.committedText.set(e.target, e.target.value));
  }

  /**
   * Show `model`. `label` (an import, a preset chosen, a link): the model shown before is
   * one Undo away; without it (the page's first model) the history starts anew.
   */
  load(model, label = null) {
    const recorded = Boolean(label && this.model);
    if (recorded) this.commitPending();
    this.model = model;
    this.core = [];
    this.previous.clear();
    this.notes.clear();
    this.shelf = new Shelf();
    this.undo = null;
    this.pendingDims.clear();
    this.render();
    if (recorded) this.commit(label, null);
    else {
      this.history.clear();
      this.baseline = JSON.parse(JSON.stringify(this.model));
      this.kept = this.keptState();
      this.showHistory();
    }
  }

  /**
   * The model changed. `label` names an action that is one edit by itself (a dimension,
   * a removal, a paste, a form switched: “N 6 → 4”), committed to the history at once;
   * without it the change is typing, committed when its field changes (`commitPending`).
   * `focus`: the selector of the control Undo and Redo move the focus to (or
   * {before, after}, one for each).
   */
  changed(label = null, focus = null) {
    this.onChange?.();
    if (label) this.commit(label, focus);
  }

  // ------------------------------------------------------------ undo and redo

  /** What the editor keeps besides the model, as it is now (the shelf is never changed in place, see `ownShelf`). */
  keptState() {
    return {
      shelf: this.shelf,
      previous: new Map([...this.previous].map(([k, v]) => [k, { ...v }])),
      notes: new Map(this.notes),
      undo: this.undo,
    };
  }

  restoreState(state) {
    this.shelf = state.shelf;
    this.previous = new Map([...state.previous].map(([k, v]) => [k, { ...v }]));
    this.notes = new Map(state.notes);
    this.undo = state.undo;
    this.kept = this.keptState();
  }

  /** The shelf, to be changed: a copy, so that the one the history keeps stays as it was. */
  ownShelf() {
    this.shelf = this.shelf.clone();
    return this.shelf;
  }

  /** Commit the typing since the last commit (one cell's or field's edit), if any. */
  commitPending() {
    if (!this.dirty || !this.model) return;
    const field = this.typedIn;
    const path = field?.dataset?.path;
    this.commit(`edit of ${path ? placeName(path) : 'a field'}`, field ? focusSelector(field) : null);
  }

  /** Record the model's difference from the last commit as one edit named `label`. */
  commit(label, focus) {
    this.dirty = false;
    const changes = diff(this.baseline, this.model);
    const before = this.kept;
    this.kept = this.keptState();
    this.settle();
    if (!changes.length) return;
    this.baseline = apply(this.baseline, changes, 'after');
    const shelfBytes = this.kept.shelf !== before.shelf ? this.kept.shelf.bytes() : 0;
    this.history.push({ label, changes, focus, state: { before, after: this.kept }, extraBytes: shelfBytes });
    this.showHistory();
  }

  undoEdit() {
    this.step('undo');
  }

  redoEdit() {
    this.step('redo');
  }

  /**
   * Undo or redo one edit: the model as it was on that side of it (exactly: its JSON),
   * the editor's state with it, and the focus at the field it changed. The cells of an
   * edit inside grids are set in place; anything else redraws.
   */
  step(way) {
    this.commitPending();
    const entry = way === 'undo' ? this.history.undo() : this.history.redo();
    if (!entry) return;
    const side = way === 'undo' ? 'before' : 'after';
    this.model = apply(this.model, entry.changes, side);
    this.baseline = apply(this.baseline, entry.changes, side);
    this.restoreState(entry.state[side]);
    const focus = typeof entry.focus === 'string' ? entry.focus : entry.focus?.[side] ?? null;
    if (!this.patchCells(entry.changes, side, focus)) {
      this.pendingDims.clear();
      this.focusNext = focus;
      this.render();
    }
    this.onChange?.();
    this.settle();
    this.showHistory();
    this.root.dispatchEvent(new CustomEvent('editor-note', { detail: `${way === 'undo' ? 'Undone' : 'Redone'}: ${entry.label}.`, bubbles: true }));
  }

  /**
   * Set the cells an edit of numbers in grids changed (no redraw: at N = 200 a redraw
   * takes a second); returns false, doing nothing, when the edit is anything else.
   */
  patchCells(changes, side, focus) {
    const scalar = (text) => text !== undefined && text[0] !== '[' && text[0] !== '{';
    if (!changes.every((c) => !c.order && c.path.length && scalar(c.before) && scalar(c.after))) return false;
    const cells = changes.map((c) => this.fields.get(pathText(c.path))?.input);
    const inGrid = (input) => {
      const grid = input?.tagName === 'INPUT' ? input.closest('[data-grid]') : null;
      return grid && !['system.states', 'measurement.names'].includes(grid.dataset.grid);
    };
    if (!cells.every(inGrid)) return false;
    changes.forEach((c, k) => {
      const input = cells[k];
      input.value = showValue(JSON.parse(c[side]));
      showTitle(input);
      this.setLocal(input.dataset.path, cellProblem(input.value), false);
    });
    this.mark();
    (focus ? this.root.querySelector(focus) : null)?.focus();
    return true;
  }

  /** The focused field's text is committed: Ctrl+Z there is the editor's, until it is typed into. */
  settle() {
    const active = document.activeElement;
    if (active && this.root.contains(active)) this.committedText.set(active, active.value);
  }

  /** Whether `target` is a text field with typing not committed yet (Ctrl+Z there is the browser's). */
  typing(target) {
    const text = target?.tagName === 'TEXTAREA' || (target?.tagName === 'INPUT' && !['checkbox', 'radio', 'button', 'file'].includes(target.type));
    return Boolean(text && this.committedText.has(target) && this.committedText.get(target) !== target.value);
  }

  /**
   * Undo and Redo: `undo` and `redo` are their buttons; Ctrl+Z, Ctrl+Shift+Z and Ctrl+Y
   * (⌘ on a Mac) work while the focus is in `keys` (the editor's pane), except in a
   * field with typing not committed yet, where they are the browser's (its text's own
   * undo comes first; leaving the field or Enter commits it).
   */
  bindHistory({ undo, redo, keys }) {
    this.historyButtons = { undo, redo };
    undo.addEventListener('click', () => this.undoEdit());
    redo.addEventListener('click', () => this.redoEdit());
    keys.addEventListener('keydown', (e) => {
      if (!(e.ctrlKey || e.metaKey) || e.altKey) return;
      const key = e.key.toLowerCase();
      const isRedo = (key === 'z' && e.shiftKey) || (key === 'y' && !e.shiftKey);
      if (!isRedo && !(key === 'z' && !e.shiftKey)) return;
      if (this.typing(e.target)) return;
      e.preventDefault();
      this.step(isRedo ? 'redo' : 'undo');
    });
    this.showHistory();
  }

  /** The buttons' state and names: what Undo and Redo would do. */
  showHistory() {
    if (!this.historyButtons) return;
    const mac = /Mac|iPhone|iPad/.test(navigator.platform);
    const show = (button, verb, entry, keys) => {
      button.disabled = !entry;
      const name = entry ? `${verb}: ${entry.label}` : `${verb} (nothing to ${verb.toLowerCase()})`;
      button.setAttribute('aria-label', name);
      button.title = `${name} — ${keys}`;
    };
    show(this.historyButtons.undo, 'Undo', this.history.nextUndo, mac ? '⌘Z' : 'Ctrl+Z');
    show(this.historyButtons.redo, 'Redo', this.history.nextRedo, mac ? '⇧⌘Z' : 'Ctrl+Shift+Z or Ctrl+Y');
  }

  /** Messages of this editor's own checks (unreadable numbers, a refused rename). */
  localErrors() {
    return [...this.local].map(([path, message]) => ({ path, message }));
  }

  // ------------------------------------------------------------ rendering

  /**
   * Draw the editor anew. The focus stays on the control that had it (found again by
   * its path, id or focus key), or goes where the change that redraws says (`focusNext`):
   * a control the redraw took away leaves the keyboard where it was, not on the page.
   */
  render() {
    const active = document.activeElement;
    const focused = this.focusNext ?? (this.root.contains(active) ? focusSelector(active) : null);
    this.focusNext = null;
    if (this.undo && JSON.stringify(this.undo.dims) !== JSON.stringify(dimensions(this.model))) this.undo = null;
    this.fields.clear();
    this.marks.clear();
    this.invalid.clear();
    this.local.clear();
    const m = this.model;
    m.system ??= {};
    m.measurement ??= {};
    m.time ??= { t0: 0, t_end: 1, steps: 1000 };
    const dims = dimensions(m);
    this.root.replaceChildren(
      this.general,
      this.sectionModel(),
      this.sectionParams(),
      this.sectionTime(dims),
      this.sectionSystem(dims),
      this.sectionMeasurement(dims),
      ...[this.sectionCriteria(), this.sectionOther()].filter(Boolean),
    );
    this.mark();
    this.updateScrollHints();
    if (focused) this.root.querySelector(focused)?.focus();
  }

  register(path, input, holder) {
    this.fields.set(path, { input, holder: holder ?? input.parentElement });
  }

  /** Record this editor's check of `path` (a message, or null when fine) and re-mark. */
  setLocal(path, message, markNow = true) {
    if (message) this.local.set(path, message);
    else this.local.delete(path);
    if (markNow) this.mark();
  }

  /**
   * A labelled input bound to obj[key]; `parse` turns its text into the value, `check`
   * says what is wrong with a text (null: fine); with `optional`, an empty text removes
   * the key (the core's default applies).
   */
  field(label, path, obj, key, { type = 'text', parse = parseCell, check, optional = false, placeholder, help } = {}) {
    const id = `f-${path.replace(/[^a-zA-Z0-9]/g, '-')}`;
    const input = el('input', {
      id,
      type,
      'data-path': path,
      value: showValue(obj[key]),
      placeholder,
      'aria-describedby': help ? `${id}-help` : undefined,
    });
    if (type === 'checkbox') input.checked = !!obj[key];
    const problem = (text) => (optional && text.trim() === '' ? null : check?.(text) ?? null);
    input.addEventListener('input', () => {
      if (type === 'checkbox') obj[key] = input.checked;
      else if (optional && input.value.trim() === '') delete obj[key];
      else obj[key] = parse(input.value);
      if (check) this.setLocal(path, problem(input.value));
      this.changed();
    });
    if (check) this.setLocal(path, problem(input.value), false);
    const wrap = el('div', { class: 'field' }, el('label', { for: id, text: label }), input);
    if (help) wrap.append(el('small', { id: `${id}-help`, class: 'help', text: help }));
    this.register(path, input, wrap);
    return wrap;
  }

  sectionModel() {
    const m = this.model;
    const desc = el('textarea', { id: 'f-description', rows: 2, 'data-path': 'description' });
    desc.value = m.description ?? '';
    desc.addEventListener('input', () => {
      m.description = desc.value;
      this.changed();
    });
    const fs = el(
      'fieldset',
      { class: 'section' },
      el('legend', { text: 'Name and description' }),
      this.field(FIELD_LABELS.name, 'name', m, 'name', { parse: (s) => s }),
      el('div', { class: 'field wide' }, el('label', { for: 'f-description', text: FIELD_LABELS.description }), desc),
    );
    this.register('description', desc);
    return fs;
  }

  /**
   * One parameter's row. A rename changes the row in place (no redraw: focus, a click
   * under way and the marks stay); a name that is taken or empty is refused at the cell.
   */
  paramRow(initial) {
    const m = this.model;
    let name = initial;
    const nameInput = el('input', { value: name, class: 'name', spellcheck: 'false', autocomplete: 'off' });
    const valueInput = el('input', { value: showValue(m.params[name]), inputmode: 'decimal', spellcheck: 'false', autocomplete: 'off' });
    const remove = el('button', { type: 'button', class: 'icon', text: '×' });
    const nameCell = el('td', {}, nameInput);
    const valueCell = el('td', {}, valueInput);
    const label = () => {
      nameInput.dataset.path = `${paramPath(name)}.name`;
      nameInput.setAttribute('aria-label', `parameter name ${name}`);
      valueInput.dataset.path = paramPath(name);
      valueInput.setAttribute('aria-label', `value of ${name}`);
      remove.setAttribute('aria-label', `remove parameter ${name}`);
      remove.dataset.focus = `remove-param:${name}`;
      remove.title = `Remove ${name}`;
      this.register(`${paramPath(name)}.name`, nameInput, nameCell);
      this.register(paramPath(name), valueInput, valueCell);
    };
    label();
    this.setLocal(paramPath(name), aNumber(valueInput.value), false);

    nameInput.addEventListener('change', () => {
      const wanted = nameInput.value.trim();
      const old = name;
      let problem = null;
      if (wanted === old) nameInput.value = old;
      else if (!wanted) problem = `a parameter needs a name (× removes ${old})`;
      else if (Object.hasOwn(m.params, wanted)) {
        problem = `“${wanted}” is already a parameter: renaming ${old} to it would replace it; choose another name`;
      }
      if (problem || wanted === old) {
        this.setLocal(`${paramPath(old)}.name`, problem);
        return;
      }
      this.commitPending();
      // Keep the order: rebuild the object with the new key in place.
      m.params = Object.fromEntries(Object.entries(m.params).map(([k, v]) => [k === old ? wanted : k, v]));
      const valueProblem = this.local.get(paramPath(old));
      for (const p of [paramPath(old), `${paramPath(old)}.name`]) {
        this.local.delete(p);
        this.fields.delete(p);
      }
      // The core's marks at the old name are stale until the next check.
      this.core = this.core.filter((e) => !(e.path === paramPath(old) || e.path?.startsWith(`${paramPath(old)}.`)));
      name = wanted;
      label();
      this.setLocal(paramPath(name), valueProblem ?? null);
      this.renameUses(old, wanted);
      const at = (p) => `[data-path="${CSS.escape(`${paramPath(p)}.name`)}"]`;
      this.changed(`rename of parameter ${old} → ${wanted}`, { before: at(old), after: at(wanted) });
    });
    nameInput.addEventListener('keydown', (e) => {
      if (e.key !== 'Enter') return;
      e.preventDefault();
      nameInput.dispatchEvent(new Event('change')); // commit, then on to the value
      if (!this.local.has(`${paramPath(name)}.name`)) {
        valueInput.focus();
        valueInput.select();
      }
    });
    valueInput.addEventListener('input', () => {
      m.params[name] = parseCell(valueInput.value);
      this.setLocal(paramPath(name), aNumber(valueInput.value));
      this.changed();
    });
    remove.addEventListener('click', () => {
      // The focus goes to the × of the row that takes this one's place (or of the row
      // above, the last one removed), then to "Add parameter".
      const names = Object.keys(m.params);
      const at = names.indexOf(name);
      const next = names[at + 1] ?? names[at - 1];
      this.commitPending();
      const after = (this.focusNext = byFocusKey(next === undefined ? 'add-param' : `remove-param:${next}`));
      delete m.params[name];
      this.render();
      this.changed(`removal of parameter ${name}`, { before: byFocusKey(`remove-param:${name}`), after });
    });
    return el('tr', {}, nameCell, valueCell, el('td', {}, remove));
  }

  /**
   * Rename parameter `old`'s uses in every expression cell, and in the forms kept for
   * switching back, so that a rename does not break them (“unknown parameter "m" in
   * "s/m"”); the note below the parameters says how many cells changed.
   */
  renameUses(old, wanted) {
    const apply = usableName(wanted); // `s/2x` would not parse: leave the uses as they are
    let cells = 0;
    if (usableName(old)) {
      eachExpression(this.model, (path, text) => {
        const renamed = renameIdentifier(text, old, wanted);
        if (renamed === text) return text;
        cells++;
        if (!apply) return text;
        const input = this.fields.get(path)?.input;
        if (input) {
          input.value = renamed;
          showTitle(input);
        }
        return renamed;
      });
    }
    if (apply && cells) {
      const rename = (text) => renameIdentifier(text, old, wanted);
      for (const kept of this.previous.values()) {
        kept.texts = mapTexts(kept.texts, rename);
        kept.made = JSON.stringify(mapTexts(JSON.parse(kept.made), rename));
      }
    }
    const count = `${cells} cell${cells === 1 ? '' : 's'}`;
    let note = `renamed ${old} → ${wanted} in ${count}`;
    if (!cells) note = `renamed ${old} → ${wanted}; no expression uses it`;
    else if (!apply) note = `${old} is still used in ${count}: expressions cannot use “${wanted}” as a parameter`;
    this.notes.set('params', note);
    this.paramsNote.textContent = note;
  }

  sectionParams() {
    const m = this.model;
    if (m.params === null || typeof m.params !== 'object' || Array.isArray(m.params)) m.params = {};
    // What the last rename did to the expressions (a live region: it is there before it says it).
    this.paramsNote = el('p', { class: 'help', role: 'status', 'data-note': 'params', text: this.notes.get('params') });
    const body = el('tbody');
    for (const name of Object.keys(m.params)) body.append(this.paramRow(name));
    const add = el('button', {
      type: 'button',
      text: 'Add parameter',
      'data-focus': 'add-param',
      onclick: () => {
        this.commitPending();
        let i = 1;
        while (`p${i}` in m.params) i++;
        m.params[`p${i}`] = 0;
        this.render();
        this.changed(`new parameter p${i}`, { before: byFocusKey('add-param'), after: `[data-path="params.p${i}.name"]` });
        // The name selected, so that typing replaces the placeholder p1 (not “windp1”).
        const input = this.root.querySelector(`[data-path="params.p${i}.name"]`);
        input?.focus();
        input?.select();
      },
    });
    const table = el(
      'table',
      { class: 'grid params' },
      el('thead', {}, el('tr', {}, el('th', { text: 'name' }), el('th', { text: 'value' }), el('th'))),
      body,
    );
    const fs = el(
      'fieldset',
      { class: 'section' },
      el('legend', { text: 'Parameters' }),
      el('p', { class: 'help', text: 'Named numbers usable in every expression (with t).' }),
      table,
      add,
      this.paramsNote,
    );
    this.register('params', table, fs);
    return fs;
  }

  sectionTime(dims) {
    const m = this.model;
    const steps = (s) => (s.trim() === 'auto' ? 'auto' : parseCell(s));
    const stepsProblem = (s) => {
      const problem = s.trim() === 'auto' ? null : numberProblem(s, { integer: true, min: 1 });
      return problem && `${problem}; D is a whole number ≥ 1 or auto`;
    };
    return el(
      'fieldset',
      { class: 'section' },
      el('legend', { text: 'Time and dimensions' }),
      el(
        'div',
        { class: 'row' },
        this.field(FIELD_LABELS['time.t0'], 'time.t0', m.time, 't0', { check: aNumber }),
        this.field(FIELD_LABELS['time.t_end'], 'time.t_end', m.time, 't_end', { check: aNumber }),
        this.field(`${FIELD_LABELS['time.steps']} (or auto)`, 'time.steps', m.time, 'steps', { parse: steps, check: stepsProblem }),
      ),
      el('div', { class: 'row dimensions' }, ...['N', 'n', 'L', 'M'].map((key) => this.dimensionField(key, dims))),
      this.undoNote('dims'),
      ...this.otherMembers('time'),
    );
  }

  /**
   * The field of dimension `key` (N, n, L or M). A whole number in its range is applied
   * when the field changes (Enter, Tab, an arrow key's step); anything else is marked at
   * the field and not applied: the model keeps its size (Esc puts the size back in the
   * field). The focus stays in the field across the redraw.
   */
  dimensionField(key, dims) {
    const id = `dim-${key}`;
    const path = `dimensions.${key}`;
    const pending = this.pendingDims.get(key);
    const input = el('input', {
      id,
      type: 'number',
      min: 1,
      max: key === 'n' ? Math.min(dims.N, MAX_DIMENSION) : MAX_DIMENSION,
      step: 1,
      value: pending ?? dims[key],
      title: DIMENSIONS[key].help,
    });
    const problem = () => dimensionProblem(key, input.value, input.validity.badInput, dims);
    if (pending !== undefined) this.setLocal(path, problem(), false);
    input.addEventListener('input', () => {
      const now = problem();
      if ((this.local.get(path) ?? null) !== now) this.setLocal(path, now);
    });
    input.addEventListener('change', () => {
      const now = problem();
      if (now) {
        this.pendingDims.set(key, input.value);
        this.setLocal(path, now);
        return;
      }
      this.pendingDims.delete(key);
      this.setLocal(path, null);
      this.setDimension(key, Number(input.value));
    });
    input.addEventListener('keydown', (e) => {
      if (e.key !== 'Escape' || !this.local.has(path)) return;
      input.value = String(dims[key]);
      this.pendingDims.delete(key);
      this.setLocal(path, null);
    });
    const wrap = el('div', { class: 'field' }, el('label', { for: id, text: FIELD_LABELS[path], title: DIMENSIONS[key].help }), input);
    this.register(path, input, wrap);
    return wrap;
  }

  /**
   * Resize the model to `size` in dimension `key`. What a smaller size removes stays on
   * the shelf (a larger size takes it back); when it was more than the zeros and names
   * growing back creates, a note says what went and offers Undo.
   */
  setDimension(key, size) {
    const m = this.model;
    const before = dimensions(m);
    if (size === before[key]) return;
    this.commitPending();
    const old = structuredClone(m);
    resize(m, { ...before, [key]: size }, this.ownShelf());
    if (size < before[key] && !removedOnlyDefaults(old, m)) {
      const { one, many, names } = DIMENSIONS[key];
      const gone = names(old).slice(size);
      const list = gone.map((x) => `“${x}”`).join(', ');
      this.undo = {
        where: 'dims',
        dims: dimensions(m),
        text:
          `${key} ${before[key]} → ${size} removed the ${gone.length === 1 ? one : many} ${list} with ${gone.length === 1 ? 'its' : 'their'} entries in ` +
          `${memberList(old, key)}. Growing ${key} back restores ${gone.length === 1 ? 'it' : 'them'} (until another model is loaded).`,
        focus: `#dim-${key}`,
        label: `${key} ${size} → ${before[key]} (the note's Undo)`,
        apply: () => resize(this.model, { ...dimensions(this.model), [key]: before[key] }, this.ownShelf()),
      };
    }
    this.render();
    this.changed(`${key} ${before[key]} → ${size}`, `#dim-${key}`);
  }

  /**
   * Remove state (`axis` 'N') or measurement ('n') number `k`, from every member; a note
   * offers Undo, which puts it back in its place. The focus goes to the × of the row
   * that takes its place (or of the row above, for the last row).
   */
  removeOne(axis, k) {
    this.commitPending();
    const m = this.model;
    const before = structuredClone(m);
    const { one } = DIMENSIONS[axis];
    const name = DIMENSIONS[axis].names(m)[k];
    const members = memberList(m, axis);
    const pairs = removeAt(m, axis, k, this.ownShelf());
    const where = axis === 'N' ? 'system' : 'measurement';
    const left = DIMENSIONS[axis].names(m).length;
    this.undo = {
      where,
      dims: dimensions(m),
      text: `Removed the ${one} “${name}” with its entries in ${members}${pairs.length ? ' and its pair in pairs' : ''}.`,
      focus: byFocusKey(`remove-${one}:${k}`),
      label: `return of the ${one} “${name}” (the note's Undo)`,
      apply: () => restoreAt(this.model, axis, k, before, pairs, this.ownShelf()),
    };
    const after = (this.focusNext = left > 1 ? byFocusKey(`remove-${one}:${Math.min(k, left - 1)}`) : byFocusKey(`undo-${where}`));
    this.render();
    this.changed(`removal of the ${one} “${name}”`, { before: byFocusKey(`remove-${one}:${k}`), after });
  }

  /** The × that removes state or measurement `i` (`axis` 'N' or 'n'), beside its name. */
  removeButton(axis, i, count, names) {
    const { one } = DIMENSIONS[axis];
    const name = names?.[i] ?? '';
    return el('button', {
      type: 'button',
      class: 'icon',
      text: '×',
      'aria-label': `remove ${one} ${name}`,
      title: count > 1 ? `Remove ${one} ${name} (its entries in every matrix; Undo brings it back)` : `The model needs at least one ${one}`,
      disabled: count <= 1,
      'data-focus': `remove-${one}:${i}`,
      'data-remove-of': `${axis === 'N' ? 'system.states' : 'measurement.names'}[${i}]`,
      onclick: () => this.removeOne(axis, i),
    });
  }

  /** The note on the last removal shown at `where` ('dims', 'system', 'measurement'), with its Undo; null when none. */
  undoNote(where) {
    const undo = this.undo;
    if (!undo || undo.where !== where) return null;
    const button = el('button', {
      type: 'button',
      text: 'Undo',
      'data-focus': `undo-${where}`,
      onclick: () => {
        this.commitPending();
        this.undo = null;
        undo.apply();
        this.focusNext = undo.focus;
        this.render();
        this.changed(undo.label, undo.focus);
      },
    });
    return el('p', { class: 'help undo-note', role: 'status', 'data-note': `undo-${where}` }, `${undo.text} `, button);
  }

  /**
   * A grid of cells for a matrix (`rows`×`cols`) or a vector (`cols` = 0) at `path`
   * inside `obj[key]`; absent optional vectors show 0 and are created on first edit, as
   * are rows and entries a ragged matrix lacks. `rowNames`/`colNames` are the paths of
   * the name vectors that label the rows/columns (kept current as the names are typed).
   * `rowAction(i)`, if given, is a control at the end of row i (a name's ×).
   *
   * Built for N = 200 (a, C and Γ: up to 120 000 cells). The cells are written as one
   * HTML text (a createElement and listeners per cell took seconds), and the grid
   * listens for all of them (`cellEdited`, `gridKey`, `gridPaste`). A grid of more than
   * LARGE_GRID cells is not a table: the browser lays a table out whole, and with
   * 40 000 inputs every frame after a keystroke took 0.2–2 s of style, layout and paint.
   * Its rows are flex rows of fixed-width cells in blocks of SEGMENT with
   * `content-visibility: auto` (style.css), so that the browser lays out and paints
   * only the blocks near the window; every cell stays in the page (Tab, find, the
   * tests), unlike a virtualised grid. An edit changes its cell, its marks and the
   * model, never the grid (the DOM nodes stay).
   */
  grid({ title, path, obj, key, rows, cols, rowLabels, colLabels, rowNames, colNames, create, text = false, rowAction }) {
    const vector = cols === 0;
    const width = vector ? 1 : cols;
    const large = rows * width > LARGE_GRID;
    const hint = '<span class="scroll-hint"> — scroll sideways for more ↔</span>';
    const labelOf = (names, k) => (names ? ` data-label-of="${escapeHtml(`${names}[${k}]`)}"` : '');
    const cellPath = (i, j) => (vector ? `${path}[${i}]` : `${path}[${i}][${j}]`);
    const named = escapeHtml(title);
    // The cell (i, j) as HTML, its own check recorded. Paths and numbers need no
    // escaping; a large grid's cells leave spellcheck to the grid, and their indices
    // to their path (`cellAt`): 120 000 cells are 25 MB of HTML at 200 characters each.
    // autocomplete="off" stays: without it Chromium's autofill looked at every input
    // at each change of the address (history.replaceState), 0.5 s at 120 000.
    const cell = (i, j) => {
      const at = cellPath(i, j);
      const current = vector ? obj[key]?.[i] : obj[key]?.[i]?.[j];
      let shown = typeof current === 'number' ? String(current) : showValue(current);
      if (typeof current !== 'number') {
        if (!text) this.setLocal(at, cellProblem(shown), false);
        shown = escapeHtml(shown);
      }
      const input =
        `<input value="${shown}"${shown ? ` title="${shown}"` : ''}${current === undefined && !text ? ' placeholder="0"' : ''} data-path="${at}"` +
        ` aria-label="${named} ${vector ? `[${i + 1}]` : `[${i + 1}, ${j + 1}]`}"`;
      return large ? `<div>${input} autocomplete="off"></div>` : `<td data-path="${at}">${input} spellcheck="false" autocomplete="off"></td>`;
    };
    const html = [];
    let table;
    let caption;
    if (!large) {
      table = el('table', { class: 'grid', 'data-grid': path });
      if (colLabels) {
        html.push('<thead><tr><th></th>');
        colLabels.forEach((c, j) => html.push(`<th scope="col"${labelOf(colNames, j)}>${escapeHtml(c)}</th>`));
        html.push('</tr></thead>');
      }
      html.push('<tbody>');
      for (let i = 0; i < rows; i++) {
        html.push(`<tr><th scope="row"${labelOf(rowNames, i)}>${escapeHtml(rowLabels?.[i] ?? String(i + 1))}</th>`);
        for (let j = 0; j < width; j++) html.push(cell(i, j));
        html.push(rowAction ? '<td></td></tr>' : '</tr>');
      }
      html.push('</tbody>');
      table.innerHTML = html.join('');
      caption = el('caption', {}, title);
      caption.insertAdjacentHTML('beforeend', hint);
      table.prepend(caption);
      if (rowAction) table.querySelectorAll('tbody > tr').forEach((tr, i) => tr.lastElementChild.append(rowAction(i)));
    } else {
      // The row labels' column as wide as the longest label (up to 12 characters; a
      // longer one is cut short, whole in its tooltip).
      const labels = Array.from({ length: rows }, (_, i) => String(rowLabels?.[i] ?? i + 1));
      const labelWidth = Math.min(12, Math.max(2, ...labels.map((s) => s.length)));
      const id = `grid-${path.replace(/[^a-zA-Z0-9]/g, '-')}`;
      table = el('div', {
        class: 'grid large',
        'data-grid': path,
        role: 'group',
        'aria-labelledby': id,
        spellcheck: 'false',
        style: `--label-width: ${labelWidth + 1}ch`,
      });
      html.push(`<div class="caption" id="${id}">${named}${hint}</div>`);
      if (colLabels) {
        html.push('<div class="grid-row"><div class="label"></div>');
        colLabels.forEach((c, j) => html.push(`<div class="col-label"${labelOf(colNames, j)} title="${escapeHtml(c)}">${escapeHtml(c)}</div>`));
        html.push('</div>');
      }
      const lastBlock = width % SEGMENT;
      for (let i = 0; i < rows; i++) {
        const label = escapeHtml(labels[i]);
        html.push(`<div class="grid-row"><div class="label"${labelOf(rowNames, i)} title="${label}">${label}</div>`);
        for (let j = 0; j < width; j++) {
          if (j % SEGMENT === 0) html.push(j + SEGMENT > width ? `<div class="segment" style="--cells: ${lastBlock}">` : '<div class="segment">');
          html.push(cell(i, j));
          if (j % SEGMENT === SEGMENT - 1 || j === width - 1) html.push('</div>');
        }
        html.push('</div>');
      }
      table.innerHTML = html.join('');
      caption = table.firstElementChild;
    }
    const inputs = table.getElementsByTagName('input');
    for (let k = 0; k < inputs.length; k++) {
      const input = inputs[k];
      this.fields.set(cellPath(Math.floor(k / width), k % width), { input, holder: input.parentElement });
    }
    const grid = { path, obj, key, rows, cols, width, vector, text, create, title, inputs, table };
    grid.at = (i, j) => (i >= 0 && i < rows && j >= 0 && j < width ? inputs[i * width + j] : undefined);
    const isCell = (target) => target.tagName === 'INPUT' && target.dataset.path?.startsWith(`${path}[`);
    table.addEventListener('input', (e) => isCell(e.target) && this.cellEdited(grid, e.target));
    table.addEventListener('keydown', (e) => isCell(e.target) && this.gridKey(e, grid));
    table.addEventListener('paste', (e) => isCell(e.target) && this.gridPaste(e, grid));
    if (text) {
      // A name's rename reaches the pairs that name it, when the edit is done.
      const was = new WeakMap(); // input → its text when it took the focus
      table.addEventListener('focusin', (e) => isCell(e.target) && was.set(e.target, e.target.value));
      table.addEventListener('change', (e) => {
        if (!isCell(e.target)) return;
        this.renameInPairs(path, was.get(e.target) ?? e.target.defaultValue, e.target.value);
        was.set(e.target, e.target.value);
      });
    }
    this.register(path, table, caption);
    const wrap = el('div', { class: 'grid-wrap' }, table);
    wrap.addEventListener('scroll', () => this.scrollHint(wrap), { passive: true });
    return wrap;
  }

  /** The row and column of `grid`'s cell `input` (from its path: `system.a[2][3]` → [2, 3]; a vector's column is 0). */
  cellAt(grid, input) {
    const [, i, j] = input.dataset.path.slice(grid.path.length).match(/^\[(\d+)\](?:\[(\d+)\])?$/);
    return [Number(i), Number(j ?? 0)];
  }

  /**
   * Put `input`'s text into the model as the entry of `grid` it shows (with the names
   * that label rows and columns, for a text grid), and record its own check; the
   * caller marks and reports the change. Returns whether the check's verdict changed.
   */
  putCell(grid, input) {
    const { obj, key, cols, vector, text } = grid;
    const [i, j] = this.cellAt(grid, input);
    const at = input.dataset.path;
    showTitle(input);
    // A number's own check (“1e400” is too large), marked only when it changes: a
    // redrawn mark is announced again.
    const problem = text ? null : cellProblem(input.value);
    const changed = (this.local.get(at) ?? null) !== problem;
    if (changed) this.setLocal(at, problem, false);
    if (!Array.isArray(obj[key])) obj[key] = grid.create();
    const value = text ? input.value : parseCell(input.value);
    const target = obj[key];
    if (vector) {
      while (target.length < i) target.push(text ? '' : 0);
      target[i] = value;
    } else {
      // A ragged matrix (imported, linked) gets the rows and entries it lacks.
      while (target.length <= i) target.push([]);
      if (!Array.isArray(target[i])) target[i] = [];
      while (target[i].length < cols) target[i].push(0);
      target[i][j] = value;
    }
    if (text) {
      for (const th of this.root.querySelectorAll(`[data-label-of="${CSS.escape(at)}"]`)) {
        th.textContent = input.value;
        if (th.title) th.title = input.value;
      }
      for (const button of this.root.querySelectorAll(`[data-remove-of="${CSS.escape(at)}"]`)) {
        button.setAttribute('aria-label', button.getAttribute('aria-label').replace(/^(remove \S+) .*$/s, `$1 ${input.value}`));
      }
    }
    return changed;
  }

  /** One cell of `grid` typed into: the model, the cell's marks, and one change. */
  cellEdited(grid, input) {
    if (this.putCell(grid, input)) this.mark();
    this.changed();
  }

  /**
   * A state's or measurement's rename (`names`: 'system.states' or 'measurement.names')
   * in `measurement.pairs`, which names them: the pairs of `old` follow it, unless
   * another state (measurement) is still called `old`.
   */
  renameInPairs(names, old, wanted) {
    const m = this.model.measurement;
    const field = names === 'system.states' ? 'state' : names === 'measurement.names' ? 'measurement' : null;
    if (!field || old === wanted || !Array.isArray(m.pairs)) return;
    const list = names === 'system.states' ? this.model.system.states : m.names;
    if (list.includes(old)) return;
    let renamed = false;
    for (const pair of m.pairs) {
      if (pair?.[field] === old) {
        pair[field] = wanted;
        renamed = true;
      }
    }
    const shown = this.fields.get('measurement.pairs')?.input;
    if (renamed && shown && !this.local.has('measurement.pairs')) shown.value = showJson(m.pairs);
    if (renamed) this.changed();
  }

  /** Mark the grids wider than their box: a caption hint and a faded edge per side with more. */
  scrollHint(wrap) {
    const more = wrap.scrollWidth - wrap.clientWidth;
    wrap.classList.toggle('overflows', more > 1);
    wrap.classList.toggle('more-left', wrap.scrollLeft > 1);
    wrap.classList.toggle('more-right', more - wrap.scrollLeft > 1);
  }

  updateScrollHints() {
    for (const wrap of this.root.querySelectorAll('.grid-wrap')) this.scrollHint(wrap);
  }

  /**
   * A block pasted into a grid's cell — rows from a spreadsheet (tab-separated) or from
   * MATLAB or numpy (separated by spaces, commas or semicolons, on several lines) —
   * fills the grid from that cell on, as a spreadsheet does, each value checked as if
   * typed. What falls beyond the grid's edge is left out, and a note on the page says
   * how much. A single value (no tab, one line) pastes into the cell as usual. The
   * block is one edit: the model takes every value, then the marks are updated and the
   * change reported once (a 200×200 block was 40 000 edits, each checked and reported).
   */
  gridPaste(e, grid) {
    const text = e.clipboardData?.getData('text/plain') ?? '';
    const tabbed = text.includes('\t');
    const lines = text.replace(/\r\n?/g, '\n').replace(/\n+$/, '').split('\n');
    if (!tabbed && lines.length < 2) return;
    e.preventDefault();
    const [r0, c0] = this.cellAt(grid, e.target);
    let pasted = 0;
    let left = 0;
    let remark = false;
    lines.forEach((line, dr) => {
      const cells = tabbed ? line.split('\t') : line.trim().split(/[\s,;]+/);
      cells.forEach((value, dc) => {
        const cell = grid.at(r0 + dr, c0 + dc);
        if (!cell) {
          left += 1;
          return;
        }
        cell.value = value.trim();
        if (this.putCell(grid, cell)) remark = true;
        pasted += 1;
      });
    });
    if (remark) this.mark();
    if (pasted) this.changed(`paste of ${pasted} value${pasted === 1 ? '' : 's'} into ${placeName(grid.path)}`, focusSelector(e.target));
    const note = `Pasted ${pasted} value${pasted === 1 ? '' : 's'} into ${grid.title}` + (left > 0 ? `; ${left} beyond its edge left out.` : '.');
    this.root.dispatchEvent(new CustomEvent('editor-note', { detail: note, bubbles: true }));
  }

  /** Arrow keys and Enter move between the cells of a grid. */
  gridKey(e, grid) {
    const input = e.target;
    const [r, c] = this.cellAt(grid, input);
    let dr = 0;
    let dc = 0;
    if (e.key === 'ArrowUp') dr = -1;
    else if (e.key === 'ArrowDown' || e.key === 'Enter') dr = 1;
    else if (e.key === 'ArrowLeft' && input.selectionStart === 0 && input.selectionEnd === 0) dc = -1;
    else if (e.key === 'ArrowRight' && input.selectionStart === input.value.length) dc = 1;
    else return;
    const next = grid.at(r + dr, c + dc);
    if (next) {
      e.preventDefault();
      next.focus();
      next.select();
    }
  }

  /** A choice between two forms of one quantity (φ or W, Γ or g, ψ or V). */
  formChoice(label, name, options, current, onPick) {
    const id = `form-${name}`;
    const select = el('select', { id });
    for (const [value, text] of options) {
      select.append(el('option', { value, text, selected: value === current }));
    }
    select.addEventListener('change', () => {
      this.commitPending();
      onPick(select.value);
      this.render();
      this.changed(`${label}: ${options.find(([value]) => value === select.value)[1]}`, `#${id}`);
    });
    const note = this.notes.get(name);
    return el(
      'div',
      { class: 'field' },
      el('label', { for: id, text: label }),
      select,
      note ? el('p', { class: 'help form-note', role: 'status', 'data-note': name, text: note }) : null,
    );
  }

  /**
   * Switch the quantity `name` from its form `obj[from]` to `obj[to]`; `convert()` gives
   * {value, note} (note: what it could not convert). The texts left are kept: switching
   * straight back (the new form, and `context`, what the conversion read besides,
   * unchanged) restores them as they were, where converting back would rewrite them
   * (`f*psi` → `(f*psi)^2` → `sqrt((f*psi)^2)`).
   */
  switchForm(name, obj, from, to, convert, context = null) {
    const kept = this.previous.get(name);
    const back = kept?.form === to && kept.made === JSON.stringify([obj[from], context]);
    const { value, note } = back ? { value: kept.texts, note: null } : convert();
    this.previous.set(name, { form: from, texts: obj[from], made: JSON.stringify([value, context]) });
    obj[to] = value;
    delete obj[from];
    this.notes.set(name, note && `${note}. Switching straight back restores the values as they were.`);
  }

  sectionSystem({ N, L }) {
    const s = this.model.system;
    const states = s.states ?? [];
    const lcols = Array.from({ length: L }, (_, l) => `F${l + 1}`);
    const errorForm = s.W ? 'W' : 'phi';
    const errorsGrid =
      errorForm === 'W'
        ? this.grid({ title: 'W (L×L)', path: 'system.W', obj: s, key: 'W', rows: L, cols: L, rowLabels: lcols, colLabels: lcols, create: () => resizeMat([], L, L) })
        : this.grid({ title: 'φ model-error SKOs (L)', path: 'system.phi', obj: s, key: 'phi', rows: L, cols: 0, rowLabels: lcols, create: () => zeros(L) });
    // A discrete model (the identification's form) has Φ per step in place of a, and
    // says where its prior is; a model cannot be switched between the forms here (Φ is
    // not a's cells: Φ = exp(a Δt)).
    const discrete = isDiscrete(this.model);
    const dynamics = discrete
      ? this.grid({ title: 'Φ transition per step (N×N)', path: 'system.transition', obj: s, key: 'transition', rows: N, cols: N, rowLabels: states, colLabels: states, rowNames: 'system.states', colNames: 'system.states', create: () => resizeMat([], N, N) })
      : this.grid({ title: 'a (N×N)', path: 'system.a', obj: s, key: 'a', rows: N, cols: N, rowLabels: states, colLabels: states, rowNames: 'system.states', colNames: 'system.states', create: () => resizeMat([], N, N) });
    return el(
      'fieldset',
      { class: 'section' },
      el('legend', { text: discrete ? 'System (discrete)  Y_k = Φ Y_{k−1} + u + b F' : 'System  dY/dt = a Y + u + b F' }),
      discrete ? el('p', { class: 'help', text: 'A discrete-time model: the Identification tab reads it; the analysis, the synthesis and the Monte Carlo need the continuous a.' }) : null,
      this.undoNote('system'),
      el(
        'div',
        { class: 'grids' },
        this.grid({
          title: 'State names',
          path: 'system.states',
          obj: s,
          key: 'states',
          rows: N,
          cols: 0,
          text: true,
          create: () => [],
          rowAction: (i) => this.removeButton('N', i, N, states),
        }),
        dynamics,
        this.grid({ title: 'b (N×L)', path: 'system.b', obj: s, key: 'b', rows: N, cols: L, rowLabels: states, colLabels: lcols, rowNames: 'system.states', create: () => resizeMat([], N, L) }),
        this.grid({ title: 'u (N)', path: 'system.u', obj: s, key: 'u', rows: N, cols: 0, rowLabels: states, rowNames: 'system.states', create: () => zeros(N) }),
        this.grid({ title: 'y₀ (N)', path: 'system.y0', obj: s, key: 'y0', rows: N, cols: 0, rowLabels: states, rowNames: 'system.states', create: () => zeros(N) }),
        this.grid({ title: 'η₀ initial SKOs (N)', path: 'system.eta0', obj: s, key: 'eta0', rows: N, cols: 0, rowLabels: states, rowNames: 'system.states', create: () => zeros(N) }),
        el(
          'div',
          { class: 'stack' },
          this.formChoice('Model errors given as', 'system-errors', [['phi', 'SKOs φ (W = diag φ²)'], ['W', 'covariance W']], errorForm, (v) =>
            v === 'W'
              ? this.switchForm('system-errors', s, 'phi', 'W', () => squares(s.phi, L, 'system.phi'))
              : this.switchForm('system-errors', s, 'W', 'phi', () => roots(s.W, L, 'system.W')),
          ),
          errorsGrid,
        ),
        discrete ? this.priorChoice(s) : null,
      ),
      ...this.otherMembers('system'),
    );
  }

  /** A discrete model's `system.prior_at`: at t₀ (absent: the default) or at the first measurement. */
  priorChoice(s) {
    const options = [
      ['t0', 'at t₀, one transition before the first measurement'],
      ['first_measurement', 'at the first measurement'],
    ];
    const known = options.some(([v]) => v === (s.prior_at ?? 't0'));
    // A value the format does not have is shown as it is, for the core's message at it.
    if (!known) options.push([String(s.prior_at), `“${String(s.prior_at)}”`]);
    const choice = this.formChoice('Prior (y₀, η₀)', 'system-prior', options, String(s.prior_at ?? 't0'), (v) => (s.prior_at = v));
    const select = choice.querySelector('select');
    select.dataset.path = 'system.prior_at';
    this.register('system.prior_at', select, choice);
    return el('div', { class: 'stack' }, choice);
  }

  sectionMeasurement({ N, n, M }) {
    const m = this.model.measurement;
    const states = this.model.system.states ?? [];
    const names = m.names ?? [];
    const mcols = Array.from({ length: M }, (_, k) => `Φ${k + 1}`);
    const noiseForm = m.g ? 'g' : 'gamma';
    const errorForm = m.V ? 'V' : 'psi';
    const noiseGrid =
      noiseForm === 'g'
        ? this.grid({ title: 'g (N×M), Γ = C g', path: 'measurement.g', obj: m, key: 'g', rows: N, cols: M, rowLabels: states, colLabels: mcols, rowNames: 'system.states', create: () => resizeMat([], N, M) })
        : this.grid({ title: 'Γ (n×M)', path: 'measurement.gamma', obj: m, key: 'gamma', rows: n, cols: M, rowLabels: names, colLabels: mcols, rowNames: 'measurement.names', create: () => resizeMat([], n, M) });
    const errorsGrid =
      errorForm === 'V'
        ? this.grid({ title: 'V (M×M)', path: 'measurement.V', obj: m, key: 'V', rows: M, cols: M, rowLabels: mcols, colLabels: mcols, create: () => resizeMat([], M, M) })
        : this.grid({ title: 'ψ measurement-error SKOs (M)', path: 'measurement.psi', obj: m, key: 'psi', rows: M, cols: 0, rowLabels: mcols, create: () => zeros(M) });
    return el(
      'fieldset',
      { class: 'section' },
      el('legend', { text: 'Measurements  Z = C y + Γ Φ' }),
      this.undoNote('measurement'),
      el(
        'div',
        { class: 'grids' },
        this.grid({
          title: 'Measurement names',
          path: 'measurement.names',
          obj: m,
          key: 'names',
          rows: n,
          cols: 0,
          text: true,
          create: () => [],
          rowAction: (j) => this.removeButton('n', j, n, names),
        }),
        this.grid({ title: 'C (n×N)', path: 'measurement.c', obj: m, key: 'c', rows: n, cols: N, rowLabels: names, colLabels: states, rowNames: 'measurement.names', colNames: 'system.states', create: () => resizeMat([], n, N) }),
        el(
          'div',
          { class: 'stack' },
          this.formChoice('Noise matrix', 'measurement-noise', [['gamma', 'Γ (n×M)'], ['g', "seed's g (N×M)"]], noiseForm, (v) =>
            v === 'g'
              ? this.switchForm('measurement-noise', m, 'gamma', 'g', () => gFromGamma(m.c, m.gamma, { N, n, M }), m.c)
              : this.switchForm('measurement-noise', m, 'g', 'gamma', () => gammaFromG(m.c, m.g, { N, n, M }), m.c),
          ),
          noiseGrid,
        ),
        el(
          'div',
          { class: 'stack' },
          this.formChoice('Measurement errors given as', 'measurement-errors', [['psi', 'SKOs ψ (V = diag ψ²)'], ['V', 'covariance V']], errorForm, (v) =>
            v === 'V'
              ? this.switchForm('measurement-errors', m, 'psi', 'V', () => squares(m.psi, M, 'measurement.psi'))
              : this.switchForm('measurement-errors', m, 'V', 'psi', () => roots(m.V, M, 'measurement.V')),
          ),
          errorsGrid,
        ),
      ),
      ...this.otherMembers('measurement'),
    );
  }

  sectionCriteria() {
    const m = this.model;
    m.criteria ??= { confidence: 0.95 };
    m.options ??= { trace_points: 1000, steady_state_shortcut: true };
    m.options.steady_state_shortcut ??= true;
    return el(
      'fieldset',
      { class: 'section' },
      el('legend', { text: 'Criteria and options' }),
      el(
        'div',
        { class: 'row' },
        this.field(FIELD_LABELS['criteria.confidence'], 'criteria.confidence', m.criteria, 'confidence', { check: aNumber, optional: true, placeholder: '0.95' }),
        this.field(FIELD_LABELS['options.trace_points'], 'options.trace_points', m.options, 'trace_points', { check: wholeAtLeast(0), optional: true, placeholder: '1000' }),
        this.field(FIELD_LABELS['options.steady_state_shortcut'], 'options.steady_state_shortcut', m.options, 'steady_state_shortcut', { type: 'checkbox' }),
      ),
      ...this.otherMembers('criteria'),
      ...this.otherMembers('options'),
    );
  }

  /** The model's top-level members the editor has no section for (a misspelt `"optoins"`), if any. */
  sectionOther() {
    const fields = this.otherMembers('');
    if (!fields.length) return null;
    return el('fieldset', { class: 'section' }, el('legend', { text: 'Other members' }), ...fields);
  }

  // ------------------------------------------------------------ members without a grid

  /**
   * The members of `part` ('' for the top level) that have no field of their own, each
   * as its JSON text, editable, with a Remove button: `measurement.schedule`,
   * `measurement.pairs` and `criteria.weights` (always shown: empty is absent, the
   * default), `time.auto`, a form not shown beside the one shown (φ beside W), and
   * members the format does not have (a misspelt `"stpes"`). The core's messages at
   * them, and inside them, are shown at them.
   */
  otherMembers(part) {
    const holder = part ? this.model[part] : this.model;
    if (holder === null || typeof holder !== 'object' || Array.isArray(holder)) return [];
    const fields = [];
    for (const [key, about] of Object.entries(OPTIONAL_MEMBERS[part] ?? {})) {
      fields.push(this.memberField(part, holder, key, { ...about, optional: true }));
    }
    const shown = shownMembers(this.model)[part] ?? [];
    for (const key of Object.keys(holder)) {
      if (shown.includes(key) || Object.hasOwn(OPTIONAL_MEMBERS[part] ?? {}, key)) continue;
      const path = part ? `${part}.${key}` : key;
      fields.push(this.memberField(part, holder, key, OTHER_MEMBERS[path] ?? unknownMember(part, key)));
    }
    return fields;
  }

  /**
   * `holder[key]` (the member `part.key`) as its JSON text: the model takes the text
   * when it parses; Remove deletes the member. `optional`: an empty text is the
   * member's absence. `summary(value, model)` says in words what the value does.
   */
  memberField(part, holder, key, { label, help, optional = false, empty, summary }) {
    const path = part ? `${part}.${key}` : key;
    const id = `f-${path.replace(/[^a-zA-Z0-9]/g, '-')}`;
    const area = el('textarea', {
      id,
      'data-path': path,
      spellcheck: 'false',
      autocomplete: 'off',
      placeholder: optional ? empty : undefined,
      'aria-describedby': `${id}-help`,
    });
    area.value = showJson(holder[key]);
    area.rows = Math.min(8, Math.max(1, area.value.split('\n').length));
    const said = summary ? el('p', { class: 'help member-summary', 'data-summary': path }) : null;
    const remove = el('button', {
      type: 'button',
      text: 'Remove',
      'aria-label': `remove ${path}`,
      title: `Remove ${path} from the model`,
      'data-focus': `remove-member:${path}`,
      hidden: holder[key] === undefined,
    });
    const say = () => {
      if (said) said.textContent = holder[key] === undefined ? '' : summary(holder[key], this.model);
      remove.hidden = holder[key] === undefined;
    };
    say();
    area.addEventListener('input', () => {
      let problem = null;
      if (optional && area.value.trim() === '') delete holder[key];
      else {
        try {
          holder[key] = JSON.parse(area.value);
        } catch (e) {
          problem = `not JSON (${e.message}); the model keeps the last JSON this field had`;
        }
      }
      this.setLocal(path, problem);
      say();
      this.changed();
    });
    remove.addEventListener('click', () => {
      this.commitPending();
      delete holder[key];
      this.local.delete(path);
      // The core's marks at it are gone with it; the focus stays at its field (an
      // optional member's, now empty), else moves to the control before it.
      this.core = this.core.filter((e) => !(e.path === path || e.path?.startsWith(`${path}.`) || e.path?.startsWith(`${path}[`)));
      const after = (this.focusNext = optional ? `#${CSS.escape(id)}` : this.controlBefore(area));
      this.render();
      this.changed(`removal of ${placeName(path)}`, { before: `#${CSS.escape(id)}`, after });
    });
    const wrap = el(
      'div',
      { class: 'field wide member' },
      el('label', { for: id, text: label }),
      el('div', { class: 'member-row' }, area, remove),
      el('small', { id: `${id}-help`, class: 'help', text: help }),
      said,
    );
    this.register(path, area, wrap);
    return wrap;
  }

  /** A selector of the focusable control before `control` in the editor (for the focus when it goes). */
  controlBefore(control) {
    const all = [...this.root.querySelectorAll('input, textarea, select, button')].filter((e) => !e.disabled && !e.hidden);
    const at = all.indexOf(control);
    for (let i = at - 1; i >= 0; i--) {
      const selector = focusSelector(all[i]);
      if (selector) return selector;
    }
    return null;
  }

  // ------------------------------------------------------------ validation

  /**
   * Show the core's errors at their cells (kept across redraws until the next call),
   * with this editor's own messages, which replace the core's at the same field; the
   * rest at the top. Returns the count.
   */
  showErrors(errors) {
    this.core = errors ?? [];
    this.mark();
    return this.core.length;
  }

  /**
   * Show the messages at their fields (a message whose path has no field of its own
   * goes to the nearest field above it, else to the list at the top). Only what
   * changed is touched — at N = 200 an edit re-marked every field of a 120 000-cell
   * editor: a message still due stays the same node (and is not announced again), a
   * mark no longer due is removed, a new one added.
   */
  mark() {
    const own = this.localErrors();
    const ownPaths = new Set(own.map((e) => e.path));
    const core = this.core.map((e) => ({ ...e, path: namePath(e) })).filter((e) => !ownPaths.has(e.path));
    const wanted = new Map(); // key → {target, path, text}: the messages due at fields, in order
    const general = [];
    for (const error of [...own, ...core]) {
      let path = error.path ?? '';
      let target = this.fields.get(path);
      while (!target && path) {
        path = parentPath(path);
        target = this.fields.get(path);
      }
      if (!target) {
        general.push(`${modelPlace(error.path)}${error.message}`);
        continue;
      }
      const text = path === error.path ? error.message : `${modelPlace(error.path)}${error.message}`;
      let key = `${path}\n${error.path}\n${text}`;
      for (let k = 2; wanted.has(key); k++) key = `${path}\n${error.path}\n${text}\n${k}`; // the same message twice is shown twice
      wanted.set(key, { target, path: error.path, text });
    }
    for (const [key, shown] of this.marks) {
      if (wanted.get(key)?.target.holder === shown.holder && shown.message.isConnected) continue;
      shown.message.remove();
      this.marks.delete(key);
    }
    const invalid = new Set();
    const added = new Map(); // holder → its messages' keys, where one was added
    for (const [key, { target, path, text }] of wanted) {
      invalid.add(target.input);
      if (!added.has(target.holder)) added.set(target.holder, []);
      added.get(target.holder).push(key);
      if (this.marks.has(key)) continue;
      const message = el('div', { class: 'cell-error', role: 'alert', 'data-error-path': path, text });
      target.holder.append(message);
      this.marks.set(key, { message, holder: target.holder, added: true });
    }
    // A holder's messages in their order (own checks first), as a redraw would show them.
    for (const [holder, keys] of added) {
      const messages = keys.map((key) => this.marks.get(key));
      if (!messages.some((m) => m.added)) continue;
      messages.forEach((m) => (m.added = false));
      const have = [...holder.children].filter((c) => c.classList.contains('cell-error'));
      if (messages.some((m, i) => have[i] !== m.message)) holder.append(...messages.map((m) => m.message));
    }
    for (const input of this.invalid) {
      if (invalid.has(input)) continue;
      input.removeAttribute('aria-invalid');
      input.classList.remove('invalid');
    }
    for (const input of invalid) {
      if (this.invalid.has(input)) continue;
      input.setAttribute('aria-invalid', 'true');
      input.classList.add('invalid');
    }
    this.invalid = invalid;
    if (general.join('\n') !== [...this.general.children].map((li) => li.textContent).join('\n')) {
      this.general.replaceChildren(...general.map((text) => el('li', { text })));
    }
  }
}

/**
 * A model path as the editor names it: `system.phi[0]` → “φ [1]: ” (indices from 1, as
 * the grids number them), `time.t_end` → “t_E: ” (the field's label), `params.2x` →
 * “parameter “2x”: ” and `params.2x.name` → “name of parameter “2x”: ”.
 */
export function modelPlace(path) {
  if (Object.hasOwn(FIELD_LABELS, path ?? '')) return `${FIELD_LABELS[path]}: `;
  const param = paramOf(path ?? '');
  if (param) return `${param.name ? 'name of ' : ''}parameter “${param.param}”: `;
  const names = {
    'system.a': 'a', 'system.transition': 'Φ', 'system.prior_at': 'prior at', 'system.b': 'b', 'system.u': 'u', 'system.y0': 'y₀', 'system.eta0': 'η₀',
    'system.phi': 'φ', 'system.W': 'W', 'measurement.c': 'C', 'measurement.gamma': 'Γ',
    'measurement.g': 'g', 'measurement.psi': 'ψ', 'measurement.V': 'V',
    'system.states': 'state names', 'measurement.names': 'measurement names',
    'measurement.schedule': 'schedule', 'measurement.pairs': 'pairs',
  };
  // A place inside an entry keeps its JSON path after the entry: `schedule [2].every`.
  const m = (path ?? '').match(/^([a-z]+\.[A-Za-z0-9_]+)((\[\d+\])*)((\.[A-Za-z0-9_]+|\[\d+\])*)$/);
  if (!m || !names[m[1]]) return path ? `${path}: ` : '';
  const idx = [...m[2].matchAll(/\[(\d+)\]/g)].map((x) => Number(x[1]) + 1);
  return `${names[m[1]]}${idx.length ? ` [${idx.join(', ')}]` : ''}${m[4]}: `;
}
