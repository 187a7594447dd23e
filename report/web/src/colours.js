// Colours shared by the 3D view, the legends and the plots: the run's patch palette (from the
// data, so a patch has the same colour as in design.ply) and the diverging error map of
// envelopes.ply: e < 0 (gouge) red, e > 0 (material left) blue, white at 0, saturated at
// ± tolerance, NaN grey.

export const NAN_GREY = [128, 128, 128];
const FALLBACK_PALETTE = ['#1f77b4', '#ff7f0e', '#2ca02c', '#d62728', '#9467bd', '#8c564b',
  '#7f7f7f', '#bcbd22', '#17becf', '#aec7e8', '#ffbb78'];

export function parseHex(s) {
  const m = /^#?([0-9a-f]{6})$/i.exec(String(s || '').trim());
  if (!m) return null;
  const n = parseInt(m[1], 16);
  return [(n >> 16) & 255, (n >> 8) & 255, n & 255];
}

export const toHex = (rgb) => `#${rgb.map((c) => c.toString(16).padStart(2, '0')).join('')}`;

export class Palette {
  constructor(data) {
    const list = (Array.isArray(data.palette) ? data.palette : []).map(parseHex).filter(Boolean);
    this.colours = list.length ? list : FALLBACK_PALETTE.map(parseHex);
    this.uncovered = parseHex(data.uncovered_colour) || [255, 0, 255];
  }
  // sRGB bytes of patch `id` (palette[id % length]); uncovered for a negative id.
  rgb(id) {
    if (!(id >= 0)) return this.uncovered;
    return this.colours[id % this.colours.length];
  }
  hex(id) {
    return toHex(this.rgb(id));
  }
}

// sRGB bytes of signed error e at saturation `tol`.
export function errorRgb(e, tol) {
  if (!Number.isFinite(e)) return NAN_GREY;
  const t = Math.abs(e) >= tol ? 1 : Math.abs(e) / tol;
  const fade = Math.round(255 * (1 - t));
  return e < 0 ? [255, fade, fade] : [fade, fade, 255];
}

// The CSS gradient of the colour bar, from −tol (left) to +tol (right).
export const ERROR_GRADIENT = 'linear-gradient(to right, rgb(255,0,0), rgb(255,255,255) 50%, rgb(0,0,255))';
