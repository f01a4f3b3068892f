// A TTES client of the wire, written from docs/PROTOCOL.md alone: framing (§2, over WebSocket §2.1), HELLO /
// ACCEPT (§3), the control messages it needs (§5), entity requests (§6), update tables and their quantisation
// (§7, §7.1), FIGURE (§7.2) and JOINT_UPDATES versions 1 (§8.1–8.3) and 2 (§8.5). No three.js here. msgpack
// (§1) is @msgpack/msgpack's ESM build, vendored (client_stub/web/vendor.py); a relative path, so node runs this too.
import { decode, encode } from "../vendor/msgpack/index.mjs";

export const T = {
  HELLO: 0x01, ACCEPT: 0x02, ERROR: 0x03, GOODBYE: 0x04, PING: 0x05, PONG: 0x06, JCL: 0x10, READY: 0x11,
  STATUS: 0x12, SETTINGS: 0x13, CREATE_SOLDIER: 0x20, SOLDIER_CREATED: 0x21, REMOVE_SOLDIER: 0x22,
  SUBSCRIBE: 0x23, UNSUBSCRIBE: 0x24, REQUEST_FULL_UPDATE: 0x25, SOLDIER_REMOVED: 0x26, REACT: 0x27,
  REQUEST_FIGURE: 0x28, ENTITY_REQUESTS: 0x30, UPDATE_TABLE: 0x31, JOINT_UPDATES: 0x32, FIGURE: 0x33,
};
export const APPEARANCE = { DEAD: 1, UPRIGHT: 2, KNEEL: 3, PRONE: 4, CRAWL: 5 };
export const WEAPON = { STOWED: 0, DEPLOYED: 1, FIRING: 2 };
export const MAX_FRAME = 1 << 24; // what we accept: FIGURE with meshes is 27 kB for DI.fig + AK-47
const MAGIC = [0x54, 0x54, 0x45, 0x53]; // "TTES"

export function frame(type, payload) {
  const out = new Uint8Array(5 + payload.length);
  new DataView(out.buffer).setUint32(0, payload.length + 1);
  out[4] = type;
  out.set(payload, 5);
  return out;
}

export function hello(name, role, version, extra = {}) {
  const body = encode({ name, role, max_frame: MAX_FRAME, ...extra });
  const p = new Uint8Array(6 + body.length);
  p.set(MAGIC);
  p[4] = version >> 8; p[5] = version & 0xff;
  p.set(body, 6);
  return frame(T.HELLO, p);
}

export const control = (type, body) => frame(type, encode(body));

// §6: count u16, then 33-byte rows {index, appearance, weapon, velocity[3], heading, position[3], immediate}
export function entityRequests(rows) {
  const p = new Uint8Array(2 + 33 * rows.length);
  const v = new DataView(p.buffer);
  v.setUint16(0, rows.length);
  rows.forEach((r, k) => {
    const o = 2 + 33 * k;
    v.setUint16(o, r.index);
    p[o + 2] = r.appearance;
    p[o + 3] = r.weapon;
    [...r.velocity, r.heading, ...r.position].forEach((x, i) => v.setFloat32(o + 4 + 4 * i, x));
    p[o + 32] = r.immediate ? 1 : 0;
  });
  return frame(T.ENTITY_REQUESTS, p);
}

// §2: frames out of a byte stream, whatever the message boundaries
export class Deframer {
  constructor() { this.buf = new Uint8Array(0); }
  push(bytes) {
    const b = new Uint8Array(this.buf.length + bytes.length);
    b.set(this.buf); b.set(bytes, this.buf.length);
    this.buf = b;
    const frames = [];
    let at = 0;
    while (this.buf.length - at >= 4) {
      const n = new DataView(this.buf.buffer, at).getUint32(0);
      if (n === 0 || n > MAX_FRAME) throw new Error(`frame length ${n}`);
      if (this.buf.length - at < 4 + n) break;
      frames.push({ type: this.buf[at + 4], payload: this.buf.slice(at + 5, at + 4 + n) });
      at += 4 + n;
    }
    this.buf = this.buf.slice(at);
    return frames;
  }
}

export function parseMessage(type, payload) {
  if (type === T.ACCEPT) {
    const version = (payload[4] << 8) | payload[5];
    return { version, ...decode(payload.subarray(6)) };
  }
  if (type === T.JOINT_UPDATES) return payload;
  return decode(payload);
}

// §7: an update table flattened into fields; the joint entries' DOFs are the pose's columns
export class UpdateTable {
  constructor(msg) {
    this.id = msg.table; this.figure = msg.figure; this.weapon = msg.weapon;
    this.entries = msg.entries.map(([index, name, kind, ndofs, quant]) => ({ index, name, kind, ndofs, quant }));
    this.fields = []; // {entry, bits, lo, step, qidx}
    this.dofColumn = {}; // joint entry -> its first DOF column
    this.figureSlot = {}; // figure entry -> its index among the figures
    let column = 0, figures = 0;
    for (const e of this.entries) {
      e.first = this.fields.length;
      if (e.kind === "joint") {
        this.dofColumn[e.index] = column; column += e.ndofs;
        for (const [, lo, hi, bits] of e.quant) this.fields.push({ bits, lo, step: (hi - lo) / 2 ** bits });
      } else {
        this.figureSlot[e.index] = figures++;
        const [plo, phi, pbits, qbits] = e.quant;
        for (let i = 0; i < 3; i++) this.fields.push({ bits: pbits, lo: plo, step: (phi - plo) / 2 ** pbits });
        this.fields.push({ bits: 2, lo: 0, step: 1, qidx: true });
        for (let i = 0; i < 3; i++) this.fields.push({ bits: qbits, lo: -Math.SQRT1_2, step: Math.SQRT2 / 2 ** qbits });
      }
      e.count = this.fields.length - e.first;
    }
    this.ndofs = column; this.nfigures = figures;
    this.soldiers = new Map(); // index -> {cur, before, tick}
  }

  // the soldier's pose: {dofs: Float64Array, figures: [{position:[x,y,z], quaternion:[w,x,y,z]}]}
  pose(index) {
    const s = this.soldiers.get(index);
    if (!s) return null;
    const dofs = new Float64Array(this.ndofs), figures = [];
    for (const e of this.entries) {
      const v = (k) => this.fields[e.first + k].lo + s.cur[e.first + k] * this.fields[e.first + k].step;
      if (e.kind === "joint") for (let k = 0; k < e.ndofs; k++) dofs[this.dofColumn[e.index] + k] = v(k);
      else {
        const c = [v(4), v(5), v(6)];
        const largest = Math.sqrt(Math.max(0, 1 - c[0] ** 2 - c[1] ** 2 - c[2] ** 2));
        const q = [...c];
        q.splice(s.cur[e.first + 3], 0, largest);
        const n = Math.hypot(...q);
        figures.push({ name: e.name, position: [v(0), v(1), v(2)], quaternion: q.map((x) => x / n) });
      }
    }
    return { dofs, figures };
  }
}

class Bits {
  constructor(bytes, at) { this.b = bytes; this.bit = at * 8; }
  read(w) {
    let v = 0;
    for (let i = 0; i < w; i++, this.bit++) v = v * 2 + ((this.b[this.bit >> 3] >> (7 - (this.bit & 7))) & 1);
    return v;
  }
  signed(w) { const v = this.read(w); return v >= 2 ** (w - 1) ? v - 2 ** w : v; }
  byte() { return Math.ceil(this.bit / 8); }
}

// §8: apply one JOINT_UPDATES payload (version 1 or 2) to its table; the indices it carried
export function applyJointUpdates(tables, payload, version) {
  const v = new DataView(payload.buffer, payload.byteOffset, payload.byteLength);
  const table = tables.get(v.getUint16(0));
  if (!table) throw new Error(`JOINT_UPDATES of table ${v.getUint16(0)}: never sent`);
  const tick = v.getUint32(2), n = v.getUint16(6), E = table.entries.length;
  const indices = [];
  for (let j = 0; j < n; j++) indices.push(v.getUint16(8 + 2 * j));
  const head = new Bits(payload, 8 + 2 * n);
  const heads = indices.map(() => ({ mode: head.read(version === 1 ? 4 : 1), mask: Array.from({ length: E }, () => head.read(1)) }));
  let widths = null, start = head.byte();
  if (version >= 2) { // §8.5: a width nibble per present entry of every delta soldier
    widths = new Bits(payload, start);
    start += Math.ceil(heads.reduce((a, h) => a + (h.mode ? h.mask.reduce((x, y) => x + y, 0) : 0), 0) / 2);
  }
  const fields = new Bits(payload, start);
  indices.forEach((index, j) => {
    const { mode, mask } = heads[j];
    let s = table.soldiers.get(index);
    if (!s) {
      s = { cur: new Int32Array(table.fields.length), before: new Int32Array(table.fields.length), tick: -1 };
      table.soldiers.set(index, s);
    }
    const predict = version >= 2 && s.tick === ((tick - 1) >>> 0);
    const next = Int32Array.from(s.cur), before = Int32Array.from(s.cur);
    table.entries.forEach((e, k) => {
      if (!mask[k]) return;
      const w = version >= 2 ? (mode ? widths.read(4) : 0) : mode;
      for (let f = e.first; f < e.first + e.count; f++) {
        const fd = table.fields[f];
        if (w === 0) { next[f] = fields.read(fd.bits); before[f] = next[f]; continue; }
        if (fd.qidx) continue;
        const p = predict ? 2 * s.cur[f] - s.before[f] : s.cur[f];
        next[f] = (version >= 2 ? p : s.cur[f]) + fields.signed(w);
      }
    });
    s.before = version >= 2 ? before : next; s.cur = next; s.tick = tick;
  });
  return { table, tick, indices };
}
