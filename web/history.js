// The editor's Undo and Redo: a history of committed edits, each stored as the
// difference it made to the model's JSON (not as snapshots: a 200-state model's JSON
// is about 1 MB, and an edit of one cell is a few bytes of difference).
//
// A difference is a list of changes at paths ([key or index, …] from the model's
// root): a value replaced ({path, before, after}, each the value's JSON text, or
// undefined for a member absent on that side), or an object's members reordered
// ({path, order: {before, after}}, the keys in JSON order; a member removed and given
// back must come back in its place, or the JSON would differ). Arrays of one length
// are compared entry by entry; an array that changed length is replaced whole.

const isObject = (x) => x !== null && typeof x === 'object' && !Array.isArray(x);
/** An object's keys as JSON writes them (a member set to undefined is not written). */
const keysOf = (o) => Object.keys(o).filter((k) => o[k] !== undefined);

/** The changes that turn `before` into `after` (JSON values; `after` may hold undefined, as JSON.stringify reads it). */
export function diff(before, after) {
  const out = [];
  const path = [];
  const walk = (b, a) => {
    if (b === a) return;
    if (Array.isArray(b) && Array.isArray(a) && b.length === a.length) {
      for (let i = 0; i < b.length; i++) {
        const [x, y] = [b[i], a[i]];
        if (x === y && (x === null || typeof x !== 'object')) continue; // the common case, without a push
        path.push(i);
        walk(x, y);
        path.pop();
      }
      return;
    }
    if (isObject(b) && isObject(a)) {
      const [bk, ak] = [keysOf(b), keysOf(a)];
      const common = new Set(bk.filter((k) => Object.hasOwn(a, k) && a[k] !== undefined));
      // Any other set or order of members is recorded as such: a member given back is
      // added at the end, and must then move to its place.
      const added = ak.filter((k) => !common.has(k));
      if (bk.length !== ak.length || bk.some((k, i) => ak[i] !== k)) out.push({ path: path.slice(), order: { before: bk, after: ak } });
      for (const k of bk) {
        path.push(k);
        if (common.has(k)) walk(b[k], a[k]);
        else out.push({ path: path.slice(), before: JSON.stringify(b[k]), after: undefined });
        path.pop();
      }
      for (const k of added) out.push({ path: [...path, k], before: undefined, after: JSON.stringify(a[k]) });
      return;
    }
    const [x, y] = [JSON.stringify(b), JSON.stringify(a)];
    if (x !== y) out.push({ path: path.slice(), before: x, after: y });
  };
  walk(before, after);
  return out;
}

/**
 * Apply `changes` to `root` in place, each as it was on `side` ('before' or 'after');
 * returns the root (a new one only when the change is at the root itself).
 */
export function apply(root, changes, side) {
  const at = (path) => path.reduce((o, k) => o[k], root);
  for (const change of changes) {
    if (change.order) continue;
    const text = change[side];
    if (!change.path.length) {
      root = JSON.parse(text);
      continue;
    }
    const parent = at(change.path.slice(0, -1));
    const key = change.path[change.path.length - 1];
    if (text === undefined) delete parent[key];
    else parent[key] = JSON.parse(text);
  }
  // The members in their order on that side (after the values: a member given back is at the end).
  for (const change of changes) {
    if (!change.order) continue;
    const o = at(change.path);
    for (const k of change.order[side]) {
      if (!Object.hasOwn(o, k)) continue;
      const v = o[k];
      delete o[k];
      o[k] = v;
    }
  }
  return root;
}

/** A change's path as the editor's fields name it: ['system', 'a', 2, 3] → `system.a[2][3]`. */
export function pathText(path) {
  return path.map((k, i) => (typeof k === 'number' ? `[${k}]` : i ? `.${k}` : k)).join('');
}

/**
 * About the bytes of heap a change takes: its texts (one byte a character, as V8 keeps
 * ASCII), and the objects around them (the change, its path, the strings' headers:
 * measured at about 150 bytes for a cell's change).
 */
const changeBytes = (c) =>
  (c.order ? c.order.before.join('').length + c.order.after.join('').length : (c.before?.length ?? 0) + (c.after?.length ?? 0)) + 100 + 16 * c.path.length;

/** At most this many edits are kept… */
export const MAX_ENTRIES = 100;
/** …and at most this many bytes of their differences (and of the dimension shelves they keep); the oldest go first. */
export const MAX_BYTES = 24 * 1024 * 1024;

/**
 * The undo and redo stacks. An entry is {label, changes, focus, state: {before,
 * after}, bytes}: `state` is what the editor keeps besides the model (the shelf of
 * removed entries, the forms a switch left, its notes), as it was on either side.
 */
export class History {
  constructor() {
    this.done = [];
    this.undone = [];
    this.bytes = 0;
  }

  clear() {
    this.done = [];
    this.undone = [];
    this.bytes = 0;
  }

  /** Record an edit; a new edit clears what was undone. The oldest edits go beyond MAX_ENTRIES or MAX_BYTES (the newest always stays). */
  push(entry) {
    entry.bytes = entry.changes.reduce((n, c) => n + changeBytes(c), 0) + (entry.extraBytes ?? 0);
    for (const e of this.undone) this.bytes -= e.bytes;
    this.undone = [];
    this.done.push(entry);
    this.bytes += entry.bytes;
    while (this.done.length > 1 && (this.done.length > MAX_ENTRIES || this.bytes > MAX_BYTES)) this.bytes -= this.done.shift().bytes;
  }

  /** The edit to undo (moved to the redo stack), or null. */
  undo() {
    const entry = this.done.pop() ?? null;
    if (entry) this.undone.push(entry);
    return entry;
  }

  /** The edit to redo (moved back to the undo stack), or null. */
  redo() {
    const entry = this.undone.pop() ?? null;
    if (entry) this.done.push(entry);
    return entry;
  }

  get nextUndo() {
    return this.done[this.done.length - 1] ?? null;
  }

  get nextRedo() {
    return this.undone[this.undone.length - 1] ?? null;
  }
}
