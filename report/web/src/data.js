// Reading the run's data (format flank-report/1) out of the page: the JSON in
// <script id="flank-data">, its base64 little-endian typed arrays, and the formatting of
// numbers for the tables (null or non-finite numbers print as "—").

export const DASH = '\u2014';

export function readReportData(doc = document) {
  const element = doc.getElementById('flank-data');
  if (!element) throw new Error('report data missing: no <script id="flank-data"> in the page');
  const text = element.textContent.trim();
  if (!text || text.startsWith('/*FLANK'))
    throw new Error('report data missing: the page is the bare template, no run was spliced in');
  let data;
  try {
    data = JSON.parse(text);
  } catch (e) {
    throw new Error(`report data is not valid JSON: ${e.message}`);
  }
  if (!data || typeof data !== 'object') throw new Error('report data is not a JSON object');
  if (data.format !== 'flank-report/1')
    throw new Error(`report data has format ${JSON.stringify(data.format)}, this page reads flank-report/1`);
  if (!Array.isArray(data.patches)) data.patches = [];
  if (!data.design) throw new Error('report data has no design surface');
  return data;
}

// Little-endian hosts only (every browser platform in use); checked once.
const littleEndian = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;

// base64 → bytes: atob's binary string copied into a Uint8Array, whose buffer is then viewed
// as the wanted type. `count` elements are expected (checked).
function decodeBytes(b64, bytesPerElement, count, what) {
  if (b64 === null || b64 === undefined || b64 === '') {
    if (count) throw new Error(`${what}: ${count} values expected, none given`);
    return new Uint8Array(0);
  }
  if (typeof b64 !== 'string') throw new Error(`${what}: base64 string expected`);
  let s;
  try {
    s = atob(b64);
  } catch (e) {
    throw new Error(`${what}: invalid base64 (${e.message})`);
  }
  const n = s.length;
  if (n % bytesPerElement !== 0)
    throw new Error(`${what}: ${n} bytes is not a whole number of ${bytesPerElement}-byte values`);
  if (Number.isFinite(count) && n / bytesPerElement !== count)
    throw new Error(`${what}: ${n / bytesPerElement} values, ${count} expected`);
  const bytes = new Uint8Array(n);
  for (let i = 0; i < n; ++i) bytes[i] = s.charCodeAt(i);
  return bytes;
}

function view(Type, b64, count, what) {
  if (!littleEndian) throw new Error('this page needs a little-endian machine');
  const bytes = decodeBytes(b64, Type.BYTES_PER_ELEMENT, count, what);
  return new Type(bytes.buffer, 0, bytes.length / Type.BYTES_PER_ELEMENT);
}

export const float32 = (b64, count, what) => view(Float32Array, b64, count, what);
export const uint32 = (b64, count, what) => view(Uint32Array, b64, count, what);
export const int32 = (b64, count, what) => view(Int32Array, b64, count, what);

const whole = (v) => (Number.isInteger(v) && v >= 0 ? v : NaN);

// A triangle mesh {vertices, triangles, position, index, ...}: typed arrays, with the triangles
// that reference a missing or non-finite vertex dropped and non-finite vertices moved onto a
// finite one (three.js's bounds would be NaN otherwise).
export function decodeMesh(m, what, extra = {}) {
  const nv = whole(m.vertices), nt = whole(m.triangles);
  if (Number.isNaN(nv) || Number.isNaN(nt)) throw new Error(`${what}: vertex and triangle counts missing`);
  const position = float32(m.position, nv * 3, `${what} positions`);
  let index = uint32(m.index, nt * 3, `${what} triangles`);
  const out = { vertices: nv, triangles: nt, position, index, dropped: 0 };
  for (const [key, decode] of Object.entries(extra)) out[key] = decode(m[key], nv, `${what} ${key}`);

  let bad = null, firstGood = -1;
  for (let v = 0; v < nv; ++v) {
    const x = position[3 * v], y = position[3 * v + 1], z = position[3 * v + 2];
    if (Number.isFinite(x) && Number.isFinite(y) && Number.isFinite(z)) {
      if (firstGood < 0) firstGood = v;
    } else {
      (bad ||= new Uint8Array(nv))[v] = 1;
    }
  }
  let badIndex = false;
  for (let i = 0; i < index.length; ++i) if (index[i] >= nv) { badIndex = true; break; }
  if (bad || badIndex) {
    const kept = new Uint32Array(index.length);
    let k = 0;
    for (let f = 0; f < nt; ++f) {
      const i0 = index[3 * f], i1 = index[3 * f + 1], i2 = index[3 * f + 2];
      if (i0 >= nv || i1 >= nv || i2 >= nv) continue;
      if (bad && (bad[i0] || bad[i1] || bad[i2])) continue;
      kept[k++] = i0; kept[k++] = i1; kept[k++] = i2;
    }
    out.dropped = nt - k / 3;
    index = kept.slice(0, k);
    out.index = index;
    if (bad) {
      const g = Math.max(firstGood, 0);
      for (let v = 0; v < nv; ++v)
        if (bad[v]) {
          position[3 * v] = firstGood < 0 ? 0 : position[3 * g];
          position[3 * v + 1] = firstGood < 0 ? 0 : position[3 * g + 1];
          position[3 * v + 2] = firstGood < 0 ? 0 : position[3 * g + 2];
        }
    }
  }
  return out;
}

export function decodeDesign(data) {
  return decodeMesh(data.design, 'design surface', { patch: int32 });
}

export function decodeEnvelope(patch) {
  if (!patch.envelope) return null;
  return decodeMesh(patch.envelope, `patch ${patch.id} envelope`, { error: float32 });
}

// Axis end points a(t_i), b(t_i), i = 0..steps; null when the patch has no usable motion.
export function decodeMotion(patch) {
  const m = patch.motion;
  if (!m) return null;
  const steps = whole(m.steps);
  if (Number.isNaN(steps)) return null;
  const a = float32(m.a, (steps + 1) * 3, `patch ${patch.id} motion a`);
  const b = float32(m.b, (steps + 1) * 3, `patch ${patch.id} motion b`);
  for (let i = 0; i < a.length; ++i) if (!Number.isFinite(a[i]) || !Number.isFinite(b[i])) return null;
  return { steps, a, b };
}

// The meridian [[z, r], ...] with its unusable points left out.
export function profilePoints(patch) {
  const out = [];
  for (const p of patch.profile || []) {
    if (Array.isArray(p) && isNum(p[0]) && isNum(p[1])) out.push([p[0], Math.max(p[1], 0)]);
  }
  return out;
}

// ---- formatting ----

export const isNum = (v) => typeof v === 'number' && Number.isFinite(v);

// A length in mm at a precision that suits its size.
export function mm(v) {
  if (!isNum(v)) return DASH;
  const a = Math.abs(v);
  if (a === 0) return '0';
  if (a >= 1000) return v.toFixed(0);
  if (a >= 100) return v.toFixed(1);
  if (a >= 1) return v.toFixed(3);
  if (a >= 1e-4) return v.toPrecision(3);
  return v.toExponential(2);
}

export function area(v) {
  if (!isNum(v)) return DASH;
  const a = Math.abs(v);
  if (a >= 100) return v.toFixed(0);
  if (a >= 1) return v.toFixed(2);
  return v.toPrecision(3);
}

export function percent(v, digits = 1) {
  return isNum(v) ? `${(100 * v).toFixed(digits)}%` : DASH;
}

export function count(v) {
  if (!isNum(v)) return DASH;
  // Thin-space thousands grouping, independent of the browser's locale.
  return String(Math.round(v)).replace(/\B(?=(\d{3})+(?!\d))/g, '\u2009');
}

export function bytes(v) {
  if (!isNum(v)) return DASH;
  const units = ['KiB', 'MiB', 'GiB', 'TiB'];
  if (v < 1024) return `${v} B`;
  let x = v, u = -1;
  while (x >= 1024 && u < units.length - 1) { x /= 1024; ++u; }
  return `${x >= 100 ? x.toFixed(0) : x >= 10 ? x.toFixed(1) : x.toFixed(2)} ${units[u]}`;
}

export function seconds(v) {
  if (!isNum(v)) return DASH;
  if (v >= 100) return `${v.toFixed(0)} s`;
  if (v >= 1) return `${v.toFixed(2)} s`;
  if (v >= 1e-3) return `${(v * 1e3).toFixed(1)} ms`;
  return `${(v * 1e6).toFixed(0)} µs`;
}

// A number as given, but with at most 6 significant digits (settings hold computed values such
// as 0.01915307665379, of which the last digits say nothing).
export function short(v) {
  if (!isNum(v)) return DASH;
  if (Number.isInteger(v)) return String(v);
  const a = Math.abs(v);
  if (a !== 0 && (a < 1e-4 || a >= 1e9)) return v.toExponential(5).replace(/\.?0+e/, 'e');
  return String(Number(v.toPrecision(6)));
}

export function plain(v) {
  if (v === null || v === undefined) return DASH;
  if (typeof v === 'number') return short(v);
  if (typeof v === 'boolean') return v ? 'yes' : 'no';
  if (Array.isArray(v)) return v.map(plain).join(', ');
  if (typeof v === 'object') return JSON.stringify(v);
  return String(v);
}
