// Benchmark: the model editor at large N, in headless Chromium against the real
// `kea serve`. For each model (a chain dY/dt = -0.5 y_i + y_{i+1}, sizes below) it
// times, median of RUNS runs:
// - import: from choosing the file to the editor drawn (the model's name in its
//   field, the next frame drawn), and to the page saying "Imported …" (the core's
//   check of the model, in a worker, has answered);
// - edit: one cell of a (focused, in view) typed into (an `input` event) to the next
//   frame, and the main thread's long tasks in the 1.5 s after it (the check, the
//   marks, the link);
// - paste: a 200×200 block pasted into a's first cell, the same two figures.
// Opt-in: `node bench-editor.mjs` (KEA_BIN, KEA_ROOT, KEA_CHROMIUM as for the tests;
// KEA_BENCH_RUNS). Prints a Markdown table.

import { chainModel, launchBrowser, newPage, startServer } from './lib.mjs';
import os from 'node:os';

const RUNS = Number(process.env.KEA_BENCH_RUNS ?? 3);

const median = (xs) => {
  const s = [...xs].sort((a, b) => a - b);
  const m = s.length >> 1;
  return s.length % 2 ? s[m] : (s[m - 1] + s[m]) / 2;
};

const MODELS = [
  { label: 'N = 200, n = 50', model: chainModel(200, 50) },
  { label: 'N = 200, n = 200', model: chainModel(200, 200) },
];

// In the page: a PerformanceObserver of long tasks, and "the next frame" (after layout and paint).
const setup = () => {
  window.__long = [];
  new PerformanceObserver((l) => window.__long.push(...l.getEntries().map((e) => ({ start: e.startTime, duration: e.duration })))).observe({ type: 'longtask' });
};
const nextFrame = () => new Promise((r) => requestAnimationFrame(() => setTimeout(r)));

/**
 * Import `model` as a file; the ms until the editor shows it (its name field has the
 * model's name, and the next frame is drawn) and until the core's check of it has
 * answered (the page's status says "Imported"; the check runs in a worker).
 */
async function importTime(page, model, i) {
  const name = `bench-${i}.json`;
  model = { ...model, name: `${model.name} #${i}` };
  const t0 = Date.now();
  await page.setInputFiles('#import-model', { name, mimeType: 'application/json', buffer: Buffer.from(JSON.stringify(model)) });
  const drawn = page.evaluate(
    (name) =>
      new Promise((resolve) => {
        const shown = () => document.querySelector('#editor input[data-path=name]')?.value === name;
        const poll = () => (shown() ? requestAnimationFrame(() => setTimeout(resolve)) : setTimeout(poll, 5));
        poll();
      }),
    model.name,
  );
  await drawn;
  const t1 = Date.now();
  await page.waitForFunction((n) => document.getElementById('page-status').textContent.includes(n), name, { timeout: 600000, polling: 50 });
  return [t1 - t0, Date.now() - t0];
}

/** In the page: run `act()` (sync); the ms to the next frame and the long tasks' ms in the next 1.5 s. */
async function timed(page, act, arg) {
  return page.evaluate(
    async ({ act, arg }) => {
      const f = new Function(`return (${act})`)();
      window.__long = [];
      const t0 = performance.now();
      f(arg);
      await new Promise((r) => requestAnimationFrame(() => setTimeout(r)));
      const frame = performance.now() - t0;
      await new Promise((r) => setTimeout(r, 1500));
      const busy = window.__long.filter((e) => e.start + e.duration >= t0).reduce((a, e) => a + e.duration, 0);
      return { frame, busy };
    },
    { act: act.toString(), arg },
  );
}

const edit = (value) => {
  const input = document.activeElement;
  input.value = value;
  input.dispatchEvent(new InputEvent('input', { bubbles: true, inputType: 'insertText', data: value }));
};

const paste = (text) => {
  const input = document.querySelector('input[data-path="system.a[0][0]"]');
  input.focus();
  const data = new DataTransfer();
  data.setData('text/plain', text);
  input.dispatchEvent(new ClipboardEvent('paste', { clipboardData: data, bubbles: true, cancelable: true }));
};

const block = Array.from({ length: 200 }, (_, i) => Array.from({ length: 200 }, (_, j) => (i === j ? '-0.25' : j === i + 1 ? '2' : '0')).join('\t')).join('\n');

const server = await startServer();
const browser = await launchBrowser();
const errors = [];
const page = await newPage(browser, errors);
page.setDefaultTimeout(600000);
try {
  await page.goto(`${server.url}/`);
  await page.waitForSelector('body[data-ready=true]', { timeout: 30000 });
  await page.evaluate(setup);
  const rows = [];
  for (const { label, model } of MODELS) {
    const r = { label, import: [], checked: [], editFrame: [], editBusy: [], pasteFrame: [], pasteBusy: [] };
    for (let i = 0; i < RUNS; i++) {
      const [drawn, checked] = await importTime(page, model, i);
      r.import.push(drawn);
      r.checked.push(checked);
      await page.waitForTimeout(1500);
      // The cell to edit in view, as after scrolling to it, with the focus.
      await page.focus('input[data-path="system.a[100][57]"]');
      await page.waitForTimeout(1500);
      const e = await timed(page, edit, String(i + 2));
      r.editFrame.push(e.frame);
      r.editBusy.push(e.busy);
      const p = await timed(page, paste, block);
      r.pasteFrame.push(p.frame);
      r.pasteBusy.push(p.busy);
      process.stderr.write(`${label} #${i + 1}: import ${drawn} / ${checked} ms, edit ${e.frame.toFixed(0)} / ${e.busy.toFixed(0)} ms, paste ${p.frame.toFixed(0)} / ${p.busy.toFixed(0)} ms\n`);
    }
    rows.push(r);
  }
  const version = browser.version();
  console.log(`Chromium ${version}, ${os.cpus()[0]?.model ?? 'unknown CPU'} (${os.cpus().length} cores), median of ${RUNS} runs\n`);
  console.log('| model | import: editor drawn / checked (ms) | one cell: to next frame / long tasks (ms) | 200×200 paste: to next frame / long tasks (ms) |');
  console.log('|---|---|---|---|');
  const f = (xs) => median(xs).toFixed(0);
  for (const r of rows) {
    console.log(`| ${r.label} | ${f(r.import)} / ${f(r.checked)} | ${f(r.editFrame)} / ${f(r.editBusy)} | ${f(r.pasteFrame)} / ${f(r.pasteBusy)} |`);
  }
  if (errors.length) throw new Error(errors.join('\n'));
} finally {
  await browser.close();
  await server.stop();
}
