// Small inline SVG plots: the coverage after 1, 2, …, k patches, and each cutter's meridian
// profile r(z).
import { isNum, mm, percent, profilePoints, DASH } from './data.js';

const SVG = 'http://www.w3.org/2000/svg';

function el(name, attrs = {}, parent = null) {
  const e = document.createElementNS(SVG, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (parent) parent.appendChild(e);
  return e;
}

function text(parent, x, y, s, attrs = {}) {
  const t = el('text', { x, y, ...attrs }, parent);
  t.textContent = s;
  return t;
}

// "Nice" tick values covering [lo, hi], about `n` of them.
function ticks(lo, hi, n = 4) {
  if (!(hi > lo)) return [lo];
  const raw = (hi - lo) / n;
  const p = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * p).find((s) => s >= raw) || 10 * p;
  const out = [];
  for (let v = Math.ceil(lo / step - 1e-9) * step; v <= hi + step * 1e-9; v += step) out.push(+v.toPrecision(12));
  return out;
}

const tickLabel = (v) => {
  const a = Math.abs(v);
  if (a === 0) return '0';
  if (a >= 100) return v.toFixed(0);
  if (a >= 10) return String(+v.toFixed(1));
  if (a >= 1) return String(+v.toFixed(2));
  return String(+v.toPrecision(2));
};

// Coverage curve: fraction of the design covered after the first 1..k patches.
// `colourOf(k)` gives patch k's colour for its marker; `target` (0..1 or null) is drawn dashed.
export function coveragePlot(curve, colourOf, { target = null, onPick = null } = {}) {
  const W = 340, H = 190, L = 44, R = 14, T = 14, B = 34;
  const svg = el('svg', { viewBox: `0 0 ${W} ${H}`, class: 'plot coverage-plot', role: 'img', 'aria-label': 'coverage after 1..k patches' });
  const values = (curve || []).map((c) => (isNum(c) ? c : null));
  const k = values.length;
  const xOf = (i) => L + (k <= 1 ? (W - L - R) / 2 : ((i) / (k - 1)) * (W - L - R));
  const yOf = (f) => T + (1 - f) * (H - T - B);
  const grid = el('g', { class: 'grid' }, svg);
  for (const f of [0, 0.25, 0.5, 0.75, 1]) {
    el('line', { x1: L, x2: W - R, y1: yOf(f), y2: yOf(f) }, grid);
    text(svg, L - 6, yOf(f) + 3.5, `${f * 100}%`, { class: 'tick', 'text-anchor': 'end' });
  }
  el('line', { x1: L, x2: W - R, y1: yOf(0), y2: yOf(0), class: 'axis' }, svg);
  el('line', { x1: L, x2: L, y1: T, y2: yOf(0), class: 'axis' }, svg);
  text(svg, (L + W - R) / 2, H - 4, 'patches used', { class: 'label', 'text-anchor': 'middle' });
  if (isNum(target) && target > 0 && target <= 1) {
    el('line', { x1: L, x2: W - R, y1: yOf(target), y2: yOf(target), class: 'target' }, svg);
    text(svg, W - R - 2, yOf(target) - 4, `target ${percent(target, 0)}`, { class: 'tick target-label', 'text-anchor': 'end' });
  }
  if (k === 0) {
    text(svg, (L + W - R) / 2, (T + H - B) / 2, 'no patches', { class: 'empty', 'text-anchor': 'middle' });
    return svg;
  }
  const step = Math.max(1, Math.ceil(k / 12));
  for (let i = 0; i < k; i += step) text(svg, xOf(i), yOf(0) + 14, String(i + 1), { class: 'tick', 'text-anchor': 'middle' });
  if (k > 1 && (k - 1) % step !== 0) text(svg, xOf(k - 1), yOf(0) + 14, String(k), { class: 'tick', 'text-anchor': 'middle' });
  // Area under the curve, the curve, markers.
  const pts = values.map((v, i) => (v === null ? null : [xOf(i), yOf(Math.min(Math.max(v, 0), 1))])).filter(Boolean);
  if (pts.length) {
    if (pts.length > 1) {
      el('path', { d: `M${pts[0][0]},${yOf(0)} ` + pts.map((p) => `L${p[0]},${p[1]}`).join(' ') + ` L${pts[pts.length - 1][0]},${yOf(0)} Z`, class: 'area' }, svg);
      el('polyline', { points: pts.map((p) => p.join(',')).join(' '), class: 'curve' }, svg);
    }
  }
  values.forEach((v, i) => {
    if (v === null) return;
    const c = el('circle', { cx: xOf(i), cy: yOf(Math.min(Math.max(v, 0), 1)), r: 4.2, fill: colourOf(i), class: 'marker', 'data-index': i }, svg);
    const title = el('title', {}, c);
    title.textContent = `after ${i + 1} patch${i ? 'es' : ''}: ${percent(v, 2)}`;
    if (onPick) c.addEventListener('click', () => onPick(i));
  });
  const last = values[k - 1];
  if (last !== null) {
    const [x, y] = [xOf(k - 1), yOf(Math.min(Math.max(last, 0), 1))];
    text(svg, x - 6, y + (last > 0.85 ? 16 : -8), percent(last, 1), { class: 'value', 'text-anchor': 'end' });
  }
  return svg;
}

// One cutter's meridian profile r(z) (z along the axis from a toward b), r from 0 so that the
// shape keeps its proportions in r; the tip end is marked.
export function profilePlot(patch, colour) {
  const W = 220, H = 112, L = 30, R = 10, T = 8, B = 20;
  const svg = el('svg', { viewBox: `0 0 ${W} ${H}`, class: 'plot profile-plot', role: 'img', 'aria-label': `meridian profile of patch ${patch.id}` });
  const pts = profilePoints(patch);
  if (pts.length < 2) {
    text(svg, W / 2, H / 2, `no profile ${DASH}`, { class: 'empty', 'text-anchor': 'middle' });
    return svg;
  }
  let z0 = Infinity, z1 = -Infinity, r1 = 0;
  for (const [z, r] of pts) { z0 = Math.min(z0, z); z1 = Math.max(z1, z); r1 = Math.max(r1, r); }
  if (!(z1 > z0)) z1 = z0 + 1;
  const rTop = r1 > 0 ? r1 * 1.12 : 1;
  const xOf = (z) => L + ((z - z0) / (z1 - z0)) * (W - L - R);
  const yOf = (r) => T + (1 - r / rTop) * (H - T - B);
  const grid = el('g', { class: 'grid' }, svg);
  for (const r of ticks(0, rTop, 3)) {
    if (r > rTop) continue;
    el('line', { x1: L, x2: W - R, y1: yOf(r), y2: yOf(r) }, grid);
    text(svg, L - 5, yOf(r) + 3.5, tickLabel(r), { class: 'tick', 'text-anchor': 'end' });
  }
  for (const z of ticks(z0, z1, 4)) text(svg, xOf(z), H - B + 13, tickLabel(z), { class: 'tick', 'text-anchor': 'middle' });
  const line = pts.map(([z, r]) => `${xOf(z).toFixed(2)},${yOf(r).toFixed(2)}`);
  el('path', { d: `M${xOf(pts[0][0]).toFixed(2)},${yOf(0)} L${line.join(' L')} L${xOf(pts[pts.length - 1][0]).toFixed(2)},${yOf(0)} Z`, fill: colour, class: 'profile-fill' }, svg);
  el('polyline', { points: line.join(' '), stroke: colour, class: 'profile-line' }, svg);
  el('line', { x1: L, x2: W - R, y1: yOf(0), y2: yOf(0), class: 'axis' }, svg);
  el('line', { x1: L, x2: L, y1: T, y2: yOf(0), class: 'axis' }, svg);
  // The tool's tip end (where a machine expects the end face).
  const tipZ = patch.tip === 'b' ? pts.reduce((m, p) => Math.max(m, p[0]), -Infinity) : pts.reduce((m, p) => Math.min(m, p[0]), Infinity);
  text(svg, xOf(tipZ) + (patch.tip === 'b' ? -3 : 3), T + 9, 'tip', { class: 'tip', 'text-anchor': patch.tip === 'b' ? 'end' : 'start' });
  const title = el('title', {}, svg);
  title.textContent = `patch ${patch.id}: z ${mm(z0)}…${mm(z1)} mm, r up to ${mm(r1)} mm`;
  return svg;
}
