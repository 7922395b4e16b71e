// kea's web UI: wires the preset picker, the model editor, the run toggle (browser
// wasm worker or server job) and the results. The model lives in the URL (#model=…,
// deflated and base64url-encoded), with the tab, so they can be shared as a link; the
// Synthesis and Monte Carlo tabs' fields (KeptFields), "Run in" and a running server
// job's id are kept for the browser tab only (sessionStorage), over a reload, and so is
// a change the URL has not caught up with yet when the page is left (see saveToUrl).

import { ModelEditor, isDiscrete, modelProblem } from './editor.js';
import { api } from './api.js';
import { BrowserRunner, ServerRunner, WasmWorker, problemOf } from './runner.js';
import { BudgetView } from './budget.js';
import { MismatchView, parseTruth } from './mismatch.js';
import { TraceChart, criteriaTable, duration, finalTable, fmt, resumedText, scrollHint } from './results.js';
import { mountTabs } from './tabs.js';
import { ProgressText, modelErrorsText, runAnyway, runPart } from './views.js';

const $ = (id) => document.getElementById(id);

const service = new WasmWorker(); // presets, validation, CSV: never blocked by a run
// The server's running job is kept for this browser tab, to be followed again after a reload.
const runners = { browser: new BrowserRunner(), server: new ServerRunner({ keep: 'kea-job-analysis' }) };
// keepUrl: the address names a model that could not be loaded; it stays as it is
// (for the person to see or fix) until the model is changed here.
// edits: how many times the model has changed, so that a run's result can tell whether
// it still belongs to the model shown.
// example: the preset's synthesis example (presets/synthesis/NAME.json), for the Synthesis tab.
// computed: the model as a run reads it (runPart: no name, no description), to tell an
// edit that changes the results from one that does not.
const state = { preset: null, example: null, result: null, job: null, running: null, checkSeq: 0, keepUrl: false, edits: 0, computed: null };

// ------------------------------------------------------------------ URL

function toBase64Url(bytes) {
  let s = '';
  for (const b of new Uint8Array(bytes)) s += String.fromCharCode(b);
  return btoa(s).replaceAll('+', '-').replaceAll('/', '_').replace(/=+$/, '');
}

function fromBase64Url(text) {
  const s = atob(text.replaceAll('-', '+').replaceAll('_', '/'));
  return Uint8Array.from(s, (c) => c.charCodeAt(0));
}

async function encodeModel(json) {
  const stream = new Blob([json]).stream().pipeThrough(new CompressionStream('deflate-raw'));
  return toBase64Url(await new Response(stream).arrayBuffer());
}

/** A link's model data that is damaged or cut short: `message` says which step failed. */
class DamagedLink extends Error {}

/**
 * The model in a link's `#model=` text. Each step that can fail on damaged or cut
 * data throws a DamagedLink naming it, in place of the browser's words (a failed
 * inflate says "Failed to fetch", which reads like a network outage).
 */
async function decodeModel(text) {
  if (!text) throw new DamagedLink('there is no data after “model=”');
  let bytes;
  try {
    bytes = fromBase64Url(text);
  } catch {
    throw new DamagedLink('the text is not base64url');
  }
  let json;
  try {
    const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('deflate-raw'));
    json = new Uint8Array(await new Response(stream).arrayBuffer());
  } catch {
    throw new DamagedLink('the compressed data does not inflate');
  }
  try {
    return await parseJson(json);
  } catch (e) {
    throw new DamagedLink(`the inflated text is not JSON: ${e.title ?? e.message ?? e}`);
  }
}

/**
 * JSON bytes (a file, a link's data) read as the core reads every way in (the wasm
 * module's `check_json`): a key given twice, a number beyond a double (1e400), text that
 * is not UTF-8 are errors, thrown as {title} saying what and where — not, as JSON.parse
 * would, the last key kept and 1e400 read as Infinity.
 */
function parseJson(bytes) {
  return service.call('parse', { bytes });
}

/** The run pane's tab for a link: `&tab=NAME`, nothing for Analysis. */
function tabParam() {
  const tab = $('results-pane').dataset.tab ?? 'analysis';
  return tab === 'analysis' ? '' : `&tab=${tab}`;
}

/** The link's hash: the preset or the model, and the tab. */
async function linkHash() {
  const model = state.preset ? `preset=${encodeURIComponent(state.preset)}` : `model=${await encodeModel(modelJson())}`;
  return `#${model}${tabParam()}`;
}

// The address follows the page 300 ms after its last change (deflating a large model
// on every key would be slow), so a reload or a closed tab within those 300 ms would
// lose the change: the page keeps it for this browser tab (sessionStorage, DRAFT) as it
// is left (pagehide; visibilitychange, which a phone may give instead), with the address
// it was made on. A page opened on that same address (a reload, a reopened tab) takes
// the kept change; another address (a link) is taken as it is, and the draft dropped.
const DRAFT = 'kea-draft';
let urlTimer = null;
let urlChanges = 0; // changes of what the address shows…
let urlWritten = 0; // …and how many of them it shows

function saveToUrl() {
  clearTimeout(urlTimer);
  const change = ++urlChanges;
  if (state.keepUrl) {
    urlWritten = change; // the address is kept as it is, on purpose
    return;
  }
  urlTimer = setTimeout(async () => {
    const hash = await linkHash();
    if (change !== urlChanges) return; // a later change writes its own
    if (location.hash !== hash) history.replaceState(null, '', hash);
    urlWritten = change;
  }, 300);
}

/** Write the address now (`push`: as a new history entry); no update is left pending. */
async function writeUrl(push = false) {
  clearTimeout(urlTimer);
  const change = ++urlChanges;
  const hash = await linkHash();
  history[push ? 'pushState' : 'replaceState'](null, '', hash);
  urlWritten = change;
}

/** The page is being left: keep what the address does not show yet (see DRAFT). */
function keepDraft() {
  try {
    if (urlWritten === urlChanges) return sessionStorage.removeItem(DRAFT);
    const draft = { address: location.hash, preset: state.preset, model: state.preset ? null : modelJson(), tab: $('results-pane').dataset.tab ?? 'analysis' };
    sessionStorage.setItem(DRAFT, JSON.stringify(draft));
  } catch {
    // storage off or full: the address has what it has
  }
}

/** The page lives on after all (shown again): it keeps its changes itself. */
function dropDraft() {
  try {
    sessionStorage.removeItem(DRAFT);
  } catch {
    // storage off: nothing kept
  }
}

/** The change kept as the page was left on this address, or null; taken once. */
function takeDraft() {
  try {
    const draft = JSON.parse(sessionStorage.getItem(DRAFT) ?? 'null');
    sessionStorage.removeItem(DRAFT);
    return draft && typeof draft === 'object' && draft.address === location.hash ? draft : null;
  } catch {
    return null;
  }
}

// ------------------------------------------------------------------ model

const editor = new ModelEditor($('editor'), () => {
  if (state.preset) {
    state.preset = null;
    $('preset').value = '';
  }
  state.keepUrl = false;
  setPageStatus('');
  saveToUrl();
  scheduleCheck();
  // The name or the description alone changes no result: the results stay current.
  const computed = runPart(editor.model);
  if (computed !== state.computed) markStale();
});

/** The shown results, and a run's error, belong to an earlier version of the model. */
function markStale() {
  state.computed = runPart(editor.model);
  state.edits++;
  if (!$('results').hidden) $('results').classList.add('stale');
  if ($('status').classList.contains('error')) setStatus('');
  document.dispatchEvent(new Event('kea:model-changed')); // the Synthesis and Monte Carlo tabs
}

function modelJson() {
  return JSON.stringify(editor.model);
}

let checkTimer = null;
function scheduleCheck() {
  clearTimeout(checkTimer);
  document.body.dataset.checking = 'true';
  checkTimer = setTimeout(() => {
    checkTimer = null;
    check();
  }, 150);
}

async function check() {
  const seq = ++state.checkSeq;
  document.body.dataset.checking = 'true';
  // A discrete model (the Identification tab's) is checked as the identification reads it.
  const errors = await service.call('check', { model: modelJson(), set: '', discrete: isDiscrete(editor.model) });
  if (seq === state.checkSeq) {
    editor.showErrors(errors);
    // The latest edit's check is shown (tests wait for this, not for a fixed time).
    if (checkTimer === null) delete document.body.dataset.checking;
  }
  return errors;
}

/**
 * Load a model (or a preset's, with its synthesis `example`) into the editor; `keepUrl`
 * leaves the address as it is. `label` names the load in the editor's history (the
 * model shown before is one Undo away).
 */
function loadModel(model, presetName = null, { keepUrl = false, example = null, label = null } = {}) {
  state.keepUrl = keepUrl;
  setPageStatus('');
  state.preset = presetName;
  state.example = example;
  $('preset').value = presetName ?? '';
  editor.load(model, label);
  markStale();
  saveToUrl();
  return check();
}

async function loadPreset(name, options) {
  const [model, example] = await Promise.all([service.call('preset', { name }), service.call('presetSynthesis', { name })]);
  if (!model) throw new Error(`no preset named “${name}”`);
  return loadModel(model, name, { ...options, example });
}

/**
 * The preset picker's choice. A model of one's own (edited, imported, from a link) is
 * not thrown away with no way back (an arrow key on the picker is enough to choose):
 * its link stays in the history, one Back away (hashchange loads it again), and the
 * preset gets a history entry of its own.
 */
async function choosePreset(name) {
  if (await replaceModel(() => loadPreset(name, { label: `choice of the preset ${name}` }))) setPageStatus('Loaded the preset; Undo or the browser’s Back brings your model back.');
}

/**
 * Show another model (`load()`: a preset, an imported file). A model of one's own
 * (edited, imported, from a link) stays in the history, one Back away: its link is
 * written as it is now (not 300 ms ago) and the new model gets an entry of its own.
 * Returns whether it did so.
 */
async function replaceModel(load) {
  const own = !state.preset;
  if (own) await writeUrl();
  await load();
  if (own) await writeUrl(true);
  return own;
}

/**
 * The link's model (`#model=…`) or preset (`#preset=NAME`). A link that cannot be read
 * is said to be broken; the seed example is shown and the address kept as it is.
 */
async function loadFromUrl() {
  const params = new URLSearchParams(location.hash.slice(1));
  const label = 'the model of the address';
  let problem; // what the message says after “could not be read”: ` (why)` or `: …`
  if (params.has('model')) {
    try {
      const model = await decodeModel(params.get('model'));
      const wrong = modelProblem(model);
      if (!wrong) return await loadModel(model, null, { label });
      problem = ` (${wrong})`;
    } catch (e) {
      problem = e instanceof DamagedLink ? `: its data is damaged or truncated (${e.message})` : ` (${e.message || e})`;
    }
  } else if (params.has('preset')) {
    try {
      return await loadPreset(params.get('preset'), { label });
    } catch (e) {
      problem = ` (${e.message || e})`;
    }
  } else {
    return loadPreset('seed-example');
  }
  const errors = await loadPreset('seed-example', { keepUrl: true, label });
  setPageStatus(
    `This link's model could not be read${problem}. Showing the seed example instead; the address is kept until you change the model.`,
    true,
  );
  return errors;
}

/** The change kept as the page was left (keepDraft): its preset, or its model. */
async function loadDraft(draft) {
  try {
    if (draft.preset) return await loadPreset(draft.preset);
    const model = JSON.parse(draft.model);
    if (!modelProblem(model)) return await loadModel(model);
  } catch {
    // unreadable: the address has the say
  }
  return loadFromUrl();
}

function download(name, type, text) {
  const url = URL.createObjectURL(new Blob([text], { type }));
  const a = Object.assign(document.createElement('a'), { href: url, download: name });
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 1000);
}

/** The start of a download's file name: the preset's name, or the model's (“Tracker (v2)” → tracker-v2). */
function fileStem() {
  const stem = (state.preset ?? editor.model.name ?? '').replace(/[^a-zA-Z0-9_-]+/g, '-').replace(/^-+|-+$/g, '');
  return stem.toLowerCase() || 'model';
}

// ------------------------------------------------------------------ running

/** The analysis's run status (the Analysis tab's run bar). */
function setStatus(text, error = false) {
  $('status').textContent = text;
  $('status').classList.toggle('error', error);
  anyway.hide();
}

const anyway = runAnyway($('run-anyway'), () => run());

/** Messages about the page and the model (import, link), shown on every tab. */
function setPageStatus(text, error = false) {
  $('page-status').textContent = text;
  $('page-status').classList.toggle('error', error);
}

// The editor's notes on what it did (a block pasted into a grid).
$('editor').addEventListener('editor-note', (e) => setPageStatus(e.detail));

function mode() {
  return document.querySelector('input[name=mode]:checked').value;
}

/**
 * "Run in" is one setting for the four tabs, though each run bar shows it: a choice
 * made in one is made in all, and kept over a reload for this browser tab
 * (sessionStorage, as the Synthesis and Monte Carlo fields are). A server that does
 * not answer (its choices disabled) leaves it in the browser.
 */
function shareRunIn() {
  const KEY = 'kea-run-in';
  const choices = [...document.querySelectorAll('.run-controls .mode input[type=radio]')];
  const choose = (value) => choices.forEach((c) => (c.checked = c.value === value));
  let kept = null;
  try {
    kept = sessionStorage.getItem(KEY);
  } catch {
    // storage off: the default
  }
  if (choices.some((c) => c.value === kept && !c.disabled)) choose(kept);
  for (const c of choices) {
    c.addEventListener('change', () => {
      choose(c.value);
      try {
        sessionStorage.setItem(KEY, c.value);
      } catch {
        // storage off: not kept
      }
    });
  }
}

async function run() {
  if (state.running) return;
  const where = mode();
  const runner = runners[where];
  if (editor.localErrors().length) {
    editor.mark();
    setStatus('The model has fields to fix first (see the marked fields).', true);
    return;
  }
  const json = modelJson(); // the model as the run starts
  const options = {};
  if ($('run-budget').checked) options.budget = true;
  try {
    const truth = parseTruth($('run-truth').value);
    if (truth) options.truth = truth;
  } catch (message) {
    setStatus(String(message), true);
    return;
  }
  await follow(where, runner, (onProgress) => runner.run(json, onProgress, options), state.edits);
}

/**
 * The server job this browser tab's page started before it was reloaded, if it has not
 * been seen to its end: followed again — progress, Cancel, its result (stale if the
 * model shown is not the one it runs) — or, when the server no longer has it, forgotten
 * without a word.
 */
function resume() {
  const runner = runners.server;
  const kept = runner.kept();
  if (!kept || state.running) return;
  if (document.querySelector('input[name=mode][value=server]').disabled) return runner.store(null);
  const edits = runPart(kept.model) === runPart(editor.model) ? state.edits : -1;
  return follow('server', runner, (onProgress) => runner.attach(kept.id, onProgress), edits, kept.id);
}

/**
 * Show a run (`start(onProgress)` → {result, job}) in the run bar, then its result:
 * current if the model has not changed since `edits` (the count when the run's model
 * was taken). `resumed`: the id of a server job taken over after a reload, or opened
 * from the Server tab (`opened`).
 */
async function follow(where, runner, start, edits, resumed = null, opened = false) {
  state.running = runner;
  $('run').disabled = true;
  $('cancel').disabled = false;
  $('progress').value = 0;
  const label = opened ? `Opening server job ${resumed}…` : resumed ? `Following server job ${resumed} (started before the reload)…` : where === 'browser' ? 'Running in this browser…' : 'Running on the server…';
  setStatus(label);
  const started = performance.now();
  const shown = new ProgressText(label);
  const onProgress = (p) => {
    $('progress').value = p;
    if (state.running === runner) setStatus(shown.text(p));
  };
  try {
    const { result, job } = await start(onProgress);
    $('progress').value = 1;
    const elapsed = performance.now() - started;
    state.result = result;
    state.job = job ?? null;
    const current = state.edits === edits;
    if (current) editor.showErrors([]); // else the check of the edited model has the say
    showResult(result, where, elapsed, current);
    setStatus(
      opened
        ? `Server job ${job}, opened from the Server tab.`
        : resumed
        ? `Done (server job ${job}, followed after the reload).`
        : `Done in ${duration(elapsed)} (${where === 'browser' ? 'browser, wasm' : `server job ${job}`}).`,
    );
  } catch (e) {
    if (e.kind === 'cancelled') {
      setStatus('Cancelled.');
    } else if (e.kind === 'gone' && resumed) {
      setStatus(opened ? `The server no longer has job ${resumed}.` : '', opened);
    } else if (e.kind === 'too-much-work') {
      setStatus(e.title, true);
      anyway.offer(e);
    } else {
      // The errors at their cells, and the first here, named as the editor names its
      // place (the core's title says `system.phi[0]`: the grids count from 1).
      const errors = e.errors ?? [];
      if (errors.length) editor.showErrors(errors);
      setStatus(errors.length ? `${modelErrorsText(errors)} (see the marked fields)` : e.title ?? String(e), true);
    }
    $('progress').value = 0;
  } finally {
    state.running = null;
    $('run').disabled = false;
    $('cancel').disabled = true;
  }
}

function cancel() {
  state.running?.cancel();
}

/**
 * Open a server job (the Server tab): its model — with the values its `set` gave
 * the params — in the editor, as an import is (one Undo, or Back, away from the model
 * shown before), its tab shown with its request, and the job followed there as a run
 * is: its result, its error at the fields, or its progress to its end.
 */
async function openJob(job, tabs) {
  const r = await api(`v1/jobs/${job.id}/request`);
  if (!r.ok) throw new Error(r.status === 404 ? 'the server no longer has it' : (await problemOf(r)).title);
  const request = await r.json();
  // A nonlinear job's model is the Nonlinear tab's own (not the editor's): its request goes there.
  if (job.kind === 'nonlinear') {
    tabs.show(job.kind);
    tabs.open(job.kind, job.id, request, request.model, JSON.stringify({ kind: job.kind, model: request.model }));
    return;
  }
  const model = request.model;
  if (!model || typeof model !== 'object' || Array.isArray(model)) throw new Error('its request has no model');
  if (request.set && typeof request.set === 'object') model.params = { ...(model.params ?? {}), ...request.set };
  const own = await replaceModel(() => loadModel(model, null, { label: `opening of server job ${job.id}` }));
  setPageStatus(`Opened server job ${job.id}; ${own ? 'Undo or the browser’s Back brings your model back' : 'Undo brings the preset back'}.`);
  tabs.show(job.kind);
  // Kept for this browser tab as a job started here is: a reload follows it again.
  const body = JSON.stringify({ kind: job.kind, model });
  // Not awaited: the job is followed in its tab, to its end.
  if (job.kind !== 'analysis') {
    tabs.open(job.kind, job.id, request, model, body);
    return;
  }
  $('run-budget').checked = request.budget === true;
  const truthSet = request.truth?.model ? null : request.truth?.set;
  $('run-truth').value = truthSet ? Object.entries(truthSet).map(([k, v]) => `${k}=${v}`).join(', ') : '';
  const runner = runners.server;
  runner.store({ id: job.id, body });
  follow('server', runner, (onProgress) => runner.attach(job.id, onProgress), state.edits, job.id, true);
}

/**
 * Open a model stored on the server (the Server tab) in the editor, as an import is (one
 * Undo, or Back, away from the model shown before).
 */
async function openStoredModel(record) {
  const model = record.model;
  const problem = modelProblem(model);
  if (problem) throw new Error(`it is not a model this page can show: ${problem}`);
  const name = record.name ?? record.id;
  const own = await replaceModel(() => loadModel(model, null, { label: `opening of the stored model ${name}` }));
  setPageStatus(`Opened the stored model “${name}”; ${own ? 'Undo or the browser’s Back brings your model back' : 'Undo brings the preset back'}.`);
}

/** Show a run's result; `current`: the model has not changed since the run started. */
function showResult(r, where, elapsed, current) {
  $('results').hidden = false;
  $('results').classList.toggle('stale', !current);
  const parts = [
    `D = ${r.steps.toLocaleString('en')} steps, Δt = ${fmt(r.dt)}`,
    `t ∈ [${fmt(r.t0)}, ${fmt(r.t_end)}]`,
    r.steady_state ? `steady state from step ${r.steady_state.reached_at_step.toLocaleString('en')}${r.steady_state.shortcut_used ? ' (shortcut used)' : ''}` : null,
    `computed in ${duration(r.timing.wall_ms)} on the ${where === 'browser' ? 'browser (wasm)' : 'server'}`,
    // A server job a restart interrupted went on from the state it had kept: the time
    // above is from there.
    resumedText(r.timing),
  ].filter(Boolean);
  $('summary').textContent = parts.join(' · ');
  $('summary').dataset.where = where;
  $('summary').dataset.elapsedMs = String(elapsed);
  $('warnings').replaceChildren(...r.warnings.map((w) => Object.assign(document.createElement('li'), { textContent: w })));
  $('criteria').replaceChildren(criteriaTable(r));
  budget.show(r);
  mismatch.show(r);
  $('final').replaceChildren(finalTable(r));
  for (const box of [$('criteria'), $('final')]) scrollHint(box);
  const select = $('trace-state');
  const previous = select.value;
  select.replaceChildren(
    ...r.traces.states.map((s, i) => Object.assign(document.createElement('option'), { value: String(i), textContent: s.state })),
  );
  if (previous && Number(previous) < r.traces.states.length) select.value = previous;
  chart.show(r, { state: select, log: $('trace-log') });
}

const chart = new TraceChart($('chart'));
const budget = new BudgetView($('budget'));
const mismatch = new MismatchView($('mismatch'));

// ------------------------------------------------------------------ wiring

async function serverAvailable() {
  try {
    const r = await api('v1/presets', { headers: { accept: 'application/json' } });
    return r.ok;
  } catch {
    return false;
  }
}

async function main() {
  const presets = await service.call('presets');
  const picker = $('preset');
  picker.append(Object.assign(document.createElement('option'), { value: '', textContent: '(custom model)' }));
  for (const p of presets) {
    picker.append(
      Object.assign(document.createElement('option'), {
        value: p.name,
        textContent: `${p.title} — N=${p.states}, n=${p.measurements}`,
        title: p.description,
      }),
    );
  }
  picker.addEventListener('change', () => picker.value && choosePreset(picker.value));

  editor.bindHistory({ undo: $('undo'), redo: $('redo'), keys: $('editor-pane') });
  $('export-model').addEventListener('click', () =>
    download(`${fileStem()}.json`, 'application/json', JSON.stringify(editor.model, null, 2) + '\n'),
  );
  $('import-button').addEventListener('click', () => $('import-model').click());
  // A file imported is read as the core reads one (parseJson), and shown as a preset
  // chosen is: a model of one's own stays one Back away (replaceModel).
  $('import-model').addEventListener('change', async (e) => {
    const file = e.target.files[0];
    if (!file) return;
    e.target.value = '';
    let model;
    try {
      model = await parseJson(new Uint8Array(await file.arrayBuffer()));
    } catch (err) {
      return setPageStatus(`${file.name} is not JSON (${err.title ?? err.message ?? err}); the model is unchanged.`, true);
    }
    const problem = modelProblem(model);
    if (problem) return setPageStatus(`${file.name} is not a kea model: ${problem}; the model is unchanged.`, true);
    const own = await replaceModel(() => loadModel(model, null, { label: `import of ${file.name}` }));
    setPageStatus(`Imported ${file.name}; ${own ? 'Undo or the browser’s Back brings your model back' : 'Undo brings the preset back'}.`);
  });
  $('copy-link').addEventListener('click', async () => {
    const link = `${location.origin}${location.pathname}#model=${await encodeModel(modelJson())}${tabParam()}`;
    try {
      await navigator.clipboard.writeText(link);
      setPageStatus('Link copied.');
    } catch {
      state.keepUrl = false;
      history.replaceState(null, '', link);
      setPageStatus('The link is in the address bar (the clipboard is not available here).');
    }
  });
  $('run').addEventListener('click', run);
  $('cancel').addEventListener('click', cancel);
  $('download-result').addEventListener('click', () =>
    download(`${fileStem()}-result.json`, 'application/json', JSON.stringify(state.result, null, 2) + '\n'),
  );
  $('download-csv').addEventListener('click', async () => {
    const csv = await service.call('traces_csv', { result: JSON.stringify(state.result) });
    download(`${fileStem()}-traces.csv`, 'text/csv', csv);
  });
  $('trace-state').addEventListener('change', () => chart.draw());
  $('trace-log').addEventListener('change', () => chart.draw());
  // The results' tables scroll sideways in a narrow window, and say so (as the editor's grids).
  const boxes = new ResizeObserver((entries) => entries.forEach((e) => scrollHint(e.target)));
  for (const box of [$('criteria'), $('final')]) {
    box.addEventListener('scroll', () => scrollHint(box), { passive: true });
    boxes.observe(box);
  }
  addEventListener('pagehide', keepDraft);
  document.addEventListener('visibilitychange', () => (document.visibilityState === 'hidden' ? keepDraft() : dropDraft()));
  addEventListener('pageshow', (e) => e.persisted && dropDraft()); // back from the cache: the page lives on
  // On one column the run bar of the tab shown sticks to the window's bottom (style.css):
  // a control the focus moves to behind it (Tab through the editor) is scrolled above it.
  document.addEventListener('focusin', (e) => {
    const bar = [...document.querySelectorAll('.run-controls')].find((b) => b.offsetParent !== null);
    if (!bar || bar.contains(e.target) || getComputedStyle(bar).position !== 'sticky') return;
    const [at, under] = [e.target.getBoundingClientRect(), bar.getBoundingClientRect()];
    if (at.bottom > under.top && at.top < under.bottom) window.scrollBy(0, at.bottom - under.top);
  });
  document.addEventListener('keydown', (e) => {
    if (($('results-pane').dataset.tab ?? 'analysis') !== 'analysis') return; // tabs.js handles the others
    if ((e.ctrlKey || e.metaKey) && e.key === 'Enter') run();
    if (e.key === 'Escape' && state.running) cancel();
  });

  if (!(await serverAvailable())) {
    const server = document.querySelector('input[name=mode][value=server]');
    server.disabled = true;
    server.parentElement.title = 'No kea server answers here (open the page through `kea serve`).';
  }
  const tabs = mountTabs({
    model: () => editor.model,
    // A model from a tab (the Identification tab's example), shown as an import is: a
    // model of one's own stays one Undo, or Back, away.
    loadModel: async (model, label) => {
      const own = await replaceModel(() => loadModel(model, null, { label }));
      setPageStatus(`Loaded ${label}; ${own ? 'Undo or the browser’s Back brings your model back' : 'Undo brings the preset back'}.`);
    },
    pendingModelErrors: () => editor.localErrors(),
    example: () => (state.preset && state.example ? { preset: state.preset, ...state.example } : null),
    showModelErrors: (errors) => editor.showErrors(errors),
    download,
    fileStem,
    server: !document.querySelector('input[name=mode][value=server]').disabled,
    openJob: (job) => openJob(job, tabs),
    openModel: openStoredModel,
    analysisBusy: () => state.running !== null,
  });
  shareRunIn();
  if (!document.querySelector('input[name=mode][value=server]').disabled) {
    $('store-model').hidden = false;
    $('store-model').addEventListener('click', async () => {
      $('store-model').disabled = true;
      try {
        const { ok, text } = await tabs.storeModel();
        setPageStatus(ok ? `${text} The Server tab lists it.` : text, !ok);
      } finally {
        $('store-model').disabled = false;
      }
    });
  }
  const draft = leftDraft;
  if (draft) await loadDraft(draft);
  else await loadFromUrl();
  // The link's tab (`&tab=synthesis` / `monte_carlo`; an older link's `simulation` is
  // `monte_carlo`), kept in the URL as it changes.
  tabs.show(draft?.tab ?? new URLSearchParams(location.hash.slice(1)).get('tab') ?? 'analysis');
  document.addEventListener('kea:tab-changed', saveToUrl);
  // Server jobs started before a reload, followed again (the other tabs' run bars listen).
  resume();
  document.dispatchEvent(new Event('kea:resume'));
  // A link opened in this tab while kea is open (the address bar, a link elsewhere): its
  // model or preset, and its tab. The page's own address updates (history.replaceState)
  // fire no hashchange; an address that names what is shown already is left alone.
  window.addEventListener('hashchange', async () => {
    if (location.hash === (await linkHash())) return;
    clearTimeout(urlTimer); // a pending update would write the model shown before
    urlWritten = urlChanges;
    const params = new URLSearchParams(location.hash.slice(1));
    if (params.has('model') || params.has('preset')) await loadFromUrl();
    tabs.show(params.get('tab') ?? 'analysis');
  });
  document.body.dataset.ready = 'true';
}

// Taken before anything can drop it (a visibilitychange while the page starts).
const leftDraft = takeDraft();
main().catch((e) => setPageStatus(`Could not start: ${e.title ?? e.message ?? e}`, true));
