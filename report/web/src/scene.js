// The 3D view: the design surface coloured by patch, the envelopes Ω coloured by signed error,
// the chosen patch's cutter (a lathe of its meridian) at a position of its motion with its axis
// trajectory and holder, orbit/zoom, fit to view, an axis triad, and picking. Frames are drawn
// on demand (after a change), never in a busy loop, unless the cutter is playing.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { decodeEnvelope, decodeMotion, profilePoints } from './data.js';
import { errorRgb } from './colours.js';

const BACKGROUND = 0x2a2f37;
const DESIGN_GREY = '#a7adb5';
const CUTTER_STEEL = '#d4d9e0';
const HOLDER_GREY = '#7e8794';
const HOLDER_HIT = '#ff2d2d';
const LATHE_SEGMENTS = 64;
const SWEEP_SECONDS = 8;

// sRGB byte → linear float (three.js takes vertex colours as linear).
const SRGB_TO_LINEAR = new Float32Array(256);
for (let i = 0; i < 256; ++i) {
  const c = i / 255;
  SRGB_TO_LINEAR[i] = c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4);
}

function meshGeometry(mesh) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(mesh.position, 3));
  g.setIndex(new THREE.BufferAttribute(mesh.index, 1));
  g.computeVertexNormals();
  g.computeBoundingBox();
  g.computeBoundingSphere();
  return g;
}

function colourAttribute(n, rgbOf) {
  const colours = new Float32Array(n * 3);
  for (let v = 0; v < n; ++v) {
    const c = rgbOf(v);
    colours[3 * v] = SRGB_TO_LINEAR[c[0]];
    colours[3 * v + 1] = SRGB_TO_LINEAR[c[1]];
    colours[3 * v + 2] = SRGB_TO_LINEAR[c[2]];
  }
  return new THREE.BufferAttribute(colours, 3);
}

// The tool as a solid in its own frame: the axis is +Y, the profile point (z, r) at height z,
// closed by flat caps at both ends. `profile` is [[z, r], ...].
function latheGroup(profile, material) {
  const group = new THREE.Group();
  const points = profile.map(([z, r]) => new THREE.Vector2(r, z));
  group.add(new THREE.Mesh(new THREE.LatheGeometry(points, LATHE_SEGMENTS), material));
  const first = profile[0], last = profile[profile.length - 1];
  const down = first[0] <= last[0];  // the first point is the lower end
  for (const [[z, r], facesUp] of [[first, !down], [last, down]]) {
    if (!(r > 0)) continue;
    const cap = new THREE.CircleGeometry(r, LATHE_SEGMENTS);
    cap.rotateX(facesUp ? -Math.PI / 2 : Math.PI / 2);
    cap.translate(0, z, 0);
    group.add(new THREE.Mesh(cap, material));
  }
  return group;
}

export class Viewer {
  constructor(container, data, design, palette, { onPick } = {}) {
    this.container = container;
    this.data = data;
    this.palette = palette;
    this.onPick = onPick || (() => {});
    this.tolerance = data.tolerance > 0 ? data.tolerance : null;
    this.mode = 'patches';
    this.selected = -1;  // index into data.patches
    this.t = 0;
    this.playing = false;
    this.show = { cutter: true, trajectory: true, holder: true, selectedOnly: false };
    this.patchCache = new Map();
    this.envelopes = null;

    // The canvas gets its final size before the context is made, so that the drawing buffer
    // is allocated once (a resize costs a reallocation, slow in software WebGL). three.js
    // works in device pixels here (its pixel ratio stays 1); CSS stretches the canvas.
    const canvas = document.createElement('canvas');
    [canvas.width, canvas.height] = this.bufferSize(container);
    const renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
    renderer.setClearColor(BACKGROUND, 1);
    renderer.autoClear = false;
    renderer.outputColorSpace = THREE.SRGBColorSpace;
    this.renderer = renderer;
    container.appendChild(renderer.domElement);
    performance.mark('flank:webgl-context');

    const scene = new THREE.Scene();
    this.scene = scene;
    const camera = new THREE.PerspectiveCamera(35, 1, 0.1, 1000);
    camera.up.set(0, 0, 1);
    this.camera = camera;
    scene.add(camera);
    scene.add(new THREE.HemisphereLight(0xffffff, 0x5d6470, 1.25));
    const headlight = new THREE.DirectionalLight(0xffffff, 2.3);
    headlight.position.set(0.35, 0.55, 0);
    headlight.target.position.set(0, 0, -1);
    camera.add(headlight, headlight.target);

    // The design surface.
    this.design = design;
    const geometry = meshGeometry(design);
    const ids = design.patch;
    geometry.setAttribute('color', colourAttribute(design.vertices, (v) => palette.rgb(ids[v])));
    this.designByPatch = new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide });
    this.designGrey = new THREE.MeshLambertMaterial({
      color: DESIGN_GREY, side: THREE.DoubleSide,
      polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 2,
    });
    this.designMesh = new THREE.Mesh(geometry, this.designByPatch);
    performance.mark('flank:design-mesh');
    scene.add(this.designMesh);
    this.bounds = geometry.boundingBox.isEmpty() ? new THREE.Box3(new THREE.Vector3(-1, -1, -1), new THREE.Vector3(1, 1, 1)) : geometry.boundingBox.clone();
    this.diagonal = Math.max(this.bounds.getSize(new THREE.Vector3()).length(), 1e-6);

    // The chosen patch's cutter, trajectory and holder live here.
    this.patchGroup = new THREE.Group();
    scene.add(this.patchGroup);
    this.cutterMaterial = new THREE.MeshPhongMaterial({ color: CUTTER_STEEL, shininess: 70, specular: 0x555555, side: THREE.DoubleSide });

    // Axis triad in the lower left corner: SVG, turned with the camera on every frame.
    this.triad = this.makeTriad(container);

    const controls = new OrbitControls(camera, renderer.domElement);
    controls.enableDamping = false;
    controls.zoomToCursor = true;
    controls.screenSpacePanning = true;
    controls.addEventListener('change', () => this.requestRender());
    this.controls = controls;

    this.raycaster = new THREE.Raycaster();
    this.installPicking();

    this.resizeObserver = new ResizeObserver(() => this.resize());
    this.resizeObserver.observe(container);
    this.resize();
    camera.position.copy(this.initialDirection(geometry.attributes.normal.array));
    this.fitView();
  }

  // ---- drawing ----

  // The drawing buffer's size in device pixels for the container's CSS size.
  bufferSize(container) {
    const ratio = Math.min(window.devicePixelRatio || 1, 2);
    return [Math.max(Math.floor(container.clientWidth * ratio), 1), Math.max(Math.floor(container.clientHeight * ratio), 1)];
  }

  resize() {
    const [w, h] = this.bufferSize(this.container);
    const canvas = this.renderer.domElement;
    if (canvas.width !== w || canvas.height !== h) this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }

  requestRender() {
    if (this.frameRequested) return;
    this.frameRequested = true;
    requestAnimationFrame((now) => this.frame(now));
  }

  frame(now) {
    this.frameRequested = false;
    if (this.playing) {
      if (this.lastTick !== undefined) {
        let t = this.t + (now - this.lastTick) / 1000 / SWEEP_SECONDS;
        if (t > 1) t -= Math.floor(t);
        this.setT(t, false);
        if (this.onTick) this.onTick(this.t);
      }
      this.lastTick = now;
      this.requestRender();
    }
    this.render();
    if (this.onFrame) this.onFrame();
  }

  render() {
    const { renderer, camera, controls } = this;
    // Clip planes follow the distance so that depth keeps its precision at any zoom.
    const distance = camera.position.distanceTo(controls.target);
    camera.near = Math.max(distance / 200, this.diagonal * 1e-5);
    camera.far = distance + 20 * this.diagonal;
    camera.updateProjectionMatrix();

    renderer.clear();
    renderer.render(this.scene, camera);
    this.updateTriad();
  }

  makeTriad(container) {
    const NS = 'http://www.w3.org/2000/svg';
    const svg = document.createElementNS(NS, 'svg');
    svg.setAttribute('class', 'triad');
    svg.setAttribute('viewBox', '-50 -50 100 100');
    svg.setAttribute('aria-hidden', 'true');
    const axes = [['X', [1, 0, 0], '#ff6b6b'], ['Y', [0, 1, 0], '#69db7c'], ['Z', [0, 0, 1], '#74a9ff']].map(([label, dir, colour]) => {
      const g = document.createElementNS(NS, 'g');
      const line = document.createElementNS(NS, 'line');
      line.setAttribute('x1', '0'); line.setAttribute('y1', '0');
      line.setAttribute('stroke', colour); line.setAttribute('stroke-width', '3'); line.setAttribute('stroke-linecap', 'round');
      const text = document.createElementNS(NS, 'text');
      text.setAttribute('fill', colour); text.setAttribute('text-anchor', 'middle'); text.setAttribute('dominant-baseline', 'central');
      text.textContent = label;
      g.append(line, text);
      svg.appendChild(g);
      return { g, line, text, dir: new THREE.Vector3(...dir) };
    });
    container.appendChild(svg);
    return { svg, axes };
  }

  // Projects the world axes with the camera's rotation; the farthest is drawn first.
  updateTriad() {
    const q = this.camera.quaternion.clone().invert();
    const v = new THREE.Vector3();
    const placed = this.triad.axes.map((axis) => {
      v.copy(axis.dir).applyQuaternion(q);
      axis.line.setAttribute('x2', (v.x * 30).toFixed(1));
      axis.line.setAttribute('y2', (-v.y * 30).toFixed(1));
      axis.text.setAttribute('x', (v.x * 41).toFixed(1));
      axis.text.setAttribute('y', (-v.y * 41).toFixed(1));
      return [v.z, axis.g];
    });
    placed.sort((p1, p2) => p1[0] - p2[0]);
    for (const [, g] of placed) this.triad.svg.appendChild(g);
  }

  // ---- camera ----

  // Looks at the surface from the side the cutters are on, tilted a little so that the view
  // reads as 3D. The side: the mean vertex normal, turned by a vote of the cutters' axis
  // midpoints (each against the normal at the nearest design vertex).
  initialDirection(normals) {
    const { position: p, vertices } = this.design;
    const n = new THREE.Vector3();
    for (let v = 0; v < normals.length; v += 3) { n.x += normals[v]; n.y += normals[v + 1]; n.z += normals[v + 2]; }
    if (n.lengthSq() === 0) n.set(1, -1.25, 0.85);
    n.normalize();
    let vote = 0;
    const stride = Math.max(1, Math.floor(vertices / 4000));
    for (const patch of this.data.patches) {
      const m = decodeMotion(patch);
      if (!m) continue;
      const every = Math.max(1, Math.floor(m.steps / 8));
      for (let i = 0; i <= m.steps; i += every) {
        const x = (m.a[3 * i] + m.b[3 * i]) / 2, y = (m.a[3 * i + 1] + m.b[3 * i + 1]) / 2, z = (m.a[3 * i + 2] + m.b[3 * i + 2]) / 2;
        let best = -1, bestD = Infinity;
        for (let v = 0; v < vertices; v += stride) {
          const dx = p[3 * v] - x, dy = p[3 * v + 1] - y, dz = p[3 * v + 2] - z;
          const d = dx * dx + dy * dy + dz * dz;
          if (d < bestD) { bestD = d; best = v; }
        }
        if (best < 0) continue;
        const side = (x - p[3 * best]) * normals[3 * best] + (y - p[3 * best + 1]) * normals[3 * best + 1] + (z - p[3 * best + 2]) * normals[3 * best + 2];
        vote += Math.sign(side);
      }
    }
    if (vote < 0) n.negate();
    const up = new THREE.Vector3(0, 0, 1);
    const elevation = up.clone().addScaledVector(n, -up.dot(n));
    const side = n.clone().cross(up);
    const d = n.clone();
    if (elevation.lengthSq() > 1e-6) d.addScaledVector(elevation.normalize(), 0.35);
    if (side.lengthSq() > 1e-6) d.addScaledVector(side.normalize(), 0.3);
    else d.add(new THREE.Vector3(0.3, -0.3, 0));
    return d.normalize();
  }

  // Frames the design (and the chosen patch's trajectory when shown), keeping the direction of view.
  fitView() {
    const box = this.bounds.clone();
    if (this.current && this.current.trajectory && this.show.trajectory) {
      this.current.trajectory.geometry.computeBoundingBox();
      box.union(this.current.trajectory.geometry.boundingBox);
    }
    const centre = box.getCenter(new THREE.Vector3());
    const camera = this.camera;
    const direction = camera.position.clone().sub(this.controls.target);
    if (direction.lengthSq() === 0) direction.set(1, -1.25, 0.85);
    direction.normalize();
    // The box's corners in the camera's frame: the distance at which all of them are in view.
    camera.position.copy(centre).add(direction);
    camera.lookAt(centre);
    camera.updateMatrixWorld();
    const right = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 0);
    const up = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 1);
    const tanV = Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2), tanH = tanV * camera.aspect;
    let distance = 0;
    const corner = new THREE.Vector3();
    for (let k = 0; k < 8; ++k) {
      corner.set(k & 1 ? box.max.x : box.min.x, k & 2 ? box.max.y : box.min.y, k & 4 ? box.max.z : box.min.z).sub(centre);
      const z = corner.dot(direction);
      distance = Math.max(distance, z + Math.abs(corner.dot(right)) / tanH, z + Math.abs(corner.dot(up)) / tanV);
    }
    distance = Math.max(distance * 1.08, this.diagonal * 1e-3);
    this.controls.target.copy(centre);
    camera.position.copy(centre).addScaledVector(direction, distance);
    camera.lookAt(centre);
    this.controls.update();
    this.requestRender();
  }

  // Looks at a point from the current direction, from about `span` away.
  focus(point, span) {
    const p = new THREE.Vector3(...point);
    const direction = this.camera.position.clone().sub(this.controls.target).normalize();
    const vfov = THREE.MathUtils.degToRad(this.camera.fov);
    const distance = Math.max(span, this.diagonal * 0.02) / Math.tan(vfov / 2);
    this.controls.target.copy(p);
    this.camera.position.copy(p).addScaledVector(direction, distance);
    this.controls.update();
    this.requestRender();
  }

  // ---- views ----

  setMode(mode) {
    this.mode = mode === 'error' ? 'error' : 'patches';
    if (this.mode === 'error') this.buildEnvelopes();
    this.designMesh.material = this.mode === 'error' ? this.designGrey : this.designByPatch;
    this.updateEnvelopeVisibility();
    this.requestRender();
  }

  // Envelope meshes, built on the first switch to the error view.
  buildEnvelopes() {
    if (this.envelopes) return;
    const tol = this.tolerance;
    this.envelopes = new THREE.Group();
    this.envelopeMeshes = [];
    this.envelopeTolerance = tol;
    const meshes = [];
    let largest = 0;
    for (const patch of this.data.patches) {
      const env = decodeEnvelope(patch);
      meshes.push(env);
      if (env && !tol) for (const e of env.error) if (Number.isFinite(e)) largest = Math.max(largest, Math.abs(e));
    }
    // Without a tolerance, saturate at the largest |e| (as envelopes.ply does).
    const saturation = tol || largest || 1;
    this.errorSaturation = saturation;
    const material = new THREE.MeshLambertMaterial({
      vertexColors: true, side: THREE.DoubleSide,
      polygonOffset: true, polygonOffsetFactor: -1, polygonOffsetUnits: -2,
    });
    meshes.forEach((env, k) => {
      if (!env || env.triangles === 0) { this.envelopeMeshes.push(null); return; }
      const g = meshGeometry(env);
      const error = env.error;
      g.setAttribute('color', colourAttribute(env.vertices, (v) => errorRgb(error[v], saturation)));
      const mesh = new THREE.Mesh(g, material);
      mesh.userData = { patchIndex: k, error };
      this.envelopeMeshes.push(mesh);
      this.envelopes.add(mesh);
    });
    this.scene.add(this.envelopes);
  }

  updateEnvelopeVisibility() {
    if (!this.envelopes) return;
    this.envelopes.visible = this.mode === 'error';
    this.envelopeMeshes.forEach((m, k) => {
      if (m) m.visible = !this.show.selectedOnly || k === this.selected;
    });
  }

  setShow(key, value) {
    this.show[key] = value;
    this.updateEnvelopeVisibility();
    this.updatePatchVisibility();
    this.requestRender();
  }

  // ---- the chosen patch: cutter, trajectory, holder ----

  select(index) {
    if (!(index >= 0 && index < this.data.patches.length)) index = -1;
    this.selected = index;
    this.patchGroup.clear();
    this.current = index >= 0 ? this.patchObjects(index) : null;
    if (this.current) this.patchGroup.add(this.current.root);
    this.updateEnvelopeVisibility();
    this.updatePatchVisibility();
    this.setT(this.t, false);
    this.requestRender();
  }

  patchObjects(index) {
    if (this.patchCache.has(index)) return this.patchCache.get(index);
    const patch = this.data.patches[index];
    const motion = decodeMotion(patch);
    const colour = this.palette.hex(patch.id);
    const root = new THREE.Group();
    const objects = { root, motion, patch };

    if (motion && motion.steps >= 1) {
      const n = motion.steps + 1;
      const pos = new Float32Array(n * 6);
      for (let i = 0; i < n; ++i) {
        pos.set(motion.a.subarray(3 * i, 3 * i + 3), 6 * i);
        pos.set(motion.b.subarray(3 * i, 3 * i + 3), 6 * i + 3);
      }
      const index32 = new Uint32Array(motion.steps * 6);
      for (let i = 0; i < motion.steps; ++i) {
        const p = 2 * i;
        index32.set([p, p + 1, p + 2, p + 1, p + 3, p + 2], 6 * i);
      }
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
      g.setIndex(new THREE.BufferAttribute(index32, 1));
      objects.trajectory = new THREE.Mesh(g, new THREE.MeshBasicMaterial({
        color: colour, transparent: true, opacity: 0.16, side: THREE.DoubleSide, depthWrite: false,
      }));
      objects.trajectory.renderOrder = 2;
      const edges = new THREE.Group();
      for (const ends of [motion.a, motion.b]) {
        const lg = new THREE.BufferGeometry();
        lg.setAttribute('position', new THREE.BufferAttribute(ends, 3));
        edges.add(new THREE.Line(lg, new THREE.LineBasicMaterial({ color: colour, transparent: true, opacity: 0.75 })));
      }
      objects.trajectoryEdges = edges;
      root.add(objects.trajectory, edges);
    }

    const profile = profilePoints(patch);
    if (motion && profile.length >= 2) {
      const tool = new THREE.Group();
      tool.add(latheGroup(profile, this.cutterMaterial));
      // The axis line a–b, drawn through the tool.
      const axis = new THREE.BufferGeometry();
      axis.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6), 3));
      objects.axisLine = new THREE.Line(axis, new THREE.LineBasicMaterial({ color: 0xffd43b, depthTest: false, transparent: true, opacity: 0.9 }));
      objects.axisLine.renderOrder = 5;
      root.add(objects.axisLine);
      const c = patch.collision || {};
      const h = Array.isArray(c.holder) ? c.holder : null;
      if (c.checked && h && h[0] > 0 && h[1] > 0) {
        const collides = c.holder_clear === false;
        const hg = new THREE.CylinderGeometry(h[1], h[1], h[0], 48, 1, false);
        hg.translate(0, h[0] / 2, 0);
        objects.holder = new THREE.Mesh(hg, new THREE.MeshPhongMaterial({
          color: collides ? HOLDER_HIT : HOLDER_GREY, transparent: true, opacity: collides ? 0.6 : 0.42,
          side: THREE.DoubleSide, depthWrite: false, shininess: 30,
        }));
        objects.holder.renderOrder = 3;
        tool.add(objects.holder);
      }
      objects.tool = tool;
      root.add(tool);
    }
    this.patchCache.set(index, objects);
    return objects;
  }

  updatePatchVisibility() {
    const o = this.current;
    if (!o) return;
    if (o.trajectory) { o.trajectory.visible = this.show.trajectory; o.trajectoryEdges.visible = this.show.trajectory; }
    if (o.tool) { o.tool.visible = this.show.cutter; o.axisLine.visible = this.show.cutter; }
    if (o.holder) o.holder.visible = this.show.holder;
  }

  // Places the cutter at t in [0, 1] (linear between the motion's samples).
  setT(t, render = true) {
    this.t = Math.min(Math.max(Number(t) || 0, 0), 1);
    const o = this.current;
    if (o && o.tool && o.motion) {
      const { steps, a, b } = o.motion;
      const x = this.t * steps;
      const i = Math.min(Math.floor(x), steps - 1 < 0 ? 0 : steps - 1);
      const f = steps > 0 ? x - i : 0;
      const j = Math.min(i + 1, steps);
      const at = (arr, k) => new THREE.Vector3(arr[3 * k], arr[3 * k + 1], arr[3 * k + 2]);
      const pa = at(a, i).lerp(at(a, j), f);
      const pb = at(b, i).lerp(at(b, j), f);
      const axis = pb.clone().sub(pa);
      const length = axis.length();
      if (length > 0) {
        axis.divideScalar(length);
        o.tool.position.copy(pa);
        o.tool.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), axis);
        if (o.holder) o.holder.position.set(0, length, 0);
        const line = o.axisLine.geometry.attributes.position;
        line.setXYZ(0, pa.x, pa.y, pa.z);
        line.setXYZ(1, pb.x, pb.y, pb.z);
        line.needsUpdate = true;
        o.axisLine.geometry.computeBoundingSphere();
      }
    }
    if (render) this.requestRender();
  }

  setPlaying(playing) {
    this.playing = !!playing;
    this.lastTick = undefined;
    if (this.playing) this.requestRender();
  }

  // ---- picking: a click (not a drag) on the surface reports the patch and the error there ----

  installPicking() {
    const el = this.renderer.domElement;
    let down = null;
    el.addEventListener('pointerdown', (e) => { down = [e.clientX, e.clientY]; });
    el.addEventListener('pointerup', (e) => {
      if (!down) return;
      const moved = Math.hypot(e.clientX - down[0], e.clientY - down[1]);
      down = null;
      if (moved > 4) return;
      this.pick(e.clientX, e.clientY);
    });
  }

  pick(clientX, clientY) {
    const rect = this.renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((clientX - rect.left) / rect.width) * 2 - 1, -((clientY - rect.top) / rect.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.camera);
    const targets = [this.designMesh];
    if (this.mode === 'error' && this.envelopes) targets.push(...this.envelopeMeshes.filter((m) => m && m.visible));
    const hits = this.raycaster.intersectObjects(targets, false);
    if (!hits.length) { this.onPick(null); return; }
    const hit = hits.find((h) => h.object !== this.designMesh) || hits[0];
    const { a, b, c } = hit.face;
    const pos = hit.object.geometry.attributes.position;
    const corner = (k) => new THREE.Vector3().fromBufferAttribute(pos, k);
    const bary = new THREE.Triangle(corner(a), corner(b), corner(c)).getBarycoord(hit.point, new THREE.Vector3());
    const result = { point: hit.point.toArray() };
    if (hit.object === this.designMesh) {
      const ids = this.design.patch;
      const w = [bary.x, bary.y, bary.z], v = [a, b, c];
      const k = w.indexOf(Math.max(...w));
      result.patchId = ids[v[k]];
    } else {
      const e = hit.object.userData.error;
      const ea = e[a], eb = e[b], ec = e[c];
      result.error = bary ? bary.x * ea + bary.y * eb + bary.z * ec : NaN;
      result.patchIndex = hit.object.userData.patchIndex;
    }
    this.onPick(result);
  }
}
