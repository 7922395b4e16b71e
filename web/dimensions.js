// The model's dimensions N, n, L, M (METHOD §1.1) and their changes: a resize, and the
// removal (and restoring) of one state or measurement. Every member indexed by a
// dimension is listed once, in MEMBERS, so that each change keeps them all consistent:
// a measurement's schedule entry goes with its row of C, a state's weights with its row
// of a, and `measurement.pairs` (which names states and measurements) loses the pairs of
// what was removed. What a smaller dimension removes is kept on a Shelf, from which a
// larger one takes it back: shrinking N by mistake loses nothing in the session.

/** The largest N, L and M kea accepts (src/validate.rs: MAX_STATES, MAX_SOURCES); n ≤ N. */
export const MAX_DIMENSION = 200;

/**
 * The members indexed by a dimension: where they are, the dimension of each index
 * (rows, then columns), the entry a new index gets (0 unless `fill` says), and whether
 * the member is created when absent (`create`; otherwise an absent one stays absent).
 */
const MEMBERS = [
  { at: ['system', 'states'], axes: ['N'], fill: (i) => `y${i + 1}`, create: () => true },
  // A discrete model (the identification's) has Φ, `transition`, in place of a.
  { at: ['system', 'a'], axes: ['N', 'N'], create: (m) => m.system.transition === undefined },
  { at: ['system', 'transition'], axes: ['N', 'N'] },
  { at: ['system', 'b'], axes: ['N', 'L'], create: () => true },
  { at: ['system', 'u'], axes: ['N'] },
  { at: ['system', 'y0'], axes: ['N'] },
  { at: ['system', 'eta0'], axes: ['N'] },
  { at: ['system', 'phi'], axes: ['L'], create: (m) => !m.system.W },
  { at: ['system', 'W'], axes: ['L', 'L'] },
  { at: ['measurement', 'names'], axes: ['n'], fill: (j) => `z${j + 1}`, create: () => true },
  { at: ['measurement', 'c'], axes: ['n', 'N'], create: () => true },
  { at: ['measurement', 'g'], axes: ['N', 'M'] },
  { at: ['measurement', 'gamma'], axes: ['n', 'M'], create: (m) => !m.measurement.g },
  { at: ['measurement', 'psi'], axes: ['M'], create: (m) => !m.measurement.V },
  { at: ['measurement', 'V'], axes: ['M', 'M'] },
  { at: ['measurement', 'schedule'], axes: ['n'], fill: () => null },
  { at: ['criteria', 'weights', 'yz'], axes: ['N'] },
  { at: ['criteria', 'weights', 'zx'], axes: ['N'] },
  { at: ['criteria', 'weights', 'yx'], axes: ['N'] },
];

const pathOf = (member) => member.at.join('.');
const fillOf = (member) => member.fill ?? (() => 0);

/** The object holding a member, or undefined when a part on the way is not an object. */
function holderOf(model, member) {
  let o = model;
  for (const key of member.at.slice(0, -1)) {
    o = o?.[key];
    if (o === null || typeof o !== 'object' || Array.isArray(o)) return undefined;
  }
  return o;
}

const lastKey = (member) => member.at[member.at.length - 1];

/** The model's dimensions N, n, L, M (METHOD §1.1). */
export function dimensions(model) {
  const s = model.system ?? {};
  const m = model.measurement ?? {};
  const noise = m.gamma ?? m.g;
  return {
    N: s.states?.length ?? 0,
    n: m.names?.length ?? 0,
    L: s.b?.[0]?.length ?? s.phi?.length ?? s.W?.length ?? 0,
    M: noise?.[0]?.length ?? m.psi?.length ?? m.V?.length ?? 0,
  };
}

/**
 * What a resize or a removal took away, for a later resize or restoring to take back:
 * per member, its entries beyond the model's current extent (the entries within it are
 * stale copies: the model's own win), and the pairs that named a removed state or
 * measurement. One shelf per editing session: a model loaded starts a new one.
 */
export class Shelf {
  constructor() {
    this.members = new Map(); // member path → a copy of its array, as large as it has been
    this.pairs = []; // pairs naming a state or measurement that a resize removed
  }

  /** Put the model's entries on the shelf, over the older ones at the same places. */
  keep(model) {
    for (const member of MEMBERS) {
      const value = holderOf(model, member)?.[lastKey(member)];
      if (Array.isArray(value)) {
        const path = pathOf(member);
        this.members.set(path, overlay(this.members.get(path), structuredClone(value), member.axes.length));
      }
    }
  }

  get(member) {
    return this.members.get(pathOf(member));
  }

  /**
   * A copy to change, this one left as it is: the editor's history keeps the shelf as
   * it was before and after each change of dimension (a removal undone must find the
   * shelf's entries where they were).
   */
  clone() {
    const copy = new Shelf();
    copy.members = structuredClone(this.members);
    copy.pairs = structuredClone(this.pairs);
    return copy;
  }

  /** About how many bytes the shelf holds (its entries as JSON text). */
  bytes() {
    let n = JSON.stringify(this.pairs).length;
    for (const value of this.members.values()) n += JSON.stringify(value).length;
    return n;
  }
}

/** `value` laid over `kept` (arrays nested `depth` deep): value's entries where it has them, kept's beyond. */
function overlay(kept, value, depth) {
  if (!Array.isArray(kept)) return value;
  const out = kept.slice();
  value.forEach((x, i) => {
    out[i] = depth > 1 && Array.isArray(x) ? overlay(kept[i], x, depth - 1) : x;
  });
  return out;
}

/**
 * An array of `sizes[0]` (× `sizes[1]`) entries: the model's `value` where it has
 * them, else the shelf's `kept`, else `fill(i)`.
 */
function sized(value, kept, sizes, fill) {
  const [rows, cols] = sizes;
  const has = (a, i) => Array.isArray(a) && i < a.length && a[i] !== undefined;
  return Array.from({ length: rows }, (_, i) => {
    if (cols === undefined) return has(value, i) ? value[i] : has(kept, i) ? structuredClone(kept[i]) : fill(i);
    return Array.from({ length: cols }, (_, j) =>
      has(value?.[i], j) ? value[i][j] : has(kept?.[i], j) ? structuredClone(kept[i][j]) : 0,
    );
  });
}

/**
 * Resize every member of the model to the dimensions `dims`. New entries come from
 * `shelf` where a smaller size put them (so growing back restores what shrinking
 * removed), else are 0 (names y1…, z1…; a schedule entry null: always). A new
 * measurement (not one from the shelf) measures the first state no row of C measures
 * yet: an all-zero row with no noise would make the innovation covariance singular.
 */
export function resize(model, dims, shelf = new Shelf()) {
  const before = dimensions(model);
  shelf.keep(model);
  const removed = removedNames(model, before, dims);
  for (const member of MEMBERS) {
    const holder = holderOf(model, member);
    if (!holder) continue;
    const key = lastKey(member);
    if (!Array.isArray(holder[key]) && !member.create?.(model)) continue;
    holder[key] = sized(holder[key], shelf.get(member), member.axes.map((x) => dims[x]), fillOf(member));
  }
  const m = model.measurement;
  const keptC = shelf.members.get('measurement.c');
  for (let j = before.n; j < dims.n && dims.N > 0; j++) {
    if (keptC?.[j] === undefined) m.c[j][firstUnmeasured(m.c.slice(0, j), dims.N)] = 1;
  }
  if (Array.isArray(m.pairs)) {
    const gone = (p) => removed.states.includes(p?.state) || removed.measurements.includes(p?.measurement);
    shelf.pairs.push(...m.pairs.filter(gone));
    m.pairs = m.pairs.filter((p) => !gone(p));
    const back = shelf.pairs.filter((p) => pairFits(model, p));
    m.pairs.push(...back);
    shelf.pairs = shelf.pairs.filter((p) => !back.includes(p));
  }
}

/** The names of the states and measurements beyond `dims` (those a resize to it removes). */
function removedNames(model, before, dims) {
  return {
    states: (model.system?.states ?? []).slice(Math.min(dims.N, before.N)),
    measurements: (model.measurement?.names ?? []).slice(Math.min(dims.n, before.n)),
  };
}

/** Whether `pair` names a state and a measurement of the model and is not listed yet. */
function pairFits(model, pair) {
  const m = model.measurement;
  return (
    (model.system.states ?? []).includes(pair.state) &&
    (m.names ?? []).includes(pair.measurement) &&
    !m.pairs.some((p) => p?.state === pair.state && p?.measurement === pair.measurement)
  );
}

/** The first column of `rows` (C's rows) that is 0 in every row; 0 when none is. */
function firstUnmeasured(rows, N) {
  const zero = (x) => x === undefined || x === null || x === 0 || x === '0' || x === '';
  for (let k = 0; k < N; k++) if (rows.every((row) => zero(row?.[k]))) return k;
  return 0;
}

/**
 * Whether a resize from `before` (the model as it was) to `after` removed nothing but
 * what growing back would create anew: new names, zeros, a new measurement's 1 in C.
 */
export function removedOnlyDefaults(before, after) {
  const fresh = structuredClone(after);
  resize(fresh, dimensions(before));
  return JSON.stringify(fresh) === JSON.stringify(before);
}

/** The members of the model indexed by dimension `axis` ('N', 'n', 'L', 'M') that it has, by path. */
export function membersAlong(model, axis) {
  return MEMBERS.filter((member) => member.axes.includes(axis) && Array.isArray(holderOf(model, member)?.[lastKey(member)])).map(pathOf);
}

/** `array` (nested as `axes` says) with index `k` of dimension `axis` spliced out at every depth it indexes. */
function spliceOut(array, axes, axis, k) {
  if (!Array.isArray(array)) return;
  if (axes[1] === axis) for (const row of array) if (Array.isArray(row)) row.splice(k, 1);
  if (axes[0] === axis) array.splice(k, 1);
}

/**
 * Remove state (`axis` 'N') or measurement ('n') number `k` (from 0) from every member,
 * and the pairs that name it; the shelf's entries beyond the model's extent move with
 * the model's. Returns the removed pairs.
 */
export function removeAt(model, axis, k, shelf) {
  const names = axis === 'N' ? model.system.states : model.measurement.names;
  const name = names?.[k];
  for (const member of MEMBERS) {
    if (!member.axes.includes(axis)) continue;
    spliceOut(holderOf(model, member)?.[lastKey(member)], member.axes, axis, k);
    spliceOut(shelf?.get(member), member.axes, axis, k);
  }
  const m = model.measurement;
  if (!Array.isArray(m.pairs)) return [];
  const field = axis === 'N' ? 'state' : 'measurement';
  const removed = m.pairs.filter((p) => p?.[field] === name);
  m.pairs = m.pairs.filter((p) => p?.[field] !== name);
  return removed;
}

/**
 * Put back state or measurement number `k` that `removeAt` took out of `before` (the
 * model as it was then): its entries in every member the model has, from `before`, and
 * `pairs`, the pairs removed with it. The model's other dimensions must be as they were.
 */
export function restoreAt(model, axis, k, before, pairs, shelf) {
  for (const member of MEMBERS) {
    if (!member.axes.includes(axis)) continue;
    const key = lastKey(member);
    const array = holderOf(model, member)?.[key];
    if (!Array.isArray(array)) continue;
    const old = holderOf(before, member)?.[key];
    const fill = fillOf(member);
    const kept = shelf?.get(member);
    if (member.axes[1] === axis) {
      // A column: row i here is row i (or i + 1, past k, when rows index this dimension too) there.
      array.forEach((row, i) => {
        const from = member.axes[0] === axis && i >= k ? i + 1 : i;
        if (Array.isArray(row)) row.splice(k, 0, old?.[from]?.[k] ?? 0);
      });
      if (Array.isArray(kept)) for (const row of kept) if (Array.isArray(row)) row.splice(k, 0, undefined);
    }
    if (member.axes[0] === axis) {
      const zeros = () => Array.from({ length: array[0]?.length ?? 0 }, () => 0);
      array.splice(k, 0, old?.[k] !== undefined ? structuredClone(old[k]) : member.axes.length > 1 ? zeros() : fill(k));
      if (Array.isArray(kept)) kept.splice(k, 0, undefined);
    }
  }
  const m = model.measurement;
  if (Array.isArray(m.pairs)) m.pairs.push(...pairs.filter((p) => pairFits(model, p)));
}
