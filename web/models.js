// The Server tab's stored models: the models the kea server keeps (POST /v1/models),
// newest first — stored from this page (the toolbar's "Store on server", or here) or by
// a script. Scripts name one by its id (`model_id` in a request); here one is opened
// into the editor, or deleted (jobs run with it keep their own copy). The server checks
// a model before it stores it: a refused one's errors are shown at the editor's fields.

import { api } from './api.js';
import { problemOf, problemText, problemWords } from './runner.js';
import { el, modelErrorsText, when } from './views.js';

const PAGE = 50;

/** A model's name as the lists show it. */
export const modelName = (name) => name ?? '(unnamed model)';

/**
 * `ctx`: {server: whether a kea server answers, model(): the editor's model,
 * showModelErrors(errors), open(record): load a stored model ({id, name, created_at,
 * model}) into the editor (app.js)}.
 */
export class ModelsView {
  constructor(root, ctx) {
    this.root = root;
    this.ctx = ctx;
    this.models = [];
    this.cursor = null;
    this.seq = 0;
    this.build();
  }

  build() {
    const title = el('h3', { id: 'models-title', text: 'Stored models' });
    const help = el('p', {
      class: 'help',
      text: 'Models this kea server keeps, newest first. A script runs one by its id ("model_id" in place of "model" in its request); Open loads one into the editor. Deleting a model leaves the jobs run with it as they are: each keeps its own copy.',
    });
    this.root.setAttribute('aria-labelledby', 'models-title');
    if (!this.ctx.server) {
      this.root.append(title, el('p', { id: 'models-status', class: 'view-status', text: 'No kea server answers here, so no model can be stored (Export JSON keeps one in a file).' }));
      return;
    }
    const store = el('button', { type: 'button', id: 'models-store', text: 'Store the editor’s model', onclick: () => this.store() });
    this.status = el('span', { id: 'models-status', class: 'view-status', role: 'status', 'aria-live': 'polite' });
    this.body = el('tbody');
    this.table = el(
      'table',
      { id: 'models-table', class: 'jobs' },
      el('thead', {}, el('tr', {}, ...['Stored', 'Name', 'Id', ''].map((h) => el('th', { scope: 'col', text: h })))),
      this.body,
    );
    this.more = el('button', { type: 'button', id: 'models-more', text: `Show ${PAGE} more`, hidden: true, onclick: () => this.load(true) });
    this.root.append(title, help, el('div', { class: 'jobs-bar' }, store, this.status), el('div', { class: 'grid-wrap' }, this.table), this.more);
  }

  /** The tab is shown: list the models as they are now. */
  shown() {
    if (this.ctx.server) this.load(false);
  }

  /** The first page (or, with `more`, the next one) of the stored models. */
  async load(more) {
    const seq = ++this.seq;
    const q = new URLSearchParams({ limit: String(PAGE) });
    if (more && this.cursor) q.set('cursor', this.cursor);
    let page;
    try {
      const r = await api(`v1/models?${q}`);
      if (!r.ok) throw new Error(await problemText(r));
      page = await r.json();
    } catch (e) {
      if (seq === this.seq) this.say(`Could not list the server’s models (${e.message ?? e}).`, true);
      return;
    }
    if (seq !== this.seq) return; // a later listing has the say
    this.models = more ? [...this.models, ...page.items] : page.items;
    this.cursor = page.next_cursor;
    this.render();
    this.say(this.models.length ? '' : 'No stored models yet.');
  }

  say(text, error = false) {
    this.status.textContent = text;
    this.status.classList.toggle('error', error);
  }

  render() {
    this.body.replaceChildren(...this.models.map((m) => this.row(m)));
    this.table.hidden = this.models.length === 0;
    this.more.hidden = !this.cursor;
  }

  row(m) {
    const name = modelName(m.name);
    return el(
      'tr',
      { 'data-model': m.id },
      el('td', { text: when(m.created_at), title: m.created_at }),
      el('td', { class: 'job-model', text: name, title: name }),
      el('td', { class: 'model-id' }, el('code', { text: m.id })),
      el(
        'td',
        { class: 'job-actions' },
        el('button', { type: 'button', class: 'model-open', text: 'Open', title: `Load model ${m.id} into the editor`, onclick: () => this.open(m) }),
        el('button', { type: 'button', class: 'model-delete', text: 'Delete', title: 'Delete this model from the server', onclick: () => this.purge(m) }),
      ),
    );
  }

  /**
   * Store the editor's model. Returns what happened in words ({ok, text}); the server's
   * objections are shown at the editor's fields, and the model stored heads the list.
   */
  async store() {
    if (!this.ctx.server) return { ok: false, text: 'No kea server answers here: nothing can be stored.' };
    this.seq++; // a listing under way would drop the row added below
    this.say('Storing…');
    let r;
    try {
      r = await api('v1/models', {
        method: 'POST',
        headers: { 'content-type': 'application/json' },
        body: JSON.stringify(this.ctx.model()),
      });
    } catch (e) {
      return this.told(false, `Could not store the model (${e.message ?? e}).`);
    }
    if (!r.ok) {
      const p = await problemOf(r);
      if (p.errors.length) {
        this.ctx.showModelErrors(p.errors);
        return this.told(false, `The server did not store the model: ${modelErrorsText(p.errors)} (see the marked fields).`);
      }
      return this.told(false, `The server did not store the model (${problemWords(p)}).`);
    }
    const m = await r.json();
    this.models = [m, ...this.models.filter((x) => x.id !== m.id)];
    this.render();
    return this.told(true, `Stored “${modelName(m.name)}” on the server as model ${m.id}.`);
  }

  told(ok, text) {
    this.say(text, !ok);
    return { ok, text };
  }

  async open(m) {
    this.say(`Opening model ${m.id}…`);
    try {
      const r = await api(`v1/models/${m.id}`);
      if (!r.ok) throw new Error(r.status === 404 ? 'the server no longer has it' : await problemText(r));
      await this.ctx.open(await r.json());
      this.say('');
    } catch (e) {
      this.say(`Could not open model ${m.id} (${e.message ?? e}).`, true);
    }
  }

  async purge(m) {
    if (!window.confirm(`Delete the model “${modelName(m.name)}” (stored ${when(m.created_at)}) from the server? Scripts that name its id will no longer find it; jobs run with it keep their copy.`)) return;
    const r = await api(`v1/models/${m.id}`, { method: 'DELETE' }).catch((e) => e);
    if (r instanceof Response && (r.ok || r.status === 404)) {
      this.models = this.models.filter((x) => x.id !== m.id);
      this.render();
      this.say(`Deleted model ${m.id}.`);
    } else {
      this.say(`Could not delete model ${m.id} (${r instanceof Response ? await problemText(r) : r.message ?? r}).`, true);
    }
  }
}
