// The Server tab's stored models in a real browser against the real server: a model a
// script stored is listed and opened into the editor; the editor's model is stored
// from the toolbar and reads back from the API as the page exports it; a model the
// server refuses is not stored and its error is marked at the field; a model is
// deleted (confirmed) from the list and the server.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { client, exportedModel, kea, openApp, screenshot } from './lib.mjs';

let app;
let page;
let call;
const consoleErrors = [];

before(async () => {
  app = await openApp(consoleErrors);
  ({ page } = app);
  call = client(app.server.url);
});

after(async () => {
  await app?.close();
});


const row = (id) => `#models-table tr[data-model="${id}"]`;

test('a stored model is listed, opened into the editor, stored from the editor and deleted', async () => {
  const model = JSON.parse(kea('preset', 'cv-tracker'));
  model.name = 'Tracker stored by a script';
  model.params.q = 3.5;
  const stored = await call('POST', '/v1/models', model);
  assert.equal(stored.status, 201, JSON.stringify(stored.json));
  const id = stored.json.id;

  // Listed, newest first, with its name and its id (what a script sends as model_id).
  await page.click('#tab-jobs');
  await page.waitForSelector(row(id));
  assert.deepEqual(
    await page.$eval(row(id), (tr) => [...tr.cells].slice(1, 3).map((c) => c.textContent)),
    [model.name, id],
  );
  assert.equal(await page.$eval('#models-table tbody tr', (tr) => tr.dataset.model), id);

  // Opened: the editor shows it, as an import (Undo brings the model before back).
  await page.click(`${row(id)} .model-open`);
  await page.waitForFunction((n) => document.getElementById('page-status').textContent.includes(n), model.name);
  assert.match(await page.textContent('#page-status'), /Undo/);
  assert.equal(await page.inputValue('input[data-path="name"]'), model.name);
  assert.equal(await page.inputValue('input[data-path="params.q"]'), '3.5');
  assert.deepEqual(await exportedModel(page), model);

  // Edited and stored from the toolbar: the server keeps the editor's model as exported.
  await page.fill('input[data-path="name"]', 'Tracker stored from the page');
  await page.press('input[data-path="name"]', 'Enter');
  await page.click('#store-model');
  await page.waitForFunction(() => /^Stored “Tracker stored from the page” on the server as model /.test(document.getElementById('page-status').textContent));
  const newId = (await page.textContent('#page-status')).match(/as model ([0-9a-f-]{36})/)[1];
  const back = await call('GET', `/v1/models/${newId}`);
  assert.equal(back.status, 200);
  assert.equal(back.json.name, 'Tracker stored from the page');
  assert.deepEqual(back.json.model, await exportedModel(page));
  // It heads the list (which the tab was not shown for).
  await page.click('#tab-jobs');
  await page.waitForFunction((i) => document.querySelector('#models-table tbody tr')?.dataset.model === i, newId);
  assert.ok(await page.$(row(id)));
  await screenshot(page, 'server-tab-models');

  // A model the server refuses (a negative SKO) is not stored; the field is marked.
  const before = (await call('GET', '/v1/models?limit=100')).json.items.length;
  await page.fill('input[data-path="system.phi[0]"]', '-1');
  await page.press('input[data-path="system.phi[0]"]', 'Enter');
  const logged = consoleErrors.length;
  await page.click('#models-store');
  await page.waitForFunction(() => document.getElementById('models-status').textContent.startsWith('The server did not store the model'));
  // (The browser logs the refusal's status itself.)
  assert.deepEqual(consoleErrors.splice(logged), ['console: Failed to load resource: the server responded with a status of 422 (Unprocessable Entity)']);
  assert.match(await page.textContent('#models-status'), /phi|SKO/i);
  assert.equal(await page.getAttribute('input[data-path="system.phi[0]"]', 'aria-invalid'), 'true');
  assert.equal((await call('GET', '/v1/models?limit=100')).json.items.length, before);

  // Delete: dismissed keeps it; accepted removes it from the list and the server.
  page.once('dialog', (d) => d.dismiss());
  await page.click(`${row(id)} .model-delete`);
  assert.ok(await page.$(row(id)), 'a dismissed delete keeps the model');
  page.once('dialog', (d) => d.accept());
  await page.click(`${row(id)} .model-delete`);
  await page.waitForSelector(row(id), { state: 'detached' });
  assert.equal((await call('GET', `/v1/models/${id}`)).status, 404);
  assert.equal((await call('GET', `/v1/models/${newId}`)).status, 200);
  assert.deepEqual(consoleErrors, []);
});
