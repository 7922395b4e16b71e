// The web UI against a server that needs a bearer token (--token): the page asks for
// the token once, sends it on every request — the job's event stream included —
// and runs the seed's worked example on the server with the CLI's figures; a dropped
// event stream is followed again.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { kea, launchBrowser, newPage, relDiff, screenshot, startServer } from './lib.mjs';

const TOKEN = 'e2e-secret-token';
let server;
let browser;
let page;
const errors = [];
const prompts = [];

before(async () => {
  server = await startServer(['--token', TOKEN]);
  browser = await launchBrowser();
  page = await newPage(browser, errors);
  page.on('dialog', (dialog) => {
    prompts.push(dialog.message());
    dialog.accept(TOKEN);
  });
  await page.goto(`${server.url}/`);
  await page.waitForSelector('body[data-ready=true]', { timeout: 30000 });
});

after(async () => {
  await browser?.close();
  await server?.stop();
});

test('the page asks for the token once and then uses the server', async () => {
  // Without the token the API refuses; the page asked, and the server mode is on.
  const refused = await fetch(`${server.url}/v1/presets`);
  assert.equal(refused.status, 401);
  assert.equal(prompts.length, 1, prompts.join(' | '));
  assert.match(prompts[0], /access token/);
  assert.equal(await page.isDisabled('input[name=mode][value=server]'), false);
  // Kept for the tab, never in the URL.
  assert.equal(await page.evaluate(() => sessionStorage.getItem('kea-token')), TOKEN);
  assert.ok(!page.url().includes(TOKEN));

  await page.selectOption('#preset', 'seed-example');
  await page.check('input[name=mode][value=server]');
  await page.click('#run');
  await page.waitForFunction(
    () => document.querySelector('#summary')?.dataset.where === 'server' && !document.querySelector('#run').disabled,
    null,
    { timeout: 60000 },
  );
  await screenshot(page, '20-token-server-run');
  const yx = await page.$eval('#criteria-table td[data-set=bound][data-criterion=yx][data-row=weighted]', (c) =>
    Number(c.dataset.value),
  );
  const cli = JSON.parse(kea('analyze', 'presets/seed-example.json', '--json'));
  assert.ok(relDiff(yx, cli.criteria.bound.weighted.yx) <= 1e-9, `server F_YX ${yx} vs CLI ${cli.criteria.bound.weighted.yx}`);
  assert.equal(prompts.length, 1, 'asked only once');

  // The job ran on the server (listed with the token).
  const jobs = await (await fetch(`${server.url}/v1/jobs`, { headers: { authorization: `Bearer ${TOKEN}` } })).json();
  const items = jobs.items ?? jobs.jobs ?? jobs;
  assert.ok(items.some((j) => j.status === 'succeeded'), JSON.stringify(jobs).slice(0, 500));
});

test("a job's event stream that drops is followed again", async () => {
  let streams = 0;
  await page.route('**/v1/jobs/*/events', (route) => {
    streams += 1;
    return streams === 1 ? route.abort('connectionreset') : route.continue();
  });
  await page.evaluate(() => delete document.querySelector('#summary').dataset.where);
  await page.click('#run');
  await page.waitForFunction(
    () => document.querySelector('#summary')?.dataset.where === 'server' && !document.querySelector('#run').disabled,
    null,
    { timeout: 60000 },
  );
  await page.unroute('**/v1/jobs/*/events');
  assert.ok(streams >= 2, `the stream was opened ${streams} time(s)`);
  assert.match(await page.textContent('#status'), /Done/);
});

test('no console errors besides the refused first request and the dropped stream', () => {
  const unexpected = errors.filter((e) => !/status of 401|ERR_CONNECTION_RESET/.test(e));
  assert.deepEqual(unexpected, []);
});
