/*! three.js 0.187.0 (npm package three), inlined in this page by esbuild. Its licence:

The MIT License

Copyright © 2010-2026 three.js authors

Permission is hereby granted, free of charge, to any person obtaining a copy
of this software and associated documentation files (the "Software"), to deal
in the Software without restriction, including without limitation the rights
to use, copy, modify, merge, publish, distribute, sublicense, and/or sell
copies of the Software, and to permit persons to whom the Software is
furnished to do so, subject to the following conditions:

The above copyright notice and this permission notice shall be included in
all copies or substantial portions of the Software.

THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR
IMPLIED, INCLUDING BUT NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY,
FITNESS FOR A PARTICULAR PURPOSE AND NONINFRINGEMENT. IN NO EVENT SHALL THE
AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM, DAMAGES OR OTHER
LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM,
OUT OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN
THE SOFTWARE.
*/
// report.html's script: reads the run's data from the page, fills the tables and plots, and
// drives the 3D view. Sets document.body.dataset.ready = "1" once the first frame of the scene
// has been drawn; any failure is shown in the page and logged with console.error.
import { REVISION } from 'three';
import { DASH, area, decodeDesign, isNum, mm, percent, plain, readReportData } from './data.js';
import { ERROR_GRADIENT, NAN_GREY, Palette, toHex } from './colours.js';
import { coveragePlot, profilePlot } from './plots.js';
import { h, inputRows, kvTable, patchCard, patchTable, regionsTable, settingsRows, swatch, timingTable } from './tables.js';
import { Viewer } from './scene.js';

const $ = (id) => document.getElementById(id);
let failures = 0;

function showError(error, where) {
  failures += 1;
  const message = `${where ? where + ': ' : ''}${error && error.message ? error.message : String(error)}`;
  console.error(`flank report: ${message}`, error);
  const box = $('page-error');
  if (box) {
    box.hidden = false;
    box.append(h('div', {}, message));
  }
  document.body.dataset.error = '1';
}

// Runs one part of the page; a failure is reported and the other parts still run.
function part(where, fn) {
  try {
    return fn();
  } catch (e) {
    showError(e, where);
    return undefined;
  }
}

function header(data) {
  const input = data.input || {};
  const name = String(input.path || '').split(/[\\/]/).pop() || 'design';
  document.title = `flank ${plain(data.command)} · ${name}`;
  $('hdr-command').textContent = plain(data.command);
  $('hdr-file').textContent = name;
  $('hdr-file').title = plain(input.path);
  const cov = data.coverage || {};
  const stats = [
    ['Coverage', percent(cov.fraction)],
    ['Patches', String(data.patches.length)],
    ['Tolerance', `${mm(data.tolerance)} mm`],
    ['Uncovered', `${area(cov.uncovered_area)} mm²`],
    ['Time', data.timing_s && isNum(data.timing_s.total) ? `${data.timing_s.total.toFixed(1)} s` : DASH],
  ];
  $('hdr-stats').replaceChildren(...stats.map(([k, v]) => h('div', { class: 'stat' }, h('span', { class: 'stat-value' }, v), h('span', { class: 'stat-key' }, k))));
}

function legend(data, palette, select) {
  const cov = data.coverage || {};
  const items = data.patches.map((p, index) => h('li', { class: 'legend-item', dataset: { index }, onclick: () => select(index), title: `select patch ${p.id}` },
    swatch(palette.hex(p.id)), h('span', {}, `P${plain(p.id)} ${plain(p.kind)}`), h('span', { class: 'legend-num' }, percent(p.coverage && p.coverage.fraction))));
  const uncovered = isNum(cov.fraction) ? Math.min(Math.max(1 - cov.fraction, 0), 1) : null;
  items.push(h('li', { class: 'legend-item uncovered' }, swatch(toHex(palette.uncovered)), h('span', {}, 'uncovered'), h('span', { class: 'legend-num' }, percent(uncovered))));
  $('legend').replaceChildren(h('div', { class: 'overlay-title' }, 'Covering patch'), h('ul', {}, items));
}

function colourBar(saturation) {
  const s = saturation;
  const fmt = (v) => (v === 0 ? '0' : (v > 0 ? '+' : '\u2212') + mm(Math.abs(v)));
  $('colourbar').replaceChildren(
    h('div', { class: 'overlay-title' }, 'Signed error e (mm)'),
    h('div', { class: 'cb-bar', style: { background: ERROR_GRADIENT } }),
    h('div', { class: 'cb-ticks' }, [-s, -s / 2, 0, s / 2, s].map((v) => h('span', {}, fmt(v)))),
    h('div', { class: 'cb-ends' }, h('span', { class: 'gouge' }, '\u25c0 gouge (e < 0)'), h('span', { class: 'left' }, 'material left (e > 0) \u25b6')),
    h('div', { class: 'cb-nan' }, swatch(`rgb(${NAN_GREY.join(',')})`), ` no value (NaN) · saturates at ±${mm(s)} mm`));
}

const mark = (name) => performance.mark(`flank:${name}`);

function start() {
  mark('script');
  const data = readReportData();
  mark('parsed');
  const palette = new Palette(data);
  const patches = data.patches;
  let viewer = null;
  let selected = -1;

  part('header', () => header(data));
  part('input table', () => kvTable($('input-table'), inputRows(data)));
  part('settings table', () => kvTable($('settings-table'), settingsRows(data)));
  part('stage times', () => timingTable($('timing-table'), data.timing_s));

  const select = (index, { fromViewer = false } = {}) => {
    if (!(index >= 0 && index < patches.length)) index = -1;
    selected = index;
    $('patch-select').value = String(index);
    for (const row of $('patch-table').tBodies[0].rows) row.classList.toggle('selected', Number(row.dataset.index) === index);
    for (const li of document.querySelectorAll('#legend .legend-item')) li.classList.toggle('selected', li.dataset.index !== undefined && Number(li.dataset.index) === index);
    for (const card of document.querySelectorAll('#profiles .profile-card')) card.classList.toggle('selected', Number(card.dataset.index) === index);
    for (const m of document.querySelectorAll('.coverage-plot .marker')) m.classList.toggle('selected', Number(m.dataset.index) === index);
    part('patch card', () => $('patch-card').replaceChildren(...patchCard(patches[index], palette, data.tolerance)));
    if (viewer && !fromViewer) part('3D view', () => viewer.select(index));
  };

  part('patch table', () => patchTable($('patch-table'), data, palette, (i) => select(i)));
  part('coverage plot', () => {
    const cov = data.coverage || {};
    const s = data.settings || {};
    const target = isNum(s.coverage_target) ? s.coverage_target : isNum(s.coverage) ? s.coverage : null;
    $('coverage-plot').replaceChildren(coveragePlot(cov.curve, (i) => (patches[i] ? palette.hex(patches[i].id) : '#888'), { target, onPick: (i) => select(i) }));
    $('coverage-note').textContent = isNum(cov.total_area)
      ? `${percent(cov.fraction, 2)} of ${area(cov.total_area)} mm² within tolerance; ${area(cov.uncovered_area)} mm² uncovered in ${(cov.regions || []).length} region${(cov.regions || []).length === 1 ? '' : 's'}.`
      : '';
  });
  part('cutter profiles', () => {
    const box = $('profiles');
    if (!patches.length) { box.replaceChildren(h('p', { class: 'muted' }, 'No patches, no cutters.')); return; }
    box.replaceChildren(...patches.map((p, index) => h('figure', { class: 'profile-card', dataset: { index }, onclick: () => select(index), title: `select patch ${p.id}` },
      h('figcaption', {}, swatch(palette.hex(p.id)), h('b', {}, ` P${plain(p.id)} `), `${plain(p.kind)} · L ${mm(p.length)} · r ${Array.isArray(p.end_radius) ? `${mm(p.end_radius[0])}–${mm(p.end_radius[1])}` : DASH}`),
      profilePlot(p, palette.hex(p.id)))));
  });

  // Controls.
  const patchSelect = $('patch-select');
  patchSelect.replaceChildren(...(patches.length
    ? patches.map((p, index) => h('option', { value: index }, `Patch ${plain(p.id)} · ${plain(p.kind)} · ${percent(p.coverage && p.coverage.fraction)}`))
    : [h('option', { value: -1 }, 'no patches')]));
  const motionControls = ['patch-select', 'play', 't-slider', 'show-cutter', 'show-trajectory', 'show-holder', 'show-selected-only'];
  if (!patches.length) for (const id of motionControls) $(id).disabled = true;

  mark('tables');
  // The 3D view.
  let design;
  part('design surface', () => { design = decodeDesign(data); });
  mark('decoded');
  if (design) {
    part('3D view', () => {
      // A click on the surface: which patch, and in the error view the error there.
      const onPick = (r) => {
        const out = $('pick-readout');
        if (!r) { out.hidden = true; return; }
        out.hidden = false;
        const p = r.point.map(mm).join(', ');
        if (r.error !== undefined) {
          const patch = patches[r.patchIndex];
          const e = r.error;
          const what = !isNum(e) ? 'no value' : e < 0 ? 'gouge' : e > 0 ? 'material left' : 'exact';
          out.replaceChildren(h('b', {}, `Patch ${plain(patch && patch.id)} envelope`), h('br'), `e = ${isNum(e) ? (e > 0 ? '+' : '') + mm(e) : DASH} mm (${what})`, h('br'), h('span', { class: 'muted' }, p));
          select(r.patchIndex);
        } else {
          const index = patches.findIndex((q) => q.id === r.patchId);
          out.replaceChildren(h('b', {}, r.patchId >= 0 ? `Patch ${r.patchId}` : 'Uncovered'), h('br'), h('span', { class: 'muted' }, p));
          if (index >= 0) select(index);
        }
      };
      try {
        viewer = new Viewer($('viewer'), data, design, palette, { onPick });
      } catch (e) {
        if (/WebGL/i.test(String(e && e.message))) throw new Error(`this browser gave the page no WebGL context, so the 3D view cannot be drawn (is hardware acceleration or WebGL turned off?): ${e.message}`);
        throw e;
      }
      mark('viewer');
      if (design.dropped) console.warn(`flank report: ${design.dropped} design triangles with invalid vertices left out`);
      legend(data, palette, (i) => select(i));
      let first = true;
      viewer.onFrame = () => {
        if (!first) return;
        first = false;
        mark('first-frame');
        document.body.dataset.readyMs = performance.now().toFixed(1);
        document.body.dataset.ready = '1';
      };
      const slider = $('t-slider');
      const showT = (t) => { $('t-value').textContent = t.toFixed(3); };
      viewer.onTick = (t) => { slider.value = String(Math.round(t * 1000)); showT(t); };
      slider.addEventListener('input', () => { const t = Number(slider.value) / 1000; part('cutter', () => viewer.setT(t)); showT(t); });
      const play = $('play');
      const setPlaying = (on) => {
        viewer.setPlaying(on);
        play.textContent = on ? '\u275a\u275a Pause' : '\u25b6 Play';
        play.classList.toggle('active', on);
      };
      play.addEventListener('click', () => setPlaying(!viewer.playing));
      const setMode = (mode) => {
        part('error view', () => {
          viewer.setMode(mode);
          if (mode === 'error') colourBar(viewer.errorSaturation);
        });
        $('view-patches').classList.toggle('active', mode !== 'error');
        $('view-error').classList.toggle('active', mode === 'error');
        $('view-patches').setAttribute('aria-pressed', String(mode !== 'error'));
        $('view-error').setAttribute('aria-pressed', String(mode === 'error'));
        $('legend').hidden = mode === 'error';
        $('colourbar').hidden = mode !== 'error';
        $('pick-readout').hidden = true;
      };
      $('view-patches').addEventListener('click', () => setMode('patches'));
      $('view-error').addEventListener('click', () => setMode('error'));
      $('fit-view').addEventListener('click', () => viewer.fitView());
      for (const [id, key] of [['show-cutter', 'cutter'], ['show-trajectory', 'trajectory'], ['show-holder', 'holder'], ['show-selected-only', 'selectedOnly']]) {
        const box = $(id);
        box.addEventListener('change', () => part('3D view', () => viewer.setShow(key, box.checked)));
        viewer.show[key] = box.checked;
      }
      patchSelect.addEventListener('change', () => select(Number(patchSelect.value)));
      document.addEventListener('keydown', (e) => {
        if (e.target && /^(INPUT|SELECT|TEXTAREA|BUTTON)$/.test(e.target.tagName)) return;
        if (e.key === 'f' || e.key === 'F') viewer.fitView();
        else if (e.key === ' ' && patches.length) { e.preventDefault(); setPlaying(!viewer.playing); }
      });
      part('uncovered regions', () => {
        const n = regionsTable($('regions-table'), data.coverage && data.coverage.regions, (r) => viewer.focus(r.centroid, Math.sqrt(Math.max(r.area, 0)) * 2.5));
        $('regions-count').textContent = String(n);
      });
      viewer.setT(0.5, false);
      slider.value = '500';
      showT(0.5);
      setMode('patches');
    });
  }
  select(patches.length ? 0 : -1);
  if (viewer) part('3D view', () => viewer.fitView());
  if (!viewer) {
    document.body.dataset.error = '1';
    $('viewer').append(h('div', { class: 'viewer-failed' }, 'No 3D view: see the error above.'));
  }
}

window.addEventListener('error', (e) => showError(e.error || e.message, 'script error'));
window.addEventListener('unhandledrejection', (e) => showError(e.reason, 'script error'));
try {
  const version = $('three-version');
  if (version) version.textContent = `r${REVISION}`;
  start();
} catch (e) {
  showError(e, failures ? 'report' : 'report could not be shown');
}
