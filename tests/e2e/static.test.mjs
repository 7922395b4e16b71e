// The web UI served as plain files, with no kea server behind it (a static host): the
// analysis runs in the browser (wasm), and everything that needs the server says so
// instead of failing — the Run-in choice, the toolbar's Store on server, the Server tab.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { createServer } from 'node:http';
import { readFile } from 'node:fs/promises';
import path from 'node:path';
import { ROOT, launchBrowser, newPage } from './lib.mjs';

const TYPES = { '.html': 'text/html', '.js': 'text/javascript', '.css': 'text/css', '.wasm': 'application/wasm', '.json': 'application/json', '.csv': 'text/csv' };
const WEB = path.join(ROOT, 'web');

let server;
let browser;
let page;
const consoleErrors = [];

before(async () => {
  // A file server and nothing else: a path outside web/ or not a file is a 404.
  server = createServer(async (req, res) => {
    const rel = decodeURIComponent(new URL(req.url, 'http://x').pathname).replace(/^\/+/, '') || 'index.html';
    const file = path.join(WEB, rel);
    try {
      if (!file.startsWith(WEB + path.sep)) throw new Error('outside');
      const body = await readFile(file);
      res.writeHead(200, { 'content-type': TYPES[path.extname(file)] ?? 'application/octet-stream' });
      res.end(body);
    } catch {
      res.writeHead(404, { 'content-type': 'text/plain' });
      res.end('not found');
    }
  });
  await new Promise((r) => server.listen(0, '127.0.0.1', r));
  browser = await launchBrowser();
  page = await newPage(browser, consoleErrors);
  await page.goto(`http://127.0.0.1:${server.address().port}/`);
  await page.waitForSelector('body[data-ready=true]', { timeout: 30000 });
});

after(async () => {
  await browser?.close();
  server?.close();
});

test('without a kea server the page runs in the browser and says what needs the server', async () => {
  // The page asked whether a server answers (GET v1/presets): the file server's 404 is
  // the one error the browser logs.
  assert.deepEqual(consoleErrors.splice(0), ['console: Failed to load resource: the server responded with a status of 404 (Not Found)']);
  assert.equal(await page.isDisabled('input[name=mode][value=server]'), true);
  assert.equal(await page.isVisible('#store-model'), false);

  // The analysis runs in this browser. Before its first run the page asks for the
  // server's work limit (GET v1/limits: the second 404), and not again.
  const notFound = 'console: Failed to load resource: the server responded with a status of 404 (Not Found)';
  for (const logged of [[notFound], []]) {
    await page.evaluate(() => delete document.querySelector('#summary').dataset.where);
    await page.click('#run');
    await page.waitForFunction(() => document.querySelector('#summary')?.dataset.where === 'browser' && !document.querySelector('#run').disabled, null, { timeout: 60000 });
    assert.match(await page.textContent('#summary'), /computed in .* on the browser \(wasm\)/);
    assert.ok((await page.$$('#criteria table tbody tr')).length > 0);
    assert.deepEqual(consoleErrors.splice(0), logged);
  }

  // The Server tab says there is nothing to list, and why.
  await page.click('#tab-jobs');
  assert.match(await page.textContent('#models-status'), /No kea server answers here/);
  assert.match(await page.textContent('#jobs-status'), /No kea server answers here/);
  assert.equal(await page.$('#models-table'), null);
  assert.equal(await page.$('#jobs-table'), null);
  assert.deepEqual(consoleErrors, []);
});

test('without a kea server the Identification tab loads its example, shipped with the page, and runs it in the browser', async () => {
  await page.click('#tab-identification');
  assert.equal(await page.isDisabled('input[name=id-where][value=server]'), true);
  await page.click('#id-example');
  await page.waitForFunction(() => /read on the model’s grid/.test(document.getElementById('id-data-summary').textContent), null, { timeout: 30000 });
  await page.click('#id-run');
  await page.waitForFunction(() => document.getElementById('id-result').dataset.where === 'browser', null, { timeout: 60000 });
  assert.match(await page.textContent('#id-summary'), /on the browser \(wasm\)$/);
  assert.equal(await page.$$eval('#id-estimates tbody tr', (trs) => trs.length), 3);
  assert.deepEqual(consoleErrors, []);
});
