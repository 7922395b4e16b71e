// The Identification tab's data (web/identification.js), and the Nonlinear tab's
// (web/nonlinear_data.js): the measurements as CSV text — a file read in this browser
// (FileReader) or text pasted —, sent as the request's `data.csv_text`. Under the box,
// what it holds: its rows and columns, and the core's reading of it against the model
// (the wasm module's work estimate reads the request as a run would: a cell that is not
// a number, a t off the model's grid, a column the model does not measure are said
// there, naming the line, row and column).

import { el, wasmCall } from './views.js';

const PROBE_MS = 400;
const HELP = 'A header row, t first, then one column per measurement name (any order); one row per measured step, t on the model’s grid t₀ + kΔt, k = 1…D. An empty cell is a missing measurement.';

/** The rows and columns of CSV `text` as a person counts them: the header's names, the data rows (blank lines skipped). */
export function csvShape(text) {
  const lines = text.replace(/^\uFEFF/, '').split(/\r\n|\n|\r/);
  const first = lines.findIndex((l) => l.trim() !== '');
  if (first < 0) return null;
  const header = lines[first].split(',').map((h) => h.trim().replace(/^"(.*)"$/, '$1'));
  let rows = 0;
  for (let i = first + 1; i < lines.length; i++) if (lines[i].trim() !== '') rows++;
  return { header, rows };
}

/** Inline rows ([[t, z1, …], …], null: missing) as the CSV text the box shows, with the model's measurement names. */
export function rowsToCsv(rows, names) {
  const cell = (v) => (v === null || v === undefined ? '' : String(v));
  return [['t', ...names].join(','), ...(Array.isArray(rows) ? rows : []).map((r) => (Array.isArray(r) ? r.map(cell).join(',') : ''))].join('\n') + '\n';
}

export class DataBox {
  /**
   * `probe()`: the request to read the data with (the editor's model, the box's data, a
   * param to estimate), or null when there is none to read them against; `onChange()`:
   * the text changed. The Identification tab's box by default; another tab's gives
   * `prefix` (of the ids), `kind` (the request's, whose work estimate reads the data),
   * `path` (the text's request path), `placeholder` and `help`.
   */
  constructor({ probe, onChange, prefix = 'id', kind = 'identification', path = 'data', placeholder = 't,z1\n1,0.13\n2,-1.03\n…', help = HELP }) {
    this.probe = probe;
    this.onChange = onChange;
    this.prefix = prefix;
    this.kind = kind;
    this.help = help;
    this.seq = 0;
    this.timer = null;
    this.file = el('input', { type: 'file', id: `${prefix}-data-file`, accept: '.csv,text/csv,text/plain', 'aria-label': 'Upload a CSV file of measurements' });
    this.text = el('textarea', {
      id: `${prefix}-data`,
      rows: 8,
      spellcheck: 'false',
      autocomplete: 'off',
      'data-request-path': path,
      placeholder,
      'aria-describedby': `${prefix}-data-help ${prefix}-data-summary`,
    });
    this.summary = el('p', { id: `${prefix}-data-summary`, class: 'view-status', role: 'status', 'aria-live': 'polite' });
    this.file.addEventListener('change', () => this.read(this.file.files[0]));
    this.text.addEventListener('input', () => this.changed());
    this.note = ''; // where the text came from (a file's name), said before its shape
  }

  /** The box's controls: the file's picker (with `extra` beside it), the text, the summary. */
  root(extra) {
    const p = this.prefix;
    return el(
      'div',
      { class: 'field wide id-data' },
      el('div', { class: 'row' }, el('label', { for: `${p}-data-file`, text: 'CSV file' }), this.file, extra),
      el('label', { for: `${p}-data`, text: 'Measurements (CSV text: the file’s, or pasted)' }),
      el('div', { class: 'id-data-text' }, this.text), // a run's messages at the data come under it
      el('small', { id: `${p}-data-help`, class: 'help', text: this.help }),
      this.summary,
    );
  }

  value() {
    return this.text.value;
  }

  /** Put `text` in the box (a file, an example, a job opened: `from` names it), as if typed. */
  set(text, from = '') {
    this.text.value = text;
    this.changed(from);
  }

  /** A file chosen: its text in the box (FileReader), or why it could not be read. */
  read(file) {
    if (!file) return;
    const reader = new FileReader();
    reader.onload = () => {
      this.file.value = '';
      this.set(String(reader.result), file.name);
    };
    reader.onerror = () => {
      this.file.value = '';
      this.say(`${file.name} could not be read (${reader.error?.message ?? 'an error'}); the data are unchanged.`, true);
    };
    reader.readAsText(file);
  }

  changed(from = '') {
    this.note = from;
    this.onChange?.();
    this.check();
  }

  say(text, error = false) {
    this.summary.textContent = text;
    this.summary.classList.toggle('error', error);
  }

  /**
   * Say what the box holds (at once), then what the core reads in it (PROBE_MS after the
   * last change: the model's or the text's).
   */
  check() {
    clearTimeout(this.timer);
    const seq = ++this.seq;
    const text = this.text.value;
    const shape = text.trim() === '' ? null : csvShape(text);
    if (!shape) {
      this.say('No data yet: upload a CSV file or paste its text.');
      return;
    }
    const found = `${this.note ? `${this.note}: ` : ''}${shape.rows.toLocaleString('en')} data row${shape.rows === 1 ? '' : 's'} × ${shape.header.length} column${shape.header.length === 1 ? '' : 's'} (${shape.header.join(', ')})`;
    this.say(found);
    this.timer = setTimeout(() => this.probeCore(seq, found), PROBE_MS);
  }

  async probeCore(seq, found) {
    // Not while the tab is hidden (each edit of the model would send the data again): the
    // tab shown checks them (its view's shown()).
    if (this.text.offsetParent === null) return;
    const request = this.probe();
    if (!request) return;
    let problems = [];
    try {
      await wasmCall(`${this.kind}_work`, { request: JSON.stringify(request) });
    } catch (e) {
      problems = (e?.errors ?? []).filter((x) => x.path === 'data' || x.path?.startsWith('data.') || x.path?.startsWith('data['));
      if (!problems.length) return; // not the data's: the run says what is wrong, at its fields
    }
    if (seq !== this.seq) return; // the text or the model changed since
    if (!problems.length) return this.say(`${found} — read on the model’s grid.`);
    const [first, ...rest] = problems;
    this.say(`${found}. The core’s reading: ${first.message}${rest.length ? ` (and ${rest.length} more)` : ''}`, true);
  }
}
