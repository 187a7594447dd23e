#!/usr/bin/env node
// Opens a flank report.html in headless Chromium, offline, and checks what a person would see:
// the page becomes ready (document.body.dataset.ready = "1" after the first frame of the 3D
// scene), logs no console error and throws no page error, makes no network request (every
// request other than the report's own file:// URL and data:/blob: URLs is aborted and counted),
// draws a 3D view that is not blank (variance of the canvas's luminance), and lists one table
// row per patch. It then switches to the error heat map, moves the t slider and selects a patch
// through the page's own controls, and checks again.
//
// usage: node tests/report_browser_test.mjs --chromium PATH --report PATH/report.html
//          --patches N [--screenshot OUT.png] [--screenshot-error OUT.png] [--modules DIR]
//          [--max-open-ms MS]
// --modules is the node_modules folder holding playwright-core (default: report/web/node_modules
// beside this script). Exit 0 when every check passes, 1 when one fails, 2 on bad arguments.
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const READY_TIMEOUT_MS = 60_000;
// Luminance variance (0..255 scale) the 3D view must exceed. A canvas that shows only its
// background gives 0; the least contrasty real scene, a part all magenta (uncovered) on the
// dark background, gives about 100, a coloured part with a cutter several hundred or more.
const VARIANCE_THRESHOLD = 30;
// While the canvas is captured, everything drawn over it (legend, colour bar, axis triad) is hidden.
const CANVAS_ONLY = '#viewer > :not(canvas) { visibility: hidden !important; }';

function usage(message) {
  if (message) console.error(`report_browser_test: ${message}`);
  console.error('usage: report_browser_test.mjs --chromium PATH --report REPORT.html --patches N ' +
    '[--screenshot OUT.png] [--screenshot-error OUT.png] [--modules DIR] [--max-open-ms MS]');
  process.exit(2);
}

function parseArgs(argv) {
  const opts = {};
  const known = new Set(['--chromium', '--report', '--patches', '--screenshot', '--screenshot-error', '--modules', '--max-open-ms']);
  for (let i = 0; i < argv.length; ++i) {
    const [key, inline] = argv[i].split(/=(.*)/s);
    if (!known.has(key)) usage(`unknown argument ${argv[i]}`);
    const value = inline !== undefined ? inline : argv[++i];
    if (value === undefined) usage(`${key} needs a value`);
    opts[key.slice(2)] = value;
  }
  for (const k of ['chromium', 'report', 'patches']) if (!opts[k]) usage(`--${k} is required`);
  if (!/^\d+$/.test(opts.patches)) usage('--patches must be a whole number');
  opts.patches = Number(opts.patches);
  if (opts['max-open-ms'] !== undefined && !(Number(opts['max-open-ms']) > 0)) usage('--max-open-ms must be a positive number');
  if (!fs.existsSync(opts.chromium)) usage(`no chromium at ${opts.chromium}`);
  if (!fs.existsSync(opts.report)) usage(`no report at ${opts.report}`);
  return opts;
}

const opts = parseArgs(process.argv.slice(2));
const modules = path.resolve(opts.modules || path.join(here, '..', 'report', 'web', 'node_modules'));
const entry = path.join(modules, 'playwright-core', 'index.mjs');
if (!fs.existsSync(entry)) usage(`no playwright-core in ${modules} (run npm ci in report/web)`);
const { chromium } = await import(pathToFileURL(entry).href);

const results = [];
function check(name, ok, detail) {
  results.push({ name, ok });
  console.log(`${ok ? 'PASS' : 'FAIL'} ${name}${detail ? `: ${detail}` : ''}`);
}

// Luminance variance of a PNG, computed in the page (the PNG loaded back as a data: URL). A
// border of BORDER pixels is left out: the element's rounded corners and fractional position
// bring in pixels of the page around it.
const BORDER = 12;
async function canvasVariance(page, png) {
  return page.evaluate(async ({ b64, border }) => {
    const img = new Image();
    img.src = `data:image/png;base64,${b64}`;
    await img.decode();
    const c = document.createElement('canvas');
    c.width = img.naturalWidth;
    c.height = img.naturalHeight;
    const ctx = c.getContext('2d', { willReadFrequently: true });
    ctx.drawImage(img, 0, 0);
    const { data, width, height } = ctx.getImageData(0, 0, c.width, c.height);
    let n = 0, sum = 0, sum2 = 0;
    for (let y = border; y < height - border; ++y)
      for (let x = border; x < width - border; ++x) {
        const i = 4 * (y * width + x);
        const l = 0.2126 * data[i] + 0.7152 * data[i + 1] + 0.0722 * data[i + 2];
        sum += l;
        sum2 += l * l;
        ++n;
      }
    const mean = sum / Math.max(n, 1);
    return { variance: Math.max(0, sum2 / Math.max(n, 1) - mean * mean), width, height };
  }, { b64: png.toString('base64'), border: BORDER });
}

const twoFrames = (page) => page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(() => r()))));

const reportUrl = pathToFileURL(path.resolve(opts.report)).href;
const sameDocument = (url) => url.split('#')[0] === reportUrl;
const allowed = (url) => sameDocument(url) || url.startsWith('data:') || url.startsWith('blob:');

const consoleErrors = [], pageErrors = [], requests = new Set();
let browser;
const watchdog = setTimeout(() => {
  console.log('FAIL the test did not finish within 180 s');
  process.exit(1);
}, 180_000);

try {
  browser = await chromium.launch({
    executablePath: opts.chromium,
    headless: true,
    // Root (no sandbox) and no GPU: WebGL through ANGLE's SwiftShader (software) backend.
    // --disable-gpu keeps compositing off the (software) GPU process: it makes WebGL come up
    // several times faster than --use-angle=swiftshader alone.
    args: ['--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
      '--disable-dev-shm-usage', '--no-first-run', '--disable-background-networking', '--disable-component-update',
      '--disable-default-apps', '--disable-sync'],
  });
  const context = await browser.newContext({ viewport: { width: 1400, height: 900 }, deviceScaleFactor: 1, serviceWorkers: 'block' });
  const page = await context.newPage();
  await context.route('**/*', (route) => {
    const url = route.request().url();
    if (allowed(url)) return route.continue();
    requests.add(url);
    return route.abort('blockedbyclient');
  });
  page.on('request', (r) => { if (!allowed(r.url())) requests.add(r.url()); });
  page.on('websocket', (ws) => requests.add(ws.url()));
  page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => pageErrors.push(String(e && e.stack ? e.stack.split('\n')[0] : e)));

  const started = Date.now();
  await page.goto(reportUrl, { waitUntil: 'load', timeout: READY_TIMEOUT_MS });
  let state = 'timeout';
  try {
    const handle = await page.waitForFunction(() => {
      const d = document.body && document.body.dataset;
      return d && (d.ready === '1' ? 'ready' : d.error === '1' ? 'error' : false);
    }, null, { timeout: Math.max(READY_TIMEOUT_MS - (Date.now() - started), 1000), polling: 50 });
    state = await handle.jsonValue();
  } catch (e) {
    state = `timeout (${e.message.split('\n')[0]})`;
  }
  if (state === 'error') {
    // The page reported a failure; give the 3D view a moment in case it still becomes ready.
    await page.waitForFunction(() => document.body.dataset.ready === '1', null, { timeout: 2000 }).then(() => { state = 'ready'; }, () => {});
  }
  const readyMs = await page.evaluate(() => Number(document.body.dataset.readyMs));
  check('ready', state === 'ready', state === 'ready' ? 'body[data-ready="1"]' : `page state ${state}`);
  console.log(`open time: ${Number.isFinite(readyMs) ? readyMs.toFixed(0) : '—'} ms (navigation start to ready, page clock)`);
  if (opts['max-open-ms'] !== undefined)
    check('open time', Number.isFinite(readyMs) && readyMs <= Number(opts['max-open-ms']), `${Number.isFinite(readyMs) ? readyMs.toFixed(0) : '—'} ms, limit ${opts['max-open-ms']} ms`);

  const shown = await page.evaluate(() => {
    const box = document.getElementById('page-error');
    return box && !box.hidden ? box.innerText.replace(/\s+/g, ' ').trim() : '';
  });
  if (shown) console.log(`page shows an error: ${shown}`);

  // The 3D view alone: what WebGL drew.
  const canvas = page.locator('#viewer canvas');
  let variance = NaN;
  if (await canvas.count()) {
    await twoFrames(page);
    const png = await canvas.screenshot({ style: CANVAS_ONLY, timeout: 20_000 });
    const v = await canvasVariance(page, png);
    variance = v.variance;
    check('canvas not blank', variance > VARIANCE_THRESHOLD, `luminance variance ${variance.toFixed(1)} over ${v.width}×${v.height} (threshold ${VARIANCE_THRESHOLD})`);
  } else {
    check('canvas not blank', false, 'no canvas in #viewer');
  }

  const rows = await page.locator('#patch-table tbody tr').count();
  const children = await page.evaluate(() => {
    const body = document.querySelector('#patch-table tbody');
    return body ? body.children.length : -1;
  });
  check('patch table rows', rows === opts.patches && children === rows, `${rows} rows in #patch-table tbody (${children} elements), ${opts.patches} patches expected`);

  if (opts.screenshot) {
    await page.screenshot({ path: opts.screenshot, fullPage: true });
    console.log(`screenshot: ${opts.screenshot}`);
  }

  // Exercise the page's controls: error heat map, the t slider, a patch chosen in the table.
  const errorsBefore = consoleErrors.length + pageErrors.length;
  let exercised = [];
  try {
    await page.click('#view-error', { timeout: 10_000 });
    await twoFrames(page);
    const barShown = await page.locator('#colourbar').isVisible();
    exercised.push(`error view${barShown ? ' with colour bar' : ' WITHOUT colour bar'}`);
    if (!barShown) throw new Error('the colour bar is not shown in the error view');
    const slider = page.locator('#t-slider');
    if (await slider.isEnabled()) {
      await slider.fill('250');
      await twoFrames(page);
      const t = (await page.locator('#t-value').textContent()).trim();
      exercised.push(`slider to t = ${t}`);
      if (t !== '0.250') throw new Error(`the slider reads t = ${t} after moving it to 0.250`);
    } else {
      exercised.push('slider disabled (no patches)');
    }
    if (rows > 0) {
      await page.locator('#patch-table tbody tr').last().click();
      await twoFrames(page);
      exercised.push('last table row selected');
    }
    const png = await canvas.screenshot({ style: CANVAS_ONLY, timeout: 20_000 });
    const v = await canvasVariance(page, png);
    exercised.push(`error-view variance ${v.variance.toFixed(1)}`);
    if (!(v.variance > VARIANCE_THRESHOLD)) throw new Error(`the error view is blank (variance ${v.variance.toFixed(1)})`);
    if (opts['screenshot-error']) {
      await page.screenshot({ path: opts['screenshot-error'], fullPage: true });
      console.log(`screenshot: ${opts['screenshot-error']}`);
    }
    await page.click('#view-patches', { timeout: 10_000 });
    await twoFrames(page);
    const after = consoleErrors.length + pageErrors.length;
    check('controls', after === errorsBefore, `${exercised.join(', ')}${after !== errorsBefore ? `; ${after - errorsBefore} new error(s)` : ''}`);
  } catch (e) {
    check('controls', false, `${exercised.join(', ')}${exercised.length ? '; ' : ''}${e.message.split('\n')[0]}`);
  }

  check('no console error', consoleErrors.length === 0, consoleErrors.length ? consoleErrors.slice(0, 5).join(' | ') : '0 console errors');
  check('no page error', pageErrors.length === 0, pageErrors.length ? pageErrors.slice(0, 5).join(' | ') : '0 page errors');
  check('no network request', requests.size === 0, requests.size ? [...requests].slice(0, 5).join(' ') : '0 requests');
} catch (e) {
  check('browser', false, e.message.split('\n')[0]);
} finally {
  if (browser) await browser.close().catch(() => {});
  clearTimeout(watchdog);
}

const failed = results.filter((r) => !r.ok).map((r) => r.name);
console.log(`report_browser_test: ${results.length - failed.length} passed, ${failed.length} failed${failed.length ? ` (${failed.join(', ')})` : ''}`);
process.exit(failed.length ? 1 : 0);
