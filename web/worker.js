// The wasm build of kea-core, in a Web Worker so the page never freezes.
//
// Messages in:  {id, op: 'presets' | 'preset' | 'presetSynthesis' | 'check' | 'analyze' | 'analysis_work' | 'traces_csv', ...args}
//               ('analyze' and 'analysis_work' with `options`: the request's other members as JSON text, e.g. '{"budget":true}')
//               ('check' with `discrete: true`: a discrete model, as the identification reads it)
//               or {id, op: 'synthesize' | 'simulate' | 'identify' | 'nonlinear' | 'sensitivity' | 'synthesis_work' | 'monte_carlo_work' | 'identification_work' | 'nonlinear_work' | 'sensitivity_work', request}
//               or {id, op: 'nonlinear_preset', name} (a nonlinear preset's model JSON text, exactly as shipped)
//               or {id, op: 'monte_carlo_csv', result} | {id, op: 'parse', bytes}
// Messages out: {id, progress} while analysing (at most every 50 ms), then
//               {id, ok: <value>} or {id, error: {kind, title, errors:[{path, message}]}}.
// Cancelling a run: the page terminates this worker and starts a new one (instant).
import init, * as kea from './pkg/kea_wasm.js';

// The module is built with WebAssembly SIMD (see .cargo/config.toml): a browser without
// it cannot compile the module, and every request says so instead of a bare CompileError.
const ready = init().catch((e) => {
  throw JSON.stringify({
    kind: 'internal',
    title: `this browser cannot run kea's WebAssembly module (it needs WebAssembly SIMD: Chrome or Edge 91+, Firefox 89+, Safari 16.4+): ${e && e.message ? e.message : e}`,
    errors: [],
  });
});

function asError(e) {
  if (typeof e === 'string') {
    try {
      return JSON.parse(e);
    } catch {
      return { kind: 'internal', title: e, errors: [] };
    }
  }
  return { kind: 'internal', title: String(e && e.message ? e.message : e), errors: [] };
}

// The worker's ops that run (or estimate) one of the core's kinds, and the kind.
const KINDS = {
  synthesize: 'synthesis',
  synthesis_work: 'synthesis',
  simulate: 'monte_carlo',
  monte_carlo_work: 'monte_carlo',
  identify: 'identification',
  identification_work: 'identification',
  nonlinear: 'nonlinear',
  nonlinear_work: 'nonlinear',
  sensitivity: 'sensitivity',
  sensitivity_work: 'sensitivity',
};

self.onmessage = async (event) => {
  const { id, op } = event.data;
  try {
    await ready;
    let value;
    switch (op) {
      case 'version':
        value = kea.version();
        break;
      case 'presets':
        value = JSON.parse(kea.presets());
        break;
      case 'preset':
        value = JSON.parse(kea.preset(event.data.name) ?? 'null');
        break;
      case 'nonlinear_preset': // the text itself, not parsed: the tab shows it as shipped
        value = kea.nonlinear_preset(event.data.name) ?? null;
        break;
      case 'presetSynthesis': // the preset's synthesis example: {target, mode}, or null
        value = JSON.parse(kea.preset_synthesis(event.data.name) ?? 'null');
        break;
      case 'parse': // JSON from a file or a link, read as the core reads it (duplicate keys, 1e400: errors)
        kea.check_json(event.data.bytes); // then JSON.parse, which keeps the keys' order, reads it alike
        value = JSON.parse(new TextDecoder().decode(event.data.bytes)); // (a byte-order mark dropped)
        break;
      case 'analysis_work': // the estimated work of a run, with the server's default limit
        value = JSON.parse(kea.analysis_work(event.data.model, event.data.set ?? '', event.data.options ?? ''));
        break;
      case 'synthesis_work':
      case 'monte_carlo_work':
      case 'identification_work':
      case 'nonlinear_work':
      case 'sensitivity_work': // the core's work(kind, request), as for a server job of that kind
        value = JSON.parse(kea.work(KINDS[op], event.data.request));
        break;
      case 'check': // a discrete model (system.transition) is checked in the identification's form
        value = JSON.parse((event.data.discrete ? kea.check_discrete : kea.check)(event.data.model, event.data.set ?? ''));
        break;
      case 'analyze': {
        let last = 0;
        const text = kea.analyze(event.data.model, event.data.set ?? '', event.data.options ?? '', (fraction) => {
          const now = performance.now();
          if (now - last > 50) {
            last = now;
            self.postMessage({ id, progress: fraction });
          }
          return true;
        });
        value = JSON.parse(text);
        break;
      }
      case 'synthesize':
      case 'simulate':
      case 'identify':
      case 'nonlinear':
      case 'sensitivity': {
        // Synthesis, Monte Carlo, identification and nonlinear (web/synthesis.js,
        // web/monte_carlo.js, web/identification.js, web/nonlinear.js): one request JSON,
        // run by the core's run(kind, request) as a server job of that kind is.
        let last = 0;
        const text = kea.run(KINDS[op], event.data.request, (fraction) => {
          const now = performance.now();
          if (now - last > 50) {
            last = now;
            self.postMessage({ id, progress: fraction });
          }
          return true;
        });
        value = JSON.parse(text);
        break;
      }
      case 'monte_carlo_csv':
        value = kea.monte_carlo_csv(event.data.result);
        break;
      case 'traces_csv':
        value = kea.traces_csv(event.data.result);
        break;
      default:
        throw `{"kind":"internal","title":"unknown op ${op}","errors":[]}`;
    }
    self.postMessage({ id, ok: value });
  } catch (e) {
    self.postMessage({ id, error: asError(e) });
  }
};
