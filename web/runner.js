// Where an analysis runs: in this browser (the wasm worker) or on the kea server
// (a job with progress over SSE). Both give the same result JSON, or throw
// {kind, title, errors:[{path, message}]} with paths relative to the model.

import { TOKEN_KEY, api, events } from './api.js';
import { duration } from './results.js';

/** A worker speaking worker.js's protocol: call(op, args, onProgress) → Promise. */
export class WasmWorker {
  constructor() {
    this.next = 1;
    this.pending = new Map();
    this.start();
  }

  start() {
    this.worker = new Worker(new URL('./worker.js', import.meta.url), { type: 'module' });
    this.worker.onmessage = (event) => {
      const { id, progress, ok, error } = event.data;
      const p = this.pending.get(id);
      if (!p) return;
      if (progress !== undefined) {
        p.onProgress?.(progress);
        return;
      }
      this.pending.delete(id);
      if (error) p.reject(error);
      else p.resolve(ok);
    };
    this.worker.onerror = (event) => {
      event.preventDefault();
      const error = { kind: 'internal', title: `worker failed: ${event.message}`, errors: [] };
      for (const p of this.pending.values()) p.reject(error);
      this.pending.clear();
    };
  }

  call(op, args = {}, onProgress) {
    const id = this.next++;
    return new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject, onProgress });
      this.worker.postMessage({ id, op, ...args });
    });
  }

  /** Stop whatever runs now: every pending call rejects as cancelled. */
  cancel() {
    this.worker.terminate();
    const error = { kind: 'cancelled', title: 'cancelled', errors: [] };
    for (const p of this.pending.values()) p.reject(error);
    this.pending.clear();
    this.start();
  }
}

/**
 * This server's `--max-work` (GET v1/limits, relative: the page may be served under a
 * path), asked once it answers; null where it does not (no server, or one with a token
 * not given yet: no token prompt for a run in this browser), and the core's default is
 * used then. Where nothing answers (a static host: 404, or no answer at all) it is not
 * asked again: each question would cost a run a round trip and the console an error.
 */
let serverMaxWork = null;
let noServer = false;
async function serverWorkLimit() {
  if (serverMaxWork !== null || noServer) return serverMaxWork;
  try {
    const token = sessionStorage.getItem(TOKEN_KEY);
    const response = await fetch('v1/limits', token ? { headers: { authorization: `Bearer ${token}` } } : {});
    noServer = response.status === 404;
    const limit = response.ok ? (await response.json())?.server?.max_work : null;
    if (typeof limit === 'number') serverMaxWork = limit;
  } catch {
    noServer = true; // no server: the default
  }
  return serverMaxWork;
}

/**
 * The check before a run in this browser: the run's estimated work (the wasm module's
 * `*_work`, the server's estimate) against the limit this kea server holds a run to
 * (`kea serve --max-work`, or its default where no server says), which the browser has
 * no reason to exceed unasked.
 * Above it the run is refused with {kind: 'too-much-work', title (the estimate and what
 * it means), work, allow()}: `allow()` lets the same request through on the next try
 * (“Run anyway”); a request changed since asks again.
 */
export class WorkGate {
  constructor(op) {
    this.op = op; // analysis_work, synthesis_work or monte_carlo_work
    this.allowed = null;
  }

  /** Throw if `args` (the worker op's, `key` their text) is above the limit and not allowed. */
  async check(worker, args, key) {
    if (this.allowed === key) return;
    let work;
    try {
      work = await worker.call(this.op, args);
    } catch (e) {
      if (e?.kind === 'cancelled') throw e;
      return; // an invalid request: the run itself says what is wrong, at its fields
    }
    const served = await serverWorkLimit();
    const limit = served ?? work.limit;
    if (!(work.units > limit)) return;
    const sci = (x) => x.toExponential(3).replace('e+', 'e'); // as the server writes it: 4.160e12
    throw {
      kind: 'too-much-work',
      title:
        `This run's estimated work is ${sci(work.units)} (${work.explain}), above ${sci(limit)}, ` +
        `where ${served === null ? 'a kea server refuses a run by default' : 'this kea server refuses a run'} (--max-work). A unit is about a nanosecond of one core: ` +
        `this may take ${duration(work.units / 1e6)} or more in this browser. Make it smaller, or run it anyway.`,
      work,
      errors: [],
      allow: () => (this.allowed = key),
    };
  }
}

/**
 * Runs in the browser: analyze on its own worker, so cancel can terminate it. Both
 * runners' `run(modelJson, onProgress, options)` add `options` ({budget, truth}) to
 * the request.
 */
export class BrowserRunner {
  constructor() {
    this.worker = null;
    this.gate = new WorkGate('analysis_work');
  }

  async run(modelJson, onProgress, options = {}) {
    this.worker ??= new WasmWorker();
    const args = { model: modelJson, set: '', options: JSON.stringify(options) };
    await this.gate.check(this.worker, args, `${args.options}${modelJson}`);
    const result = await this.worker.call('analyze', args, onProgress);
    return { result };
  }

  cancel() {
    this.worker?.cancel();
  }
}

/** Strip the server's `model.` prefix so paths match the editor's. */
function modelPaths(problem) {
  const errors = (problem.errors ?? []).map((e) => ({
    path: (e.path ?? '').replace(/^model(\.|$)/, ''),
    message: e.message,
  }));
  return {
    kind: problem.kind ?? problem.type ?? 'server',
    title: problem.title ?? problem.detail ?? 'the server refused the request',
    detail: problem.detail,
    status: problem.status,
    errors,
  };
}

/** A job's statuses before its end. */
export const ACTIVE = ['queued', 'running'];

/** A refused request's problem+json body (or its status when it has none). */
export async function problemOf(response) {
  let body = {};
  try {
    body = await response.json();
  } catch {
    // not JSON: keep the status line
  }
  return {
    type: body.type,
    title: body.title ?? `${response.status} ${response.statusText}`,
    detail: body.detail,
    status: response.status,
    errors: body.errors ?? [],
  };
}

/** A problem ({title, detail}) in words: its title and detail. */
export function problemWords(p) {
  return [p.title, p.detail].filter(Boolean).join(': ');
}

/** A refused request's problem, in words. */
export async function problemText(response) {
  return problemWords(await problemOf(response));
}

const CANCELLED = { kind: 'cancelled', title: 'cancelled', errors: [] };

/**
 * A request to the kea server (api()); a request that gets no answer at all (the server
 * stopped, the network down: fetch's bare “Failed to fetch”) throws {kind:
 * 'unreachable'} saying so and what to do instead.
 */
async function ask(path, init) {
  try {
    return await api(path, init);
  } catch (e) {
    if (e?.name === 'AbortError') throw e;
    throw {
      kind: 'unreachable',
      title: `The kea server does not answer (${e?.message ?? e}); run in this browser, or try again.`,
      errors: [],
    };
  }
}

// Set while the page is being left (a reload, a close): the requests it cuts short
// fail, but the job runs on, so its id stays kept for the next page to re-attach to.
let leaving = false;
addEventListener('pagehide', () => (leaving = true));
addEventListener('pageshow', () => (leaving = false));

/**
 * Runs on the server: POST a job, follow its events, fetch the result. With `keep` (a
 * sessionStorage key) the running job's id is kept for this browser tab, with its
 * request: a page reloaded during the run re-attaches to it (`kept()`, `attach()`) to
 * follow, cancel or show it, instead of leaving it to run on unseen.
 */
export class ServerRunner {
  constructor({ base = '', keep = null } = {}) {
    this.base = base;
    this.keep = keep;
    this.job = null;
    this.cancelRequested = false;
  }

  run(modelJson, onProgress, options = {}) {
    const also = Object.entries(options).map(([k, v]) => `,${JSON.stringify(k)}:${JSON.stringify(v)}`).join('');
    return this.runJob(`{"kind":"analysis","model":${modelJson}${also}}`, onProgress);
  }

  /** A refused request's or a failed job's problem, as the page reports it. */
  located(problem) {
    return modelPaths(problem);
  }

  /**
   * POST the job `body`, follow it, fetch its result: {result, job}. Errors are thrown
   * as `located(problem)`. A cancel that comes before the server has answered the POST
   * is remembered, and the job deleted as soon as its id is known.
   */
  async runJob(body, onProgress) {
    this.cancelRequested = false;
    try {
      const response = await ask(`${this.base}/v1/jobs`, {
        method: 'POST',
        headers: { 'content-type': 'application/json' },
        body,
      });
      if (!response.ok) throw this.located(await problemOf(response));
      const job = await response.json();
      this.store({ id: job.id, body });
      return await this.attach(job.id, onProgress);
    } finally {
      this.cancelRequested = false;
    }
  }

  /**
   * Follow the job `id` to its end and fetch its result: {result, job}; `cancel()`
   * deletes it meanwhile. A job the server does not have (any more) throws {kind: 'gone'}.
   * The kept id is forgotten once the job is over for this page, unless the page is
   * being left.
   */
  async attach(id, onProgress) {
    this.job = id;
    try {
      if (this.cancelRequested) await this.deleteJob(id);
      const final = await this.follow(id, onProgress).catch((e) => {
        throw e?.status === 404 ? { kind: 'gone', title: `the server has no job ${id}`, status: 404, errors: [] } : e;
      });
      if (final.status === 'cancelled') throw CANCELLED;
      if (final.status !== 'succeeded') {
        throw this.located({ title: final.error?.title ?? `job ${final.status}`, ...(final.error ?? {}) });
      }
      const result = await ask(`${this.base}/v1/jobs/${id}/result`);
      if (!result.ok) throw this.located(await problemOf(result));
      return { result: await result.json(), job: id };
    } finally {
      this.job = null;
      if (!leaving) this.store(null);
    }
  }

  /** The job kept by a page before a reload: {id, model} (the model it runs), or null. */
  kept() {
    if (!this.keep) return null;
    try {
      const { id, body } = JSON.parse(sessionStorage.getItem(this.keep) ?? 'null') ?? {};
      return typeof id === 'string' ? { id, model: JSON.parse(body).model ?? null } : null;
    } catch {
      return null; // unreadable: nothing to re-attach to
    }
  }

  /** Keep `job` ({id, body}) for this browser tab, or forget it (null). */
  store(job) {
    if (!this.keep) return;
    try {
      if (job) sessionStorage.setItem(this.keep, JSON.stringify(job));
      else sessionStorage.removeItem(this.keep);
    } catch {
      // storage off or full: a reload cannot re-attach to this job
    }
  }

  /**
   * Follow the job's SSE stream to its final status; resolves to the job object. A
   * stream that ends while the job still runs (a proxy's timeout, a network blip) is
   * followed again.
   */
  async follow(id, onProgress) {
    for (;;) {
      const stop = new AbortController();
      try {
        for await (const { data } of events(`${this.base}/v1/jobs/${id}/events`, stop.signal)) {
          let event = {};
          try {
            event = JSON.parse(data);
          } catch {
            continue;
          }
          if (typeof event.progress === 'number') onProgress?.(event.progress);
          const status = event.status ?? event.state;
          if (status && !ACTIVE.includes(status)) break;
        }
      } catch {
        // The stream failed or was refused: the job itself says where it is.
      } finally {
        stop.abort();
      }
      const r = await ask(`${this.base}/v1/jobs/${id}`);
      if (!r.ok) throw await problemOf(r);
      const job = await r.json();
      if (!ACTIVE.includes(job.status)) return job;
      await new Promise((resolve) => setTimeout(resolve, 1000));
    }
  }

  /** Cancel the job: now, or as soon as the server has said its id. */
  async cancel() {
    this.cancelRequested = true;
    if (this.job) await this.deleteJob(this.job);
  }

  deleteJob(id) {
    return api(`${this.base}/v1/jobs/${id}`, { method: 'DELETE' }).catch(() => {});
  }
}
