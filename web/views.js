// Shared pieces of the Synthesis and Monte Carlo views (web/synthesis.js,
// web/monte_carlo.js): a DOM helper, a runner for a request of one kind — in this
// browser (the wasm worker) or as a server job of the same kind (progress over SSE) —
// the run bar (where, Run, Cancel, progress, status) and the fields kept over a reload.

import { ServerRunner, WasmWorker, WorkGate } from './runner.js';
import { duration, fmt, scrollHint, scrollHintText, when } from './results.js';
import { isDiscrete, modelPlace } from './editor.js';

export { duration, fmt, scrollHint, scrollHintText, when };

export function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k === 'class') e.className = v;
    else if (k === 'text') e.textContent = v;
    else if (k.startsWith('on')) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v === true ? '' : v);
  }
  for (const c of children) if (c !== null && c !== undefined && c !== false) e.append(c);
  return e;
}

/** A labelled control: `<div class=field><label for=id>…</label>control</div>`. */
export function field(label, control, help) {
  const wrap = el('div', { class: 'field' }, el('label', { for: control.id, text: label }), control);
  if (help) {
    control.setAttribute('aria-describedby', `${control.id}-help`);
    wrap.append(el('small', { id: `${control.id}-help`, class: 'help', text: help }));
  }
  return wrap;
}

export function select(id, options, value) {
  const s = el('select', { id });
  for (const [v, text] of options) s.append(el('option', { value: v, text, selected: v === value }));
  return s;
}

export function input(id, value, attrs = {}) {
  return el('input', { id, value: value ?? '', spellcheck: 'false', autocomplete: 'off', ...attrs });
}

/**
 * A server job of one kind (`synthesis`, `monte_carlo`): POST, follow SSE, fetch the
 * result. The running job is kept for this browser tab (`kea-job-KIND`): see RunBar.resume.
 */
class JobRunner extends ServerRunner {
  constructor(kind) {
    super({ keep: `kea-job-${kind}` });
    this.kind = kind;
  }

  run(request, onProgress) {
    return this.runJob(JSON.stringify({ kind: this.kind, ...request }), onProgress);
  }

  /** A problem with the request's own paths (`model.…`, `mode.…`): the view routes them (routeErrors). */
  located(p) {
    return { kind: p.type ?? p.kind ?? 'server', title: p.title, detail: p.detail, status: p.status, errors: p.errors ?? [] };
  }
}

/**
 * The browser's side: the wasm op on a worker of its own (cancel terminates it), after
 * the check of its estimated work (WorkGate: the kind's `KIND_work`).
 */
class WasmRunner {
  constructor(op, kind) {
    this.op = op;
    this.worker = null;
    this.gate = new WorkGate(`${kind}_work`);
  }

  async run(request, onProgress) {
    this.worker ??= new WasmWorker();
    const text = JSON.stringify(request);
    await this.gate.check(this.worker, { request: text }, text);
    return { result: await this.worker.call(this.op, { request: text }, onProgress) };
  }

  cancel() {
    this.worker?.cancel();
  }
}

/**
 * A run's progress as its status line says it: the percentage to 0.01 % below 10 % (a
 * run of hours moves by that), then to 0.1 %; and, from 2 s after the first report on,
 * the time left at the pace so far.
 */
export class ProgressText {
  constructor(label) {
    this.label = label;
    this.first = null;
  }

  text(p) {
    const now = performance.now();
    this.first ??= { p, at: now };
    const [done, spent] = [p - this.first.p, now - this.first.at];
    const shown = p < 0.1 ? (Math.floor(p * 1e4) / 100).toFixed(2) : (Math.floor(p * 1e3) / 10).toFixed(1);
    const left = spent >= 2000 && done > 0 && p < 1 ? ` — about ${roughly((spent / done) * (1 - p))} left` : '';
    return `${this.label} ${shown} %${left}`;
  }
}

/** A time to come, as it is worth saying: 5 s steps below a minute, then minutes, hours and minutes. */
function roughly(ms) {
  const s = ms / 1000;
  if (s < 60) return `${Math.max(5, Math.ceil(s / 5) * 5)} s`;
  const min = Math.ceil(s / 60);
  return min < 60 ? `${min} min` : `${Math.floor(min / 60)} h${min % 60 ? ` ${min % 60} min` : ''}`;
}

/**
 * The “Run anyway” button beside a run bar's status: shown with a run refused for its
 * estimated work in this browser (runner.js, WorkGate); a click allows that request and
 * runs it (`run()`). Hidden again by the next status.
 */
export function runAnyway(button, run) {
  let error = null;
  button.hidden = true;
  button.addEventListener('click', () => {
    error?.allow();
    button.hidden = true;
    run();
  });
  return {
    offer(e) {
      error = e;
      button.hidden = false;
    },
    hide() {
      error = null;
      button.hidden = true;
    },
  };
}

/**
 * The run bar of a view: "Run in" (browser/server), Run, Cancel, progress, status.
 * `onRun(where, exec)` does the work; the bar handles the buttons and the states.
 * `onResume(model, exec)` takes over a server job this browser tab's page started
 * before it was reloaded (`model`: the model it runs), when app.js says `kea:resume`.
 */
export class RunBar {
  constructor({ prefix, label, op, kind, onRun, onResume }) {
    this.prefix = prefix;
    this.runners = { browser: new WasmRunner(op, kind), server: new JobRunner(kind) };
    this.running = null;
    this.onRun = onRun;
    this.onResume = onResume;
    const radio = (value, text, checked) =>
      el('label', {}, el('input', { type: 'radio', name: `${prefix}-where`, value, checked }), ` ${text}`);
    this.serverRadio = radio('server', 'the server (job)', false);
    this.runButton = el('button', { type: 'button', id: `${prefix}-run`, class: 'primary', title: 'Ctrl+Enter', text: label });
    this.cancelButton = el('button', { type: 'button', id: `${prefix}-cancel`, title: 'Esc', text: 'Cancel', disabled: true });
    this.progress = el('progress', { id: `${prefix}-progress`, max: 1, value: 0, 'aria-label': `${label}: progress` });
    this.status = el('span', { id: `${prefix}-status`, class: 'view-status', role: 'status', 'aria-live': 'polite' });
    const anyway = el('button', { type: 'button', id: `${prefix}-run-anyway`, text: 'Run anyway' });
    this.anyway = runAnyway(anyway, () => this.run());
    this.root = el(
      'div',
      { class: 'run-controls' },
      el('fieldset', { class: 'mode' }, el('legend', { text: 'Run in' }), radio('browser', 'this browser (wasm)', true), this.serverRadio),
      this.runButton,
      this.cancelButton,
      this.progress,
      this.status,
      anyway,
    );
    this.runButton.addEventListener('click', () => this.run());
    this.cancelButton.addEventListener('click', () => this.cancel());
    document.addEventListener('kea:resume', () => this.resume(), { once: true });
  }

  where() {
    return this.root.querySelector(`input[name="${this.prefix}-where"]:checked`).value;
  }

  disableServer(reason) {
    const radio = this.serverRadio.querySelector('input');
    radio.disabled = true;
    this.serverRadio.title = reason;
  }

  setStatus(text, error = false) {
    this.status.textContent = text;
    this.status.classList.toggle('error', error);
    this.anyway.hide();
  }

  run() {
    if (this.running) return;
    const where = this.where();
    const runner = this.runners[where];
    return this.follow(where, runner, (onProgress) => this.onRun(where, (request) => runner.run(request, onProgress)));
  }

  /**
   * The server job this browser tab's page started before it was reloaded, if it has
   * not been seen to its end: followed again — progress, Cancel, its result — or, when
   * the server no longer has it, forgotten without a word. Without a server it is
   * forgotten too.
   */
  resume() {
    const runner = this.runners.server;
    const kept = runner.kept();
    if (!kept || this.running) return;
    if (this.serverRadio.querySelector('input').disabled) return runner.store(null);
    return this.follow('server', runner, (onProgress) => this.onResume(kept.model, () => runner.attach(kept.id, onProgress)), kept.id);
  }

  /**
   * The server job `id`, opened from the Server tab (`model`: the model it runs,
   * `body`: what a reload needs to follow it again): followed as a run is.
   */
  open(id, model, body) {
    const runner = this.runners.server;
    runner.store({ id, body });
    return this.follow('server', runner, (onProgress) => this.onResume(model, () => runner.attach(id, onProgress)), id, true);
  }

  /**
   * Show a run (`start(onProgress)` → the job's id, if a server job) in the bar, to its
   * end; `resumed`: the id of a job taken over after a reload, or opened from the
   * Server tab (`opened`).
   */
  async follow(where, runner, start, resumed = null, opened = false) {
    this.running = runner;
    this.runButton.disabled = true;
    this.cancelButton.disabled = false;
    this.progress.value = 0;
    const label = opened ? `Opening server job ${resumed}…` : resumed ? `Following server job ${resumed} (started before the reload)…` : where === 'browser' ? 'Running in this browser…' : 'Running on the server…';
    this.setStatus(label);
    const shown = new ProgressText(label);
    const onProgress = (p) => {
      this.progress.value = p;
      if (this.running === runner) this.setStatus(shown.text(p));
    };
    const started = performance.now();
    try {
      const job = await start(onProgress);
      this.progress.value = 1;
      const ms = performance.now() - started;
      this.setStatus(
        opened ? `Server job ${job}, opened from the Server tab.`
        : resumed ? `Done (server job ${job}, followed after the reload).`
        : `Done in ${duration(ms)} (${where === 'browser' ? 'browser, wasm' : `server job ${job}`}).`,
      );
    } catch (e) {
      this.progress.value = 0;
      if (e?.kind === 'cancelled') this.setStatus('Cancelled.');
      else if (e?.kind === 'gone' && resumed) this.setStatus(opened ? `The server no longer has job ${resumed}.` : '', opened);
      else if (e?.kind === 'too-much-work') {
        this.setStatus(e.title, true);
        this.anyway.offer(e);
      } else this.setStatus(e?.message ?? e?.title ?? String(e), true);
    } finally {
      this.running = null;
      this.runButton.disabled = false;
      this.cancelButton.disabled = true;
    }
  }

  cancel() {
    this.running?.cancel();
  }
}

/**
 * A view's request fields kept over a reload of the page: in sessionStorage under `key`,
 * so for this browser tab only. Not in the URL: a link carries the model and the tab
 * (app.js), what is shared; these are one person's work on it, as the server's token is
 * (api.js), and a link opened elsewhere starts from the defaults. `groups`: controls kept
 * together or not at all (a param and its values). A stored value a control cannot take
 * (not a string, not one of a select's options: a param the model does not have) leaves
 * its group at the defaults; storage that cannot be read or written keeps nothing.
 */
export class KeptFields {
  constructor(key, groups) {
    this.key = key;
    this.groups = groups;
  }

  save() {
    const values = Object.fromEntries(this.groups.flat().map((c) => [c.id, c.value]));
    try {
      sessionStorage.setItem(this.key, JSON.stringify(values));
    } catch {
      // storage off or full: the fields are not kept
    }
  }

  /** Put the stored values back, group by group; returns whether any field changed. */
  restore() {
    let saved = null;
    try {
      saved = JSON.parse(sessionStorage.getItem(this.key));
    } catch {
      return false; // unreadable: the defaults stay
    }
    if (!saved || typeof saved !== 'object' || Array.isArray(saved)) return false;
    const takes = (c, v) => typeof v === 'string' && (c.tagName !== 'SELECT' || [...c.options].some((o) => o.value === v));
    let changed = false;
    for (const group of this.groups) {
      if (!group.every((c) => takes(c, saved[c.id]))) continue;
      for (const c of group) {
        changed ||= c.value !== saved[c.id];
        c.value = saved[c.id];
      }
    }
    return changed;
  }
}

let helper = null;

/**
 * A model as a run reads it: its JSON without the name and the description, which no
 * result depends on. Two models alike in it give the same results (an edit of the
 * description leaves them current).
 */
export function runPart(model) {
  const { name, description, ...rest } = model ?? {};
  return JSON.stringify(rest);
}

/** A quick op of worker.js (check, monte_carlo_csv, …) on a worker of its own. */
export function wasmCall(op, args) {
  helper ??= new WasmWorker();
  return helper.call(op, args);
}

const inModel = (e) => ({ path: e.path ? `model${e.path.startsWith('[') ? '' : '.'}${e.path}` : 'model', message: e.message });

/**
 * The core's validation of a model, with the editor's own (`pending`: fields it could
 * not read), as errors at `model.…` paths: a run of an invalid model is refused here,
 * without a request. `discrete`: checked in the identification's form (Φ,
 * `system.transition`); by default a discrete model is, and the run of another kind
 * says what the core says of it.
 */
export async function checkModel(model, pending = [], { discrete = isDiscrete(model) } = {}) {
  const errors = await wasmCall('check', { model: JSON.stringify(model), set: '', discrete });
  const own = new Set(pending.map((e) => e.path));
  return [...pending, ...errors.filter((e) => !own.has(e.path))].map(inModel);
}

/**
 * What each value a synthesis gives a param does to the model (the model itself being
 * valid): `checks` is [{name, values, path}] (path: the control that set them); returns
 * errors at those paths, as “name = value: <the model's error>”.
 */
export async function checkOverrides(model, checks) {
  const json = JSON.stringify(model);
  const discrete = isDiscrete(model); // in the model's own form, as checkModel: the run says what the core says of it
  const out = [];
  for (const { name, values, path } of checks) {
    for (const value of values.slice(0, 64)) {
      if (!Number.isFinite(value)) continue;
      const errors = await wasmCall('check', { model: json, set: JSON.stringify({ [name]: value }), discrete });
      if (errors.length) {
        const first = errors[0];
        out.push({ path, message: `${name} = ${value} makes the model invalid: ${modelPlace(first.path)}${first.message}` });
        break;
      }
    }
  }
  return out;
}

/**
 * A run's errors at model paths (without the request's `model.`) as a status line says
 * them: the first, its place named as the editor names it, and how many more there are
 * (the editor shows each at its cell).
 */
export function modelErrorsText(errors) {
  const [first, ...rest] = errors;
  if (!first) return '';
  const text = `${modelPlace(first.path)}${first.message}`;
  return rest.length ? `${text} (and ${rest.length} more)` : text;
}

// A model path in the core's text (`model.system.phi[0]: an SKO …`, from a title or a
// message that quotes a model's error), to be named as the editor names it.
const MODEL_PATH = /(?:\bmodel\.)?\b((?:system|measurement)\.[A-Za-z0-9_]+(?:\[\d+\])*): /g;

/** The core's words for the view's: API names become the controls' labels, model paths the editor's places. */
export function uiWords(text) {
  return String(text ?? '')
    .replaceAll('give `cost_order`', 'choose a cost order (the “cost” column)')
    .replaceAll('`cost_order`', 'the cost order')
    .replace(MODEL_PATH, (_, path) => modelPlace(path));
}

/**
 * Split a run's errors: those under `model.` go to the model editor (paths without
 * the prefix), the rest (target, mode, runs, …) stay with the view. Returns both:
 * {own, model}.
 */
export function routeErrors(errors, showModelErrors) {
  const model = [];
  const own = [];
  for (const e of errors ?? []) {
    const path = e.path ?? '';
    if (path === 'model' || path.startsWith('model.') || path.startsWith('model[')) {
      model.push({ path: path.replace(/^model\.?/, ''), message: e.message });
    } else own.push(e);
  }
  showModelErrors(model);
  return { own, model };
}

/**
 * A failed run as an Error whose message names the problem and where to look.
 * `modelErrors`: those the editor shows (the first is said here, at its place as the
 * editor names it); `unplaced`: the view's errors no control shows (said here, with
 * their paths).
 */
export function runError(e, ownErrors, modelErrors, unplaced = []) {
  if (['cancelled', 'gone', 'too-much-work'].includes(e?.kind)) return e;
  const parts = [];
  if (ownErrors.length) {
    parts.push(
      unplaced.length
        ? `Invalid request: ${unplaced.map((x) => uiWords(x.path ? `${x.path}: ${x.message}` : x.message)).join('; ')}`
        : 'Invalid request',
    );
    if (ownErrors.length > unplaced.length) parts.push('see the marked fields of this tab');
  } else if (!modelErrors.length) parts.push(uiWords(e?.title ?? String(e)), e?.detail && e.detail !== e.title ? uiWords(e.detail) : null);
  else parts.push(modelErrorsText(modelErrors));
  if (modelErrors.length) parts.push('see the marked model fields');
  return new Error(parts.filter(Boolean).join(' — '));
}

/** Take a control's mark (and its messages) away. */
function unmark(control) {
  for (const m of control.parentElement?.querySelectorAll(':scope > .control-error') ?? []) m.remove();
  control.removeAttribute('aria-invalid');
  control.classList.remove('invalid');
}

/** Mark a control as invalid, with `error`'s message under it. */
function mark(control, error) {
  control.setAttribute('aria-invalid', 'true');
  control.classList.add('invalid');
  control.parentElement.append(
    el('div', { class: 'cell-error control-error', role: 'alert', 'data-error-path': error.path ?? '', text: uiWords(error.message) }),
  );
}

/**
 * Mark the view's controls named by error paths (data-request-path) as invalid, with
 * the message under the control. Returns the errors no control was found for.
 */
export function markControls(root, errors) {
  for (const c of root.querySelectorAll('[aria-invalid="true"]')) unmark(c);
  for (const m of root.querySelectorAll('.control-error')) m.remove();
  const unplaced = [];
  for (const e of errors) {
    let path = e.path ?? '';
    let control = null;
    while (path && !control) {
      control = root.querySelector(`[data-request-path="${CSS.escape(path)}"]`);
      if (!control) path = path.endsWith(']') ? path.slice(0, path.lastIndexOf('[')) : path.slice(0, Math.max(0, path.lastIndexOf('.')));
    }
    if (!control) {
      unplaced.push(e);
      continue;
    }
    mark(control, e);
  }
  return unplaced;
}

/** The errors `request()` throws for a form's own fields as they read now ([] if none). */
export function requestErrors(request) {
  try {
    request();
    return [];
  } catch (e) {
    return e.errors ?? [];
  }
}

/**
 * Re-check a control as it is edited, as the model editor does: its mark (from the last
 * Run) is replaced by what the view's own check (`local()`: the errors of the fields as
 * they read now) finds at it, or goes. The core's checks come with the next Run.
 */
export function recheckControl(control, local) {
  const errors = local(); // first: it may renumber the paths of the rows
  const path = control.dataset?.requestPath;
  if (!path) return;
  unmark(control);
  for (const e of errors) if (e.path === path) mark(control, e);
}

/**
 * What the Synthesis and Monte Carlo views share: following a run (or a server job
 * taken over after a reload) to its result, and a run's errors at the model's cells and
 * at the tab's controls. A subclass has `form`, `ctx`, `edits` and
 * `show(result, where, current)`.
 */
export class RunView {
  /**
   * A run of the tab's `request()` on the editor's model: the model checked first (its
   * errors at its cells), then the tab's own checks (`checkRequest`), then the run
   * followed.
   */
  async run(where, exec) {
    try {
      const request = this.request();
      markControls(this.form, []);
      const invalid = await checkModel(request.model, this.ctx.pendingModelErrors?.() ?? []);
      if (invalid.length) throw { kind: 'invalid', title: 'Invalid model', errors: invalid };
      await this.checkRequest(request);
      return await this.follow(where, () => exec(request), request.model); // exec serialises the request at once
    } catch (e) {
      throw this.failed(e);
    }
  }

  /** A tab with more to check than the model throws {kind: 'invalid', …} here. */
  async checkRequest(_request) {}

  /** The editor's model changed: a result shown is stale, and a run's error (about the model before) goes. */
  markStale() {
    this.edits++;
    if (!this.out.hidden) this.out.classList.add('stale');
    if (this.bar.status.classList.contains('error')) this.bar.setStatus('');
  }

  /** A server job opened from the Server tab: its request in the fields, then the job followed as a run. */
  openJob(id, request, model, body) {
    this.fill(request);
    return this.bar.open(id, model, body);
  }

  /** A server job taken over after a reload (RunBar.resume); `model`: the model it runs. */
  async resume(model, exec) {
    try {
      return await this.follow('server', exec, model);
    } catch (e) {
      throw this.failed(e);
    }
  }

  /** Wait for a run's result and show it: current if `model` is still the editor's. Returns the job's id. */
  async follow(where, exec, model) {
    const edits = this.edits;
    const { result, job } = await exec();
    const current = this.edits === edits && runPart(model) === runPart(this.ctx.model());
    if (current) this.ctx.showModelErrors([]); // else the check of the edited model has the say
    this.show(result, where, current);
    return job;
  }

  /** A run's error, its parts at the model's cells and at this tab's controls. */
  failed(e) {
    const { own, model } = routeErrors(e?.errors, this.ctx.showModelErrors);
    const unplaced = markControls(this.form, own);
    return runError(e, own, model, unplaced);
  }
}
