// Shared pieces of the Synthesis and Monte Carlo views (web/synthesis.js,
// web/simulation.js): a DOM helper, a runner for a request of one kind — in this
// browser (the wasm worker) or as a server job of the same kind (progress over SSE) —
// and the run bar (where, Run, Cancel, progress, status).

import { api } from './api.js';
import { ServerRunner, WasmWorker } from './runner.js';
import { fmt } from './results.js';

export { fmt };

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

/** A number typed by a person: the value, or NaN (never silently 0). */
export function num(text) {
  const s = String(text).trim();
  return s === '' ? NaN : Number(s);
}

async function problemOf(response) {
  let body = {};
  try {
    body = await response.json();
  } catch {
    // not JSON: keep the status line
  }
  return {
    kind: body.type ?? 'server',
    title: body.title ?? `${response.status} ${response.statusText}`,
    detail: body.detail,
    status: response.status,
    errors: body.errors ?? [],
  };
}

/** A server job of one kind (`synthesis`, `simulation`): POST, follow SSE, fetch the result. */
class JobRunner extends ServerRunner {
  constructor(kind) {
    super();
    this.kind = kind;
  }

  async run(request, onProgress) {
    const response = await api(`${this.base}/v1/jobs`, {
      method: 'POST',
      headers: { 'content-type': 'application/json' },
      body: JSON.stringify({ kind: this.kind, ...request }),
    });
    if (!response.ok) throw await problemOf(response);
    const job = await response.json();
    this.job = job.id;
    const final = await this.follow(job.id, onProgress);
    this.job = null;
    if (final.status === 'cancelled') throw { kind: 'cancelled', title: 'cancelled', errors: [] };
    if (final.status !== 'succeeded') {
      const e = final.error ?? {};
      throw { kind: e.type ?? 'server', title: e.title ?? `job ${final.status}`, detail: e.detail, errors: e.errors ?? [] };
    }
    const result = await api(`${this.base}/v1/jobs/${job.id}/result`);
    if (!result.ok) throw await problemOf(result);
    return { result: await result.json(), job: job.id };
  }
}

/** The browser's side: the wasm op on a worker of its own (cancel terminates it). */
class WasmRunner {
  constructor(op) {
    this.op = op;
    this.worker = null;
  }

  async run(request, onProgress) {
    this.worker ??= new WasmWorker();
    return { result: await this.worker.call(this.op, { request: JSON.stringify(request) }, onProgress) };
  }

  cancel() {
    this.worker?.cancel();
  }
}

/**
 * The run bar of a view: "Run in" (browser/server), Run, Cancel, progress, status.
 * `onRun(where, runner)` does the work; the bar handles the buttons and the states.
 */
export class RunBar {
  constructor({ prefix, label, op, kind, onRun }) {
    this.prefix = prefix;
    this.runners = { browser: new WasmRunner(op), server: new JobRunner(kind) };
    this.running = null;
    this.onRun = onRun;
    const radio = (value, text, checked) =>
      el('label', {}, el('input', { type: 'radio', name: `${prefix}-where`, value, checked }), ` ${text}`);
    this.serverRadio = radio('server', 'the server (job)', false);
    this.runButton = el('button', { type: 'button', id: `${prefix}-run`, class: 'primary', title: 'Ctrl+Enter', text: label });
    this.cancelButton = el('button', { type: 'button', id: `${prefix}-cancel`, title: 'Esc', text: 'Cancel', disabled: true });
    this.progress = el('progress', { id: `${prefix}-progress`, max: 1, value: 0, 'aria-label': `${label}: progress` });
    this.status = el('span', { id: `${prefix}-status`, class: 'view-status', role: 'status', 'aria-live': 'polite' });
    this.root = el(
      'div',
      { class: 'run-controls' },
      el('fieldset', { class: 'mode' }, el('legend', { text: 'Run in' }), radio('browser', 'this browser (wasm)', true), this.serverRadio),
      this.runButton,
      this.cancelButton,
      this.progress,
      this.status,
    );
    this.runButton.addEventListener('click', () => this.run());
    this.cancelButton.addEventListener('click', () => this.cancel());
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
  }

  async run() {
    if (this.running) return;
    const where = this.where();
    const runner = this.runners[where];
    this.running = runner;
    this.runButton.disabled = true;
    this.cancelButton.disabled = false;
    this.progress.value = 0;
    const label = where === 'browser' ? 'Running in this browser…' : 'Running on the server…';
    this.setStatus(label);
    const onProgress = (p) => {
      this.progress.value = p;
      if (this.running === runner) this.setStatus(`${label} ${Math.floor(p * 100)} %`);
    };
    const started = performance.now();
    try {
      const job = await this.onRun(where, (request) => runner.run(request, onProgress));
      this.progress.value = 1;
      const s = (performance.now() - started) / 1000;
      this.setStatus(`Done in ${fmt(s)} s (${where === 'browser' ? 'browser, wasm' : `server job ${job}`}).`);
    } catch (e) {
      this.progress.value = 0;
      if (e?.kind === 'cancelled') this.setStatus('Cancelled.');
      else this.setStatus(e?.message ?? e?.title ?? String(e), true);
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

let helper = null;

/** A quick op of worker.js (check, simulation_csv, …) on a worker of its own. */
export function wasmCall(op, args) {
  helper ??= new WasmWorker();
  return helper.call(op, args);
}

/**
 * The core's validation of a model, as errors at `model.…` paths: a server run of an
 * invalid model is refused here, without a request.
 */
export async function checkModel(model) {
  const errors = await wasmCall('check', { model: JSON.stringify(model), set: '' });
  return errors.map((e) => ({ path: e.path ? `model${e.path.startsWith('[') ? '' : '.'}${e.path}` : 'model', message: e.message }));
}

/**
 * Split a run's errors: those under `model.` go to the model editor (paths without
 * the prefix), the rest (target, mode, runs, …) stay with the view. Returns the view's.
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
  return own;
}

/** A failed run as an Error whose message names the problem (and where to look). */
export function runError(e, ownErrors, modelCount) {
  if (e?.kind === 'cancelled') return e;
  const parts = [];
  if (ownErrors.length) parts.push(`Invalid request: ${ownErrors.map((x) => (x.path ? `${x.path}: ${x.message}` : x.message)).join('; ')}`);
  else if (!modelCount) parts.push(e?.title ?? String(e), e?.detail && e.detail !== e.title ? e.detail : null);
  else parts.push(e?.title && !e.title.includes(': ') ? e.title : 'Invalid model');
  if (modelCount) parts.push('see the marked model fields');
  return new Error(parts.filter(Boolean).join(' — '));
}

/** Mark the view's controls named by error paths (data-request-path) as invalid. */
export function markControls(root, errors) {
  for (const c of root.querySelectorAll('[aria-invalid="true"]')) {
    c.removeAttribute('aria-invalid');
    c.classList.remove('invalid');
  }
  for (const e of errors) {
    let path = e.path ?? '';
    while (path) {
      const c = root.querySelector(`[data-request-path="${CSS.escape(path)}"]`);
      if (c) {
        c.setAttribute('aria-invalid', 'true');
        c.classList.add('invalid');
        break;
      }
      path = path.endsWith(']') ? path.slice(0, path.lastIndexOf('[')) : path.slice(0, Math.max(0, path.lastIndexOf('.')));
    }
  }
}
