// The error budget of an analysis (result.budget, docs/budget.md): per state, a stacked
// bar of the error sources' shares of its variance — filtered at t_D, filtered averaged
// over the steps, or open-loop at t_D — and the same numbers in a table below it. The
// bars are plain elements sized in percent (a share is a length, nothing to scale or
// zoom), so they print, read aloud through their titles, and need no chart library.

import { fmt } from './results.js';

/** The views of the budget: [which variance, when, its words]. */
const VIEWS = [
  ['potential', 'final', 'filtered variance at t_D'],
  ['potential', 'mean', 'filtered variance, averaged over the steps'],
  ['open_loop', 'final', 'open-loop variance at t_D'],
];

/** A hue per source kind (blue initial, orange model, green measurement errors); within
 * a kind, neighbours alternate dark and light and turn the hue a little. */
const HUES = { initial: 215, model_error: 30, measurement_error: 140 };
const LIGHTNESS = [32, 62, 44, 74, 38, 68, 50];

function colours(sources) {
  const seen = {};
  return sources.map((s) => {
    const k = (seen[s.kind] = (seen[s.kind] ?? -1) + 1);
    return `hsl(${(HUES[s.kind] ?? 0) + 9 * (k % 5)} 65% ${LIGHTNESS[k % LIGHTNESS.length]}%)`;
  });
}

function el(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (k === 'style') Object.assign(e.style, v);
    else if (k in e) e[k] = v;
    else e.setAttribute(k, v);
  }
  e.append(...children);
  return e;
}

const percent = (x) => (x === null || x === undefined ? '—' : `${fmt(100 * x)} %`);

/** A source's label: its name and the state or measurement it enters. */
const label = (s) => (s.enters && s.kind !== 'initial' ? `${s.name} → ${s.enters}` : s.name);

export class BudgetView {
  constructor(root) {
    this.root = root;
    this.view = 0;
  }

  /** Show `result.budget`, or hide the section when the run did not ask for one. */
  show(result) {
    const b = result.budget;
    this.root.hidden = !b;
    if (!b) return this.root.replaceChildren();
    const picker = el(
      'select',
      { id: 'budget-view', 'aria-label': 'Which variance' },
      ...VIEWS.map(([, , words], i) => el('option', { value: String(i), textContent: words })),
    );
    picker.value = String(this.view);
    const body = el('div');
    const draw = () => body.replaceChildren(...this.draw(b, VIEWS[this.view]));
    picker.addEventListener('change', () => {
      this.view = Number(picker.value);
      draw();
    });
    this.root.replaceChildren(
      el('h3', { textContent: 'Error budget' }),
      el('p', { className: 'note', textContent: "Each error source's share of a state's variance, with the optimal filter's gains: the shares add up to the variance (SKO²)." }),
      el('div', { className: 'chart-controls' }, el('label', { htmlFor: 'budget-view', textContent: 'Share of the' }), picker),
      body,
    );
    draw();
  }

  draw(b, [which, when]) {
    const colour = colours(b.sources);
    const share = (st) => st[which][`${when}_share`];
    const variance = (st) => st[which][`${when}_variance`];
    const rows = b.states.map((st) => {
      const shares = share(st);
      const bar = el('div', { className: 'budget-bar', role: 'img', 'aria-label': `${st.state}: shares of its variance` });
      shares.forEach((x, k) => {
        if (!(x > 0)) return;
        bar.append(el('span', { title: `${label(b.sources[k])}: ${percent(x)}`, style: { width: `${100 * x}%`, background: colour[k] } }));
      });
      const sko = Math.sqrt(Math.max(variance(st), 0));
      return el(
        'div',
        { className: 'budget-row' },
        el('span', { className: 'budget-state', textContent: `${st.state} (SKO ${fmt(sko)})` }),
        shares.every((x) => x === null) ? el('span', { className: 'note', textContent: 'variance 0' }) : bar,
      );
    });
    const legend = el(
      'ul',
      { className: 'budget-legend' },
      ...b.sources.map((s, k) => el('li', {}, el('span', { className: 'swatch', style: { background: colour[k] } }), label(s))),
    );
    const head = el('tr', {}, el('th', { scope: 'col', textContent: 'source' }), ...b.states.map((st) => el('th', { scope: 'col', textContent: st.state })));
    const lines = b.sources.map((s, k) =>
      el('tr', {}, el('th', { scope: 'row', textContent: label(s) }), ...b.states.map((st) => el('td', { textContent: percent(share(st)[k]) }))),
    );
    const table = el('table', { className: 'budget-table' }, el('thead', {}, head), el('tbody', {}, ...lines));
    return [el('div', { className: 'budget-bars' }, ...rows), legend, el('div', { className: 'grid-wrap' }, table)];
  }
}
