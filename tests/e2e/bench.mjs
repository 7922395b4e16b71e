// Benchmark: the same analysis in the browser (wasm in a Web Worker, Chromium) and
// natively (`kea analyze --json`), timing only the analysis (`timing.wall_ms`), median
// of RUNS runs per preset. Run with `cargo xtask bench-web`; prints a Markdown table.

import { kea, launchBrowser, newPage, startServer } from './lib.mjs';
import fs from 'node:fs';
import os from 'node:os';

const RUNS = Number(process.env.KEA_BENCH_RUNS ?? 5);
const PRESETS = (process.env.KEA_BENCH_PRESETS ?? 'seed-example,helicopter-range').split(',');
// KEA_BENCH_STEPS: run every preset with this many steps instead of its own.
const STEPS = process.env.KEA_BENCH_STEPS ? Number(process.env.KEA_BENCH_STEPS) : null;

const median = (xs) => {
  const s = [...xs].sort((a, b) => a - b);
  const m = s.length >> 1;
  return s.length % 2 ? s[m] : (s[m - 1] + s[m]) / 2;
};

const server = await startServer();
const browser = await launchBrowser();
const errors = [];
const page = await newPage(browser, errors);
try {
  await page.goto(`${server.url}/`);
  await page.waitForSelector('body[data-ready=true]', { timeout: 30000 });
  const rows = [];
  for (const name of PRESETS) {
    // A name ending in .json is a model file.
    let model = name.endsWith('.json') ? fs.readFileSync(name, 'utf8') : kea('preset', name);
    if (STEPS) {
      const m = JSON.parse(model);
      m.time.steps = STEPS;
      model = JSON.stringify(m);
    }
    // One warm-up run each, then RUNS timed runs.
    const wasm = await page.evaluate(
      async ({ model, runs }) => {
        const worker = new Worker('/worker.js', { type: 'module' });
        let id = 0;
        const call = (msg) =>
          new Promise((resolve, reject) => {
            const my = ++id;
            worker.onmessage = (e) => {
              if (e.data.id !== my || e.data.progress !== undefined) return;
              if (e.data.error) reject(new Error(e.data.error.title));
              else resolve(e.data.ok);
            };
            worker.postMessage({ id: my, ...msg });
          });
        const times = [];
        for (let i = 0; i <= runs; i++) {
          const r = await call({ op: 'analyze', model, set: '' });
          if (i > 0) times.push(r.timing.wall_ms);
        }
        worker.terminate();
        return times;
      },
      { model, runs: RUNS },
    );
    const native = [];
    const file = `${os.tmpdir()}/kea-bench-${name.replace(/\W/g, '_')}.json`;
    fs.writeFileSync(file, model);
    for (let i = 0; i <= RUNS; i++) {
      const r = JSON.parse(kea('analyze', file, '--json'));
      if (i > 0) native.push(r.timing.wall_ms);
    }
    const m = JSON.parse(model);
    rows.push({ name, steps: m.time.steps, n: m.system.states.length, wasm: median(wasm), native: median(native) });
  }
  const version = browser.version();
  console.log(`Chromium ${version}, ${os.cpus()[0]?.model ?? 'unknown CPU'} (${os.cpus().length} cores), median of ${RUNS} runs after one warm-up\n`);
  console.log('| preset | N | steps D | native (ms) | browser wasm worker (ms) | wasm / native |');
  console.log('|---|---|---|---|---|---|');
  for (const r of rows) {
    console.log(`| ${r.name} | ${r.n} | ${r.steps} | ${r.native.toFixed(1)} | ${r.wasm.toFixed(1)} | ${(r.wasm / r.native).toFixed(2)}× |`);
  }
  if (errors.length) throw new Error(errors.join('\n'));
} finally {
  await browser.close();
  await server.stop();
}
