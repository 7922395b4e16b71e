// The Server tab's jobs: the jobs the kea server keeps (GET /v1/jobs), newest first —
// of every client, the page's own and a script's alike. A job is opened (its model
// into the editor, its request into its tab's fields, its result, error or progress
// into that tab, as if just run), cancelled while it is queued or running, run again
// once finished (its stored request submitted as a new job, which is then opened), or
// deleted with its result (DELETE ?purge=true). Without a server the tab says so.

import { api } from './api.js';
import { ACTIVE, problemText, problemWords } from './runner.js';
import { duration, el, when } from './views.js';
import { modelName } from './models.js';

const PAGE = 50;
/** Each job kind's tab, as the page names it. */
export const KINDS = { analysis: 'Analysis', synthesis: 'Synthesis', monte_carlo: 'Monte Carlo', identification: 'Identification', nonlinear: 'Nonlinear', sensitivity: 'Sensitivity' };
const POLL_MS = 2000;

/**
 * `ctx`: {server: whether a kea server answers, open(job): open the job (app.js), busy(kind):
 * why a job of that kind cannot be opened now, or null}.
 */
export class JobsView {
  constructor(root, ctx) {
    this.root = root;
    this.ctx = ctx;
    this.jobs = [];
    this.cursor = null;
    this.timer = null;
    this.seq = 0;
    this.visible = false; // whether the tab is shown (its active rows are followed then)
    this.build();
  }

  build() {
    const title = el('h3', { id: 'jobs-title', text: 'Jobs' });
    this.root.setAttribute('aria-labelledby', 'jobs-title');
    const about = 'The jobs this kea server keeps, newest first — run from this page or by a script. Open shows a job’s model in the editor, its request in its tab and its result (or its progress, or why it failed).';
    const help = el('p', { class: 'help', text: `${about} A finished job is kept until it is deleted here.` });
    this.help = { p: help, about, asked: false };
    if (!this.ctx.server) {
      this.root.append(title, help, el('p', { id: 'jobs-status', class: 'view-status', text: 'No kea server answers here, so there are no server jobs (a run in this browser is not kept). Open the page through `kea serve` to see its jobs.' }));
      return;
    }
    this.filter = el('select', { id: 'jobs-filter', 'aria-label': 'Jobs of status' });
    for (const [v, text] of [['', 'all'], ['queued', 'queued'], ['running', 'running'], ['succeeded', 'succeeded'], ['failed', 'failed'], ['cancelled', 'cancelled']]) {
      this.filter.append(el('option', { value: v, text }));
    }
    this.filter.addEventListener('change', () => this.refresh());
    const refresh = el('button', { type: 'button', id: 'jobs-refresh', text: 'Refresh', onclick: () => this.refresh() });
    this.status = el('span', { id: 'jobs-status', class: 'view-status', role: 'status', 'aria-live': 'polite' });
    this.body = el('tbody');
    this.table = el(
      'table',
      { id: 'jobs-table', class: 'jobs' },
      el('thead', {}, el('tr', {}, ...['Created', 'Kind', 'Model', 'Status', 'Took', ''].map((h) => el('th', { scope: 'col', text: h })))),
      this.body,
    );
    this.more = el('button', { type: 'button', id: 'jobs-more', text: `Show ${PAGE} more`, hidden: true, onclick: () => this.load(true) });
    this.root.append(
      title,
      help,
      el('div', { class: 'jobs-bar' }, el('label', { for: 'jobs-filter', text: 'Status' }), this.filter, refresh, this.status),
      el('div', { class: 'grid-wrap' }, this.table),
      this.more,
    );
  }

  /**
   * A server that deletes finished jobs itself (`--keep-finished`) is said to in the help
   * (asked once, when the tab is first shown: by then a token the server needs is given).
   */
  async keptFor() {
    const { p: help, about } = this.help;
    this.help.asked = true;
    try {
      const r = await api('v1/limits');
      const keep = r.ok ? (await r.json())?.server?.keep_finished_s : null;
      if (typeof keep === 'number') {
        help.textContent = `${about} This server deletes a finished job ${duration(keep * 1000)} after it finished (its --keep-finished), or here before that.`;
      }
    } catch {
      // the help as it is
    }
  }

  /** The tab is shown: list the jobs as they are now, and keep following those that run. */
  shown() {
    this.visible = true;
    if (!this.ctx.server) return;
    if (!this.help.asked) this.keptFor();
    this.refresh();
  }

  /** The tab is left: its rows stop following their jobs. */
  leave() {
    this.visible = false;
    clearTimeout(this.timer);
  }

  refresh() {
    return this.load(false);
  }

  /** The first page (or, with `more`, the next one) of the jobs of the status chosen. */
  async load(more) {
    const seq = ++this.seq;
    clearTimeout(this.timer);
    const q = new URLSearchParams({ limit: String(PAGE) });
    if (this.filter.value) q.set('status', this.filter.value);
    if (more && this.cursor) q.set('cursor', this.cursor);
    let page;
    try {
      const r = await api(`v1/jobs?${q}`);
      if (!r.ok) throw new Error(await problemText(r));
      page = await r.json();
    } catch (e) {
      if (seq === this.seq) this.say(`Could not list the server’s jobs (${e.message ?? e}).`, true);
      return;
    }
    if (seq !== this.seq) return; // a later listing has the say
    this.jobs = more ? [...this.jobs, ...page.items] : page.items;
    this.cursor = page.next_cursor;
    this.render();
    this.say(this.jobs.length ? '' : this.filter.value ? `No ${this.filter.value} jobs.` : 'No jobs yet: run one on the server (Run in: the server).');
    // While a job shown is queued or running, its row follows it.
    if (this.jobs.some((j) => ACTIVE.includes(j.status)) && this.visible) {
      this.timer = setTimeout(() => this.follow(), POLL_MS);
    }
  }

  /** The rows of jobs that were queued or running, read again (each on its own). */
  async follow() {
    const seq = this.seq;
    const active = this.jobs.filter((j) => ACTIVE.includes(j.status));
    const fresh = await Promise.all(
      active.map((j) =>
        api(`v1/jobs/${j.id}`)
          .then((r) => (r.ok ? r.json() : r.status === 404 ? null : j))
          .catch(() => j),
      ),
    );
    if (seq !== this.seq || !this.visible) return;
    const byId = new Map(active.map((j, i) => [j.id, fresh[i]]));
    this.jobs = this.jobs.flatMap((j) => (byId.has(j.id) ? (byId.get(j.id) ? [byId.get(j.id)] : []) : [j]));
    this.render();
    if (this.jobs.some((j) => ACTIVE.includes(j.status))) this.timer = setTimeout(() => this.follow(), POLL_MS);
  }

  say(text, error = false) {
    this.status.textContent = text;
    this.status.classList.toggle('error', error);
  }

  render() {
    this.body.replaceChildren(...this.jobs.map((j) => this.row(j)));
    this.table.hidden = this.jobs.length === 0;
    this.more.hidden = !this.cursor;
  }

  row(job) {
    const took =
      job.started_at && job.finished_at ? duration(new Date(job.finished_at) - new Date(job.started_at)) : '';
    const status =
      job.status === 'running' ? `running ${(100 * job.progress).toFixed(job.progress < 0.1 ? 2 : 1)} %`
      : job.status === 'queued' && job.cancel_requested ? 'queued (cancel asked)'
      : job.status;
    const statusCell = el('td', { class: `job-status ${job.status}`, text: status });
    if (job.error) statusCell.title = problemWords(job.error);
    const name = modelName(job.model_name);
    const open = el('button', { type: 'button', class: 'job-open', text: 'Open', title: `Open job ${job.id}: its model, its request and its result`, onclick: () => this.open(job) });
    const actions = [open];
    if (ACTIVE.includes(job.status)) {
      actions.push(el('button', { type: 'button', class: 'job-cancel', text: 'Cancel', disabled: job.cancel_requested, onclick: () => this.cancel(job) }));
    } else {
      actions.push(el('button', { type: 'button', class: 'job-again', text: 'Run again', title: 'Submit this job’s request again, as a new job, and open it', onclick: () => this.again(job) }));
      actions.push(el('button', { type: 'button', class: 'job-delete', text: 'Delete', title: 'Delete this job and its result from the server', onclick: () => this.purge(job) }));
    }
    return el(
      'tr',
      { 'data-job': job.id },
      el('td', { text: when(job.created_at), title: job.created_at }),
      el('td', { text: KINDS[job.kind] ?? job.kind }),
      el('td', { class: 'job-model', text: name, title: `${name} — job ${job.id}` }),
      statusCell,
      el('td', { text: took }),
      el('td', { class: 'job-actions' }, ...actions),
    );
  }

  async open(job) {
    const busy = this.ctx.busy(job.kind);
    if (busy) return this.say(busy, true);
    this.say(`Opening job ${job.id}…`);
    try {
      await this.ctx.open(job);
      this.say('');
    } catch (e) {
      this.say(`Could not open job ${job.id} (${e.message ?? e}).`, true);
    }
  }

  /** Submit a finished job's stored request again, as a new job, and open that one. */
  async again(job) {
    const busy = this.ctx.busy(job.kind);
    if (busy) return this.say(busy, true);
    this.say(`Submitting job ${job.id} again…`);
    let fresh;
    try {
      const r = await api(`v1/jobs/${job.id}/request`);
      if (!r.ok) throw new Error(r.status === 404 ? 'the server no longer has it' : await problemText(r));
      const submitted = await api('v1/jobs', { method: 'POST', headers: { 'content-type': 'application/json' }, body: await r.text() });
      if (!submitted.ok) throw new Error(await problemText(submitted));
      fresh = await submitted.json();
    } catch (e) {
      return this.say(`Could not run job ${job.id} again (${e.message ?? e}).`, true);
    }
    this.jobs = [fresh, ...this.jobs];
    this.render();
    await this.open(fresh);
  }

  async cancel(job) {
    const r = await api(`v1/jobs/${job.id}`, { method: 'DELETE' }).catch((e) => e);
    if (!(r instanceof Response) || (!r.ok && r.status !== 409)) {
      this.say(`Could not cancel job ${job.id} (${r instanceof Response ? await problemText(r) : r.message ?? r}).`, true);
    }
    return this.refresh();
  }

  async purge(job) {
    const what = `${KINDS[job.kind] ?? job.kind} of “${modelName(job.model_name)}”, ${when(job.created_at)}`;
    if (!window.confirm(`Delete this job (${what}) and its result from the server? This cannot be undone.`)) return;
    const r = await api(`v1/jobs/${job.id}?purge=true`, { method: 'DELETE' }).catch((e) => e);
    if (r instanceof Response && (r.ok || r.status === 404)) {
      this.jobs = this.jobs.filter((j) => j.id !== job.id);
      this.render();
      this.say(`Deleted job ${job.id}.`);
    } else {
      this.say(`Could not delete job ${job.id} (${r instanceof Response ? await problemText(r) : r.message ?? r}).`, true);
    }
  }
}
