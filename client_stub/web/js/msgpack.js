// The msgpack subset of docs/PROTOCOL.md §1: maps with string keys, str, int, float32/64, nil, bool, arrays.
// Written from the spec (https://msgpack.org), no library: the page has no build step but three.js.

export function encode(value) {
  const out = [];
  const bytes = (...b) => { for (const x of b) out.push(x & 0xff); };
  const u32 = (n) => bytes(n >>> 24, n >>> 16, n >>> 8, n);
  const text = new TextEncoder();
  const put = (v) => {
    if (v === null || v === undefined) bytes(0xc0);
    else if (v === false) bytes(0xc2);
    else if (v === true) bytes(0xc3);
    else if (typeof v === "number" && Number.isInteger(v) && Math.abs(v) < 2 ** 32) {
      if (v >= 0 && v < 128) bytes(v);
      else if (v < 0 && v >= -32) bytes(v & 0xff);
      else if (v >= 0) { bytes(0xce); u32(v); }
      else { bytes(0xd2); u32(v >>> 0); }
    } else if (typeof v === "number") {
      const b = new DataView(new ArrayBuffer(8));
      b.setFloat64(0, v);
      bytes(0xcb, ...new Uint8Array(b.buffer));
    } else if (typeof v === "string") {
      const s = text.encode(v);
      if (s.length < 32) bytes(0xa0 | s.length);
      else { bytes(0xdb); u32(s.length); }
      for (const c of s) out.push(c);
    } else if (Array.isArray(v)) {
      bytes(0xdd); u32(v.length);
      v.forEach(put);
    } else {
      const keys = Object.keys(v);
      bytes(0xdf); u32(keys.length);
      for (const k of keys) { put(k); put(v[k]); }
    }
  };
  put(value);
  return new Uint8Array(out);
}

export function decode(buf) {
  const view = new DataView(buf.buffer, buf.byteOffset, buf.byteLength);
  const text = new TextDecoder();
  let at = 0;
  const take = (n) => { const s = at; at += n; if (at > buf.length) throw new Error("msgpack: cut short"); return s; };
  const str = (n) => text.decode(buf.subarray(take(n), at));
  const arr = (n) => { const a = new Array(n); for (let i = 0; i < n; i++) a[i] = get(); return a; };
  const map = (n) => { const m = {}; for (let i = 0; i < n; i++) { const k = get(); m[k] = get(); } return m; };
  const get = () => {
    const t = buf[take(1)];
    if (t < 0x80) return t;
    if (t >= 0xe0) return t - 0x100;
    if ((t & 0xf0) === 0x80) return map(t & 0x0f);
    if ((t & 0xf0) === 0x90) return arr(t & 0x0f);
    if ((t & 0xe0) === 0xa0) return str(t & 0x1f);
    switch (t) {
      case 0xc0: return null;
      case 0xc2: return false;
      case 0xc3: return true;
      case 0xca: return view.getFloat32(take(4));
      case 0xcb: return view.getFloat64(take(8));
      case 0xcc: return view.getUint8(take(1));
      case 0xcd: return view.getUint16(take(2));
      case 0xce: return view.getUint32(take(4));
      case 0xcf: return Number(view.getBigUint64(take(8)));
      case 0xd0: return view.getInt8(take(1));
      case 0xd1: return view.getInt16(take(2));
      case 0xd2: return view.getInt32(take(4));
      case 0xd3: return Number(view.getBigInt64(take(8)));
      case 0xd9: return str(view.getUint8(take(1)));
      case 0xda: return str(view.getUint16(take(2)));
      case 0xdb: return str(view.getUint32(take(4)));
      case 0xdc: return arr(view.getUint16(take(2)));
      case 0xdd: return arr(view.getUint32(take(4)));
      case 0xde: return map(view.getUint16(take(2)));
      case 0xdf: return map(view.getUint32(take(4)));
      default: throw new Error(`msgpack: type 0x${t.toString(16)} not in the protocol`);
    }
  };
  const v = get();
  if (at !== buf.length) throw new Error("msgpack: bytes after the value");
  return v;
}
