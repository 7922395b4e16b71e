// The error budget in the page, in a real browser against the real server: ticked
// before a run, in this browser (wasm) and on the server (a job), it shows a stacked bar
// per state whose parts are the result's shares — the numbers `kea analyze --budget`
// prints — and a table of them; a run without it shows none.

import { after, before, test } from 'node:test';
import assert from 'node:assert/strict';
import { choosePreset, kea, openApp, runAnalysis } from './lib.mjs';

let app;
let page;
const consoleErrors = [];

before(async () => {
  app = await openApp(consoleErrors);
  ({ page } = app);
});

after(() => app?.close());


/** What the budget section shows: each state's bar widths (%) and the table's text. */
function shown() {
  return page.evaluate(() => {
    const root = document.querySelector('#budget');
    const bars = [...root.querySelectorAll('.budget-bar')].map((bar) => [...bar.children].map((s) => ({ width: parseFloat(s.style.width), title: s.title })));
    const rows = [...root.querySelectorAll('table.budget-table tbody tr')].map((tr) => [...tr.children].map((c) => c.textContent));
    const states = [...root.querySelectorAll('.budget-state')].map((s) => s.textContent);
    return { hidden: root.hidden, bars, rows, states };
  });
}

test('the error budget, in this browser and on the server, shows the shares kea analyze --budget gives', async () => {
  const cli = JSON.parse(kea('analyze', 'preset:helicopter-range', '--budget', '--json'));
  await choosePreset(page, 'helicopter-range');
  for (const where of ['browser', 'server']) {
    await page.uncheck('#run-budget');
    await runAnalysis(page, where);
    assert.equal((await shown()).hidden, true, `${where}: no budget unless asked`);

    await page.check('#run-budget');
    await runAnalysis(page, where);
    await page.selectOption('#budget-view', '0'); // the filtered variance at t_D
    const s = await shown();
    assert.equal(s.hidden, false, where);
    assert.equal(s.bars.length, 6, `${where}: a bar per state`);
    s.bars.forEach((parts, i) => {
      const total = parts.reduce((a, p) => a + p.width, 0);
      // (A style's width is kept to about 6 digits.)
      assert.ok(Math.abs(total - 100) < 1e-3, `${where}: state ${i}'s parts add up to ${total}`);
      const shares = cli.budget.states[i].potential.final_share.filter((x) => x > 0);
      assert.equal(parts.length, shares.length, `${where}: state ${i}: a part per source with a share`);
      parts.forEach((p, k) => assert.ok(Math.abs(p.width - 100 * shares[k]) <= 1e-5 * Math.max(1, 100 * shares[k]), `${where}: state ${i}'s part ${k}: ${p.width} against ${100 * shares[k]}`));
    });
    // phi[0] enters j_f: most of j_f's filtered variance at t_D (87 %).
    const jf = cli.states.indexOf('j_f');
    const phi0 = s.rows.find((r) => r[0] === 'phi[0] → j_f');
    assert.ok(phi0, JSON.stringify(s.rows.map((r) => r[0])));
    assert.match(phi0[1 + jf], /^87\.2\d* %$/);
    assert.match(s.states[jf], /^j_f \(SKO 0\.569/);

    // The open loop: measurement errors have no part in it.
    await page.selectOption('#budget-view', '2');
    const open = await shown();
    const psi0 = open.rows.find((r) => r[0].startsWith('psi[0]'));
    assert.ok(psi0.slice(1).every((c) => c === '0 %'), JSON.stringify(psi0));
  }
  assert.deepEqual(consoleErrors, []);
});
