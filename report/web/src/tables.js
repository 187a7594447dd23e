// The numbers beside the picture: header figures, the patch table, the selected patch's card,
// input, settings, stage times and uncovered regions.
import { DASH, area, bytes, count, isNum, mm, percent, plain, seconds } from './data.js';

export function h(tag, attrs = {}, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === null || v === undefined || v === false) continue;
    if (k === 'class') e.className = v;
    else if (k === 'style' && typeof v === 'object') Object.assign(e.style, v);
    else if (k.startsWith('on') && typeof v === 'function') e.addEventListener(k.slice(2), v);
    else if (k === 'dataset') Object.assign(e.dataset, v);
    else e.setAttribute(k, v === true ? '' : String(v));
  }
  for (const c of children.flat()) if (c !== null && c !== undefined && c !== false) e.append(c instanceof Node ? c : String(c));
  return e;
}

export const swatch = (colour, cls = 'swatch') => h('span', { class: cls, style: { background: colour } });

const signed = (v) => (isNum(v) ? (v > 0 ? '+' : '') + mm(v) : DASH);

// Holder clearance: "—" when not checked; a collision marked clearly.
export function holderCell(c) {
  if (!c || !c.checked) return h('span', { class: 'muted', title: 'holder not checked' }, DASH);
  if (c.holder_clear === false)
    return h('span', { class: 'badge bad', title: 'the holder collides with the part' }, '\u2716 collision', isNum(c.min_clearance) ? ` ${signed(c.min_clearance)}` : '');
  return h('span', { class: 'ok', title: 'holder clear of the part' }, '\u2714 ', mm(c.min_clearance));
}

export function holderText(c) {
  if (!c || !c.checked) return `${DASH} (not checked)`;
  const size = Array.isArray(c.holder) ? ` · holder L ${mm(c.holder[0])} × R ${mm(c.holder[1])}` : '';
  if (c.holder_clear === false) return `COLLISION, clearance ${signed(c.min_clearance)} mm${size}`;
  return `clear by ${mm(c.min_clearance)} mm${size}`;
}

const pair = (v) => (Array.isArray(v) ? `${mm(v[0])} / ${mm(v[1])}` : DASH);

export function patchTable(table, data, palette, onSelect) {
  const tbody = table.tBodies[0];
  tbody.replaceChildren();
  const tol = data.tolerance;
  data.patches.forEach((p, index) => {
    const e = p.error || {}, c = p.coverage || {};
    const gougeBad = isNum(e.max_gouge) && isNum(tol) && e.max_gouge > tol;
    const row = h('tr', { tabindex: 0, dataset: { index, patch: p.id }, onclick: () => onSelect(index),
      onkeydown: (ev) => { if (ev.key === 'Enter' || ev.key === ' ') { ev.preventDefault(); onSelect(index); } } },
      h('td', { class: 'id' }, swatch(palette.hex(p.id)), ` ${plain(p.id)}`),
      h('td', {}, plain(p.kind), p.tip === 'b' ? h('span', { class: 'muted', title: 'tip at b' }, ' (tip b)') : ''),
      h('td', { class: 'num' }, mm(p.length)),
      h('td', { class: 'num', title: 'radius of the tool profile at the a end / b end' }, pair(p.end_radius)),
      h('td', { class: 'num' }, mm(e.max)),
      h('td', { class: 'num' }, mm(e.rms)),
      h('td', { class: 'num' + (gougeBad ? ' bad-text' : ''), title: gougeBad ? 'deeper than the tolerance' : null }, mm(e.max_gouge)),
      h('td', { class: 'num' }, area(c.area)),
      h('td', { class: 'num' }, percent(c.fraction)),
      h('td', { class: 'num' }, isNum(c.adds) ? `+${percent(c.adds)}` : DASH),
      h('td', { class: 'num' }, holderCell(p.collision)));
    tbody.appendChild(row);
  });
  const cov = data.coverage || {};
  let covered = isNum(cov.total_area) && isNum(cov.uncovered_area) ? cov.total_area - cov.uncovered_area : null;
  // Rounding leaves ±1e-11 where nothing (or everything) is covered.
  if (covered !== null && Math.abs(covered) <= 1e-9 * Math.max(Math.abs(cov.total_area), 1)) covered = 0;
  table.tFoot.replaceChildren(h('tr', {},
    h('td', { colspan: 7 }, `${data.patches.length} patch${data.patches.length === 1 ? '' : 'es'} together`),
    h('td', { class: 'num' }, area(covered)),
    h('td', { class: 'num' }, percent(cov.fraction)),
    h('td', {}, ''), h('td', {}, '')));
}

// Key/value rows into a <table>.
export function kvTable(table, rows) {
  table.replaceChildren(h('tbody', {}, rows.map(([k, v, cls]) => h('tr', {}, h('th', {}, k), h('td', { class: cls || null }, v)))));
}

export function patchCard(p, palette, tolerance) {
  if (!p) return [h('p', { class: 'muted' }, 'No patch: the whole design is uncovered.')];
  const e = p.error || {}, c = p.coverage || {};
  const rows = [
    ['Kind', `${plain(p.kind)}, tip at ${plain(p.tip)}`],
    ['Length', `${mm(p.length)} mm`],
    ['Sphere radii d(0), d(1)', `${pair(p.sphere_radius)} mm`],
    ['Profile radius a / b', `${pair(p.end_radius)} mm`],
    ['Error max |e| / rms', `${mm(e.max)} / ${mm(e.rms)} mm`],
    ['Max gouge', `${mm(e.max_gouge)} mm`, isNum(e.max_gouge) && isNum(tolerance) && e.max_gouge > tolerance ? 'bad-text' : null],
    ['Covers', `${area(c.area)} mm² (${percent(c.fraction)}), adds ${isNum(c.adds) ? '+' + percent(c.adds) : DASH}`],
    ['Holder', holderText(p.collision), p.collision && p.collision.checked && p.collision.holder_clear === false ? 'bad-text' : null],
  ];
  return [
    h('div', { class: 'card-title' }, swatch(palette.hex(p.id)), ` Patch ${plain(p.id)}`),
    h('dl', { class: 'kv' }, rows.flatMap(([k, v, cls]) => [h('dt', {}, k), h('dd', { class: cls || null }, v)])),
  ];
}

export function inputRows(data) {
  const i = data.input || {};
  const tol = data.tolerance;
  const rel = isNum(tol) && isNum(i.bbox_diagonal) && i.bbox_diagonal > 0 ? ` (${(tol / i.bbox_diagonal).toExponential(1)} × diagonal)` : '';
  return [
    ['File', plain(i.path), 'path'],
    ['Format', plain(i.format).toUpperCase()],
    ['Size', isNum(i.bytes) ? `${bytes(i.bytes)} (${count(i.bytes)} bytes)` : DASH],
    ['Vertices', count(i.vertices)],
    ['Triangles', count(i.triangles)],
    ['Bounding-box diagonal', `${mm(i.bbox_diagonal)} mm`],
    ['Tolerance', `${mm(tol)} mm${rel}`],
  ];
}

export function settingsRows(data) {
  const s = data.settings && typeof data.settings === 'object' ? data.settings : {};
  return Object.entries(s).map(([k, v]) => [k, plain(v), typeof v === 'number' || Array.isArray(v) ? 'num' : null]);
}

export function timingTable(table, timing) {
  const entries = Object.entries(timing && typeof timing === 'object' ? timing : {});
  const total = isNum(timing && timing.total) ? timing.total : entries.reduce((s, [, v]) => s + (isNum(v) ? v : 0), 0);
  table.replaceChildren(h('tbody', {}, entries.map(([k, v]) => {
    const isTotal = k === 'total';
    const share = isNum(v) && total > 0 ? Math.min(v / total, 1) : 0;
    return h('tr', { class: isTotal ? 'total' : null },
      h('th', {}, k),
      h('td', { class: 'bar-cell' }, isTotal ? '' : h('span', { class: 'bar', style: { width: `${(share * 100).toFixed(1)}%` } })),
      h('td', { class: 'num' }, seconds(v)));
  })));
}

export function regionsTable(table, regions, onFocus, limit = 25) {
  const list = (Array.isArray(regions) ? regions : []).map((r, k) => ({ ...r, k }));
  list.sort((x, y) => (isNum(y.area) ? y.area : -1) - (isNum(x.area) ? x.area : -1));
  const shown = list.slice(0, limit);
  const body = h('tbody', {}, shown.map((r) => h('tr', {
    tabindex: 0, class: Array.isArray(r.centroid) && r.centroid.every(isNum) ? 'clickable' : null, title: 'click to look at this region',
    onclick: () => { if (Array.isArray(r.centroid) && r.centroid.every(isNum)) onFocus(r); },
  },
  h('td', { class: 'num' }, area(r.area)),
  h('td', { class: 'num mono' }, Array.isArray(r.centroid) ? r.centroid.map(mm).join(', ') : DASH),
  h('td', { class: 'num' }, count(r.vertices)))));
  const none = list.length === 0 ? h('tfoot', {}, h('tr', {}, h('td', { colspan: 3, class: 'muted' }, 'None: the whole surface is covered within tolerance.'))) : '';
  const foot = list.length > limit ? h('tfoot', {}, h('tr', {}, h('td', { colspan: 3, class: 'muted' }, `and ${list.length - limit} smaller regions`))) : '';
  table.replaceChildren(h('thead', {}, h('tr', {}, h('th', { class: 'num' }, 'area mm²'), h('th', { class: 'num' }, 'centroid x, y, z (mm)'), h('th', { class: 'num' }, 'vertices'))), body, foot || none);
  return list.length;
}
