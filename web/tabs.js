// The tabs of the run pane: Analysis (app.js), Synthesis (synthesis.js), Monte Carlo
// (monte_carlo.js) and Identification (identification.js), all on the model in the
// editor; Sensitivity (sensitivity.js), too; Nonlinear (nonlinear.js), on a nonlinear
// model of its own; and Server: the
// models (models.js) and jobs (jobs.js) the kea server keeps.
// Arrow keys move between the tabs; Ctrl+Enter runs and Esc cancels in the tab shown.

import { IdentificationView } from './identification.js';
import { JobsView, KINDS } from './jobs.js';
import { ModelsView } from './models.js';
import { MonteCarloView } from './monte_carlo.js';
import { NonlinearView } from './nonlinear.js';
import { SensitivityView } from './sensitivity.js';
import { SynthesisView } from './synthesis.js';

/**
 * `ctx`: {model(), loadModel(model, label) (into the editor, one Undo away), example() (a
 * loaded preset's synthesis example), showModelErrors(errors),
 * download(name, type, text), fileStem(), server: whether a kea server answers,
 * openJob(job), openModel(record) (app.js), analysisBusy()}. Returns {current() (the name
 * of the tab shown), show(name), open(kind, id, request, model, body) (a server job in
 * its tab), storeModel() (the editor's model stored on the server: {ok, text})}.
 */
// A tab by a former name (a link or a reloaded page of an earlier kea): the Monte Carlo
// tab was `simulation`, its kind's former name.
const FORMER_NAMES = { simulation: 'monte_carlo' };

export function mountTabs(ctx) {
  const pane = document.getElementById('results-pane');
  const tabs = [...document.querySelectorAll('#run-tabs [role=tab]')];
  const views = {
    synthesis: new SynthesisView(document.getElementById('synthesis-panel'), ctx),
    monte_carlo: new MonteCarloView(document.getElementById('monte-carlo-panel'), ctx),
    identification: new IdentificationView(document.getElementById('identification-panel'), ctx),
    nonlinear: new NonlinearView(document.getElementById('nonlinear-panel'), ctx),
    sensitivity: new SensitivityView(document.getElementById('sensitivity-panel'), ctx),
  };
  if (!ctx.server) {
    for (const v of Object.values(views)) v.bar.disableServer('No kea server answers here (open the page through `kea serve`).');
  }
  const busy = (kind) => {
    const running = kind === 'analysis' ? ctx.analysisBusy() : views[kind]?.bar.running;
    return running ? `A run is under way in the ${KINDS[kind] ?? kind} tab: let it end, or cancel it, before opening a job there.` : null;
  };
  // The Server tab: its stored models, then its jobs, each a section of the panel.
  const panel = document.getElementById('jobs-panel');
  const [modelsRoot, jobsRoot] = [document.createElement('section'), document.createElement('section')];
  modelsRoot.id = 'models-section';
  jobsRoot.id = 'jobs-section';
  panel.append(modelsRoot, jobsRoot);
  const models = new ModelsView(modelsRoot, {
    server: ctx.server,
    model: ctx.model,
    showModelErrors: ctx.showModelErrors,
    open: (record) => ctx.openModel(record),
  });
  const jobs = new JobsView(jobsRoot, { server: ctx.server, open: (job) => ctx.openJob(job), busy });
  views.jobs = {
    root: panel,
    shown: () => {
      models.shown();
      jobs.shown();
    },
    leave: () => jobs.leave(),
  };
  const current = () => pane.dataset.tab ?? 'analysis';

  function show(shown, focus = false) {
    const name = FORMER_NAMES[shown] ?? shown;
    if (!tabs.some((t) => t.dataset.tab === name)) return;
    const changed = name !== current();
    pane.dataset.tab = name;
    for (const t of tabs) {
      const on = t.dataset.tab === name;
      t.setAttribute('aria-selected', String(on));
      t.tabIndex = on ? 0 : -1;
      if (on && focus) t.focus();
    }
    for (const [key, v] of Object.entries(views)) {
      v.root.hidden = key !== name;
      if (key === name) {
        v.draw?.();
        v.shown?.();
      } else v.leave?.();
    }
    if (changed) document.dispatchEvent(new CustomEvent('kea:tab-changed', { detail: name }));
  }

  tabs.forEach((t, i) => {
    t.addEventListener('click', () => show(t.dataset.tab));
    t.addEventListener('keydown', (e) => {
      const step = { ArrowRight: 1, ArrowLeft: -1 }[e.key];
      let next = step === undefined ? null : (i + step + tabs.length) % tabs.length;
      if (e.key === 'Home') next = 0;
      if (e.key === 'End') next = tabs.length - 1;
      if (next === null) return;
      e.preventDefault();
      show(tabs[next].dataset.tab, true);
    });
  });

  document.addEventListener('kea:model-changed', () => {
    for (const v of Object.values(views)) v.markStale?.();
    views.synthesis.refreshChoices();
  });

  document.addEventListener('keydown', (e) => {
    const view = views[current()];
    if (!view?.bar) return;
    if ((e.ctrlKey || e.metaKey) && e.key === 'Enter') view.bar.run();
    if (e.key === 'Escape' && view.bar.running) view.bar.cancel();
  });

  show(current());
  return {
    current,
    show,
    open: (kind, id, request, model, body) => views[kind].openJob(id, request, model, body),
    storeModel: () => models.store(),
  };
}
