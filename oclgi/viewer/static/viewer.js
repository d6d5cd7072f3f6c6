// oclgi view: the tessellated scene drawn with WebGL2, coloured by the
// session's per-vertex radiance (linear; exposure and sRGB applied here).
// The server sends the mesh once and then only changed colours, as float16
// at a power-of-two scale (oclgi/viewer/vertex_colours.py): the page copies
// a frame's runs into its float32 colours with typed-array sets (a
// Float16Array widens natively), uploads the changed runs and folds the
// scale into the exposure. (The colours stay float32 on the GPU: a
// three-channel 16-bit float is no vertex format of Direct3D and an
// optional one in Vulkan, so ANGLE may convert the whole buffer at each
// upload.) The page
// moves a dragged object's vertices itself (a model matrix per movable
// object), so orbiting and dragging run at display rate whatever the
// server is doing, and the light follows when its update arrives.
//
// While the view moves (a drag, an orbit, the wheel, keys; until REST_MS
// after the last), a page whose exact frame (the full mesh, sRGB per
// fragment, every pixel) takes longer than FRAME_BUDGET_MS to draw draws
// motion frames instead: a level of detail (oclgi/viewer/level_of_detail.py),
// the finest whose motion frame fits the budget, at MOTION_SCALE of the
// canvas's resolution each way, with sRGB per vertex; the draw times are
// measured when the page loads (each frame drawn and finished). The page
// tells the server which mesh it draws (a "level" message), so a drag's
// frames carry that level's colours only; at rest it asks for the
// tessellation again and draws the exact frame once the tessellation's
// colours are as new as the level's. A mesh is drawn only with colours of
// the latest update, or, until those arrive, the mesh that has the latest.
// A page whose exact frame fits the budget (a GPU's) never leaves it.
"use strict";

const MAX_OBJECTS = 16; // model matrices in the shader: the static scene and up to 15 movable objects
const PLOT_SECONDS = 10;
const MAX_RANGE_UPLOADS = 64; // a frame's changed runs uploaded one by one up to this many, else the whole array
// a moving view's draw: half a 60 Hz display frame, the other half for the page's other work and, on a
// machine without a GPU, for the server's and the browser's other threads
const FRAME_BUDGET_MS = 8;
const REST_MS = 250; // the view rests this long after the last motion: the full mesh again
const MOTION_SCALE = 0.5; // a motion frame's pixels per canvas pixel, each way
// Without a GPU every frame shown costs the browser 10-25 ms of CPU
// (SwiftShader's draw and the compositor's, headless Chromium on 2 cores),
// taken from the server computing the move. So while a move of this page
// is on its way, a moving view without a GPU shows a new pose alone only
// once the answer is late: a frame after the server's usual time (the
// median of its last answers), and no sooner than MOTION_INTERVAL_MS nor
// later than POSE_INTERVAL_MAX_MS after the frame before. An answer on
// time is drawn with its pose in one frame: one draw per update instead
// of 1.2-2.3 (bench/README.md, "Viewer"); a slow server's drag still shows
// the object at 10 poses a second. New colours are shown at once, an orbit
// at display rate.
const MOTION_INTERVAL_MS = 50;
const POSE_INTERVAL_MAX_MS = 100;
const DISPLAY_FRAME_MS = 1000 / 60;

function halfToFloat(h) { // an IEEE float16's bits -> its value
  const e = (h >> 10) & 31, m = h & 1023, s = h & 0x8000 ? -1 : 1;
  if (e === 0) return s * m * Math.pow(2, -24);
  if (e === 31) return m ? NaN : s * Infinity;
  return s * (1 + m / 1024) * Math.pow(2, e - 15);
}
function halves(buf, offset, n) { // n float16 values at offset, readable as numbers (natively where it can)
  if (typeof Float16Array === "function") return new Float16Array(buf, offset, n);
  const bits = new Uint16Array(buf, offset, n), out = new Float32Array(n);
  for (let i = 0; i < n; i++) out[i] = halfToFloat(bits[i]);
  return out;
}

// -- 4x4 matrices: row-major arrays of 16 (as the server writes them) ------
function mul(a, b) {
  const r = new Array(16).fill(0);
  for (let i = 0; i < 4; i++)
    for (let j = 0; j < 4; j++)
      for (let k = 0; k < 4; k++) r[4 * i + j] += a[4 * i + k] * b[4 * k + j];
  return r;
}
function translation(x, y, z) { return [1, 0, 0, x, 0, 1, 0, y, 0, 0, 1, z, 0, 0, 0, 1]; }
function rotationY(a) {
  const c = Math.cos(a), s = Math.sin(a);
  return [c, 0, s, 0, 0, 1, 0, 0, -s, 0, c, 0, 0, 0, 0, 1];
}
function inverseAffine(m) { // the inverse of an affine matrix (last row 0 0 0 1)
  const [a, b, c, d, e, f, g, h, i] = [m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]];
  const A = e * i - f * h, B = -(d * i - f * g), C = d * h - e * g;
  const det = a * A + b * B + c * C;
  const inv = [A, -(b * i - c * h), b * f - c * e,
               B, a * i - c * g, -(a * f - c * d),
               C, -(a * h - b * g), a * e - b * d].map(x => x / det);
  const t = [m[3], m[7], m[11]];
  const r = new Array(16).fill(0);
  for (let row = 0; row < 3; row++) {
    for (let col = 0; col < 3; col++) r[4 * row + col] = inv[3 * row + col];
    r[4 * row + 3] = -(inv[3 * row] * t[0] + inv[3 * row + 1] * t[1] + inv[3 * row + 2] * t[2]);
  }
  r[15] = 1;
  return r;
}
function apply(m, p) {
  return [m[0] * p[0] + m[1] * p[1] + m[2] * p[2] + m[3],
          m[4] * p[0] + m[5] * p[1] + m[6] * p[2] + m[7],
          m[8] * p[0] + m[9] * p[1] + m[10] * p[2] + m[11]];
}
function columnMajor(m) { // for uniformMatrix4fv
  const r = new Float32Array(16);
  for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) r[4 * j + i] = m[4 * i + j];
  return r;
}
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const normalize = a => scale(a, 1 / Math.hypot(a[0], a[1], a[2]));

// -- shaders --------------------------------------------------------------
// Two programs from one source: the exact one converts the interpolated
// linear radiance to sRGB per fragment; the motion one (MOTION, for the
// frames of a moving view only) converts per vertex and interpolates the
// sRGB values, which halves a software rasterizer's fragment cost.
const SRGB = `vec3 srgb(vec3 c) {
  c = clamp(c, 0.0, 1.0);
  return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}`;
const VERTEX = motion => `#version 300 es
layout(location = 0) in vec3 position;
layout(location = 1) in vec3 radiance;
layout(location = 2) in uint object;
uniform mat4 viewProjection;
uniform mat4 model[${MAX_OBJECTS}];
uniform float exposure;
out vec3 colour;
flat out uint objectId;
${motion ? SRGB : ""}
void main() {
  gl_Position = viewProjection * model[min(object, ${MAX_OBJECTS - 1}u)] * vec4(position, 1.0);
  colour = ${motion ? "srgb(radiance * exposure)" : "radiance * exposure"};
  objectId = object;
}`;
const FRAGMENT = motion => `#version 300 es
precision highp float;
in vec3 colour;
flat in uint objectId;
uniform int picking;
uniform int selected;
out vec4 fragment;
${motion ? "" : SRGB}
void main() {
  if (picking == 1) { fragment = vec4(float(objectId) / 255.0, 0.0, 0.0, 1.0); return; }
  vec3 c = ${motion ? "colour" : "srgb(colour)"};
  if (selected > 0 && int(objectId) == selected) c = mix(c, vec3(1.0, 0.7, 0.2), 0.2);
  fragment = vec4(c, 1.0);
}`;

function compile(gl, type, source) {
  const s = gl.createShader(type);
  gl.shaderSource(s, source);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
  return s;
}

// -- the page -------------------------------------------------------------
const $ = id => document.getElementById(id);
const state = window.oclgiState = { // what a test or a benchmark reads (and drives through .api)
  ready: false, seq: -1, frames: 0, updates: 0, draws: 0, drawnSeq: -1, errors: [], log: [],
  colours: null, poses: {}, serverPoses: {}, lastUpdate: null, hello: null, connection: null,
  lights: {}, serverLights: {}, renders: [],
  poseGaps: [], // ms since the frame before, of each pose drawn alone while a move was on its way (the last 64)
};

function showError(text) {
  $("error").textContent = text;
  state.errors.push(text);
}

async function main() {
  const canvas = $("view");
  const gl = canvas.getContext("webgl2", {antialias: false, preserveDrawingBuffer: false});
  if (!gl) { showError("this browser has no WebGL2"); return; }
  // the server's token (oclgi/viewer/guard.py), from the URL `oclgi view` printed
  const token = encodeURIComponent(new URLSearchParams(location.search).get("token") || "");
  const scene = await (await fetch(`scene.json?token=${token}`)).json();
  const meshBuffer = await (await fetch(`mesh.bin?token=${token}`)).arrayBuffer();
  const header = new DataView(meshBuffer);
  const V = header.getUint32(4, true), F = header.getUint32(8, true);
  const positions = new Float32Array(meshBuffer, 16, 3 * V);
  const objectOf = new Uint32Array(meshBuffer, 16 + 12 * V, V);
  const faces = new Uint32Array(meshBuffer, 16 + 16 * V, 3 * F);
  const levelBuffer = await (await fetch(`levels.bin?token=${token}`)).arrayBuffer();
  const levelData = []; // per level of detail: positions, objects, faces
  {
    const h = new DataView(levelBuffer);
    let at = 8;
    for (let k = 0; k < h.getUint32(4, true); k++) {
      const C = h.getUint32(at, true), G = h.getUint32(at + 4, true);
      levelData.push({positions: new Float32Array(levelBuffer, at + 16, 3 * C),
                      objects: new Uint32Array(levelBuffer, at + 16 + 12 * C, C),
                      faces: new Uint32Array(levelBuffer, at + 16 + 16 * C, 3 * G)});
      at += 16 + 16 * C + 12 * G;
    }
  }
  $("scene-name").textContent = scene.name;
  const objects = scene.objects; // movable: object i is id i + 1 in objectOf
  const loadedInverse = objects.map(o => inverseAffine(o.matrix));
  for (const o of objects) state.poses[o.name] = o.matrix.slice();
  const lights = scene.lights || []; // point and spot lights: name, kind, position, path (precomputed positions)
  for (const l of lights) state.lights[l.name] = l.position.slice();

  // geometry
  function link(motion) { // a program and its uniforms (the shaders above)
    const program = gl.createProgram();
    gl.attachShader(program, compile(gl, gl.VERTEX_SHADER, VERTEX(motion)));
    gl.attachShader(program, compile(gl, gl.FRAGMENT_SHADER, FRAGMENT(motion)));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(program));
    const u = name => gl.getUniformLocation(program, name);
    return {program, viewProjection: u("viewProjection"), model: u("model"), exposure: u("exposure"),
            picking: u("picking"), selected: u("selected")};
  }
  const programs = {exact: link(false), motion: link(true)};
  const buffer = (target, data, usage) => {
    const b = gl.createBuffer();
    gl.bindBuffer(target, b);
    gl.bufferData(target, data, usage);
    return b;
  };
  function makeMesh(pos, obj, tri) { // a mesh to draw: its buffers and the colours the server sent it
    const n = pos.length / 3;
    const mesh = {n, count: tri.length, colours: new Float32Array(3 * n), e: 0, seq: -1, dirty: true,
                  ranges: null, // [first, count] in vertices changed since the last upload; null: the whole array
                  vao: gl.createVertexArray()};
    gl.bindVertexArray(mesh.vao);
    buffer(gl.ARRAY_BUFFER, pos, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    mesh.colourBuffer = buffer(gl.ARRAY_BUFFER, mesh.colours, gl.DYNAMIC_DRAW);
    gl.enableVertexAttribArray(1);
    gl.vertexAttribPointer(1, 3, gl.FLOAT, false, 0, 0);
    buffer(gl.ARRAY_BUFFER, obj, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(2);
    gl.vertexAttribIPointer(2, 1, gl.UNSIGNED_INT, 0, 0);
    buffer(gl.ELEMENT_ARRAY_BUFFER, tri, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    return mesh;
  }
  // meshes[0]: the tessellation; meshes[k]: its k-th level of detail
  const meshes = [makeMesh(positions, objectOf, faces), ...levelData.map(l => makeMesh(l.positions, l.objects, l.faces))];
  const colours = state.colours = meshes[0].colours; // float16 values (exact in float32), times 2^scaleExponent
  state.scaleExponent = 0;
  state.drawnLevel = 0;
  // the update each mesh's colours are of (for tests: the meshes' own)
  Object.defineProperty(state, "levelSeqs", {get: () => meshes.map(m => m.seq)});
  Object.defineProperty(state, "fullSeq", {get: () => meshes[0].seq});
  // the measured draw times (ms): the exact frame of the full mesh, and the motion frame of each mesh
  state.frameMs = {full: null, motion: meshes.map(() => null)};
  state.drawsByLevel = meshes.map(() => 0);
  let motionLevel = 0; // the mesh drawn while the view moves
  let slow = false; // the exact frame misses the budget: a moving view draws motion frames
  let shownMotion = false; // the frame drawn last was a motion frame
  let serverLevel = 0; // the mesh the server sends the colours of
  let lastMotion = -Infinity;
  let shown = 0; // the mesh drawn last
  let redraw = true; // something shown changed: the next display frame draws (an idle page costs nothing)
  const changed = () => { redraw = true; };
  const moved = () => { redraw = true; lastMotion = performance.now(); }; // the view or an object moves
  function chooseLevel() { // the finest mesh whose motion frame fits the budget (the coarsest if none does)
    const ms = state.frameMs;
    slow = ms.full != null && ms.full > FRAME_BUDGET_MS;
    motionLevel = 0;
    if (slow) {
      motionLevel = meshes.length - 1;
      for (let k = 0; k < meshes.length; k++) if (ms.motion[k] != null && ms.motion[k] <= FRAME_BUDGET_MS) { motionLevel = k; break; }
    }
    state.motionLevel = motionLevel;
    return motionLevel;
  }
  const moving = () => slow && (drag || performance.now() - lastMotion < REST_MS);
  function wantedLevel() { return moving() ? motionLevel : 0; }
  function levelToShow() { // the wanted mesh once its colours are of the latest update, else the newest one
    const want = wantedLevel();
    if (meshes[want].seq === state.seq) return want;
    let best = 0;
    for (let k = 1; k < meshes.length; k++) if (meshes[k].seq > meshes[best].seq) best = k;
    return best;
  }

  // camera: orbit about a target
  const [lo, hi] = scene.bounds;
  const cam0 = scene.camera || {position: [hi[0] * 2, (lo[1] + hi[1]) / 2, hi[2] * 2],
                                look_at: [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2],
                                fov: 45};
  const camera = {};
  function home() {
    const d = sub(cam0.position, cam0.look_at);
    camera.target = cam0.look_at.slice();
    camera.distance = Math.hypot(d[0], d[1], d[2]);
    camera.yaw = Math.atan2(d[0], d[2]);
    camera.pitch = Math.asin(d[1] / camera.distance);
    camera.fov = cam0.fov * Math.PI / 180;
    redraw = true;
  }
  home();
  function frame() { // eye, forward, right, up (right/up at the image plane's half-extents)
    const cp = Math.cos(camera.pitch);
    const eye = add(camera.target, scale([cp * Math.sin(camera.yaw), Math.sin(camera.pitch),
                                          cp * Math.cos(camera.yaw)], camera.distance));
    const forward = normalize(sub(camera.target, eye));
    const right = normalize(cross(forward, [0, 1, 0]));
    const up = cross(right, forward);
    const halfH = Math.tan(camera.fov / 2), halfW = halfH * canvas.width / canvas.height;
    return {eye, forward, right: scale(right, halfW), up: scale(up, halfH), rightUnit: right, upUnit: up};
  }
  function viewProjection() {
    const f = frame();
    const near = Math.max(camera.distance * 1e-3, scene.diagonal * 1e-5), far = camera.distance + 2 * scene.diagonal;
    const r = f.rightUnit, up = f.upUnit, b = scale(f.forward, -1);
    const view = [r[0], r[1], r[2], -dot(r, f.eye), up[0], up[1], up[2], -dot(up, f.eye),
                  b[0], b[1], b[2], -dot(b, f.eye), 0, 0, 0, 1];
    const t = 1 / Math.tan(camera.fov / 2), aspect = canvas.width / canvas.height;
    const proj = [t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), 2 * far * near / (near - far),
                  0, 0, -1, 0];
    return mul(proj, view);
  }
  function ray(x, y) { // canvas pixels -> (origin, direction)
    const f = frame();
    const nx = 2 * x / canvas.clientWidth - 1, ny = 1 - 2 * y / canvas.clientHeight;
    return {origin: f.eye, dir: normalize(add(f.forward, add(scale(f.right, nx), scale(f.up, ny))))};
  }
  function project(p, m = viewProjection()) { // world point -> canvas pixels (CSS); null behind the eye
    const c = [0, 1, 2, 3].map(i => m[4 * i] * p[0] + m[4 * i + 1] * p[1] + m[4 * i + 2] * p[2] + m[4 * i + 3]);
    if (c[3] <= 0) return null;
    return [(c[0] / c[3] + 1) / 2 * canvas.clientWidth, (1 - c[1] / c[3]) / 2 * canvas.clientHeight];
  }

  // light markers: a ring at each light, dots at its precomputed positions (HTML over the canvas)
  const markerLayer = $("markers");
  const markers = lights.map(l => {
    const ring = document.createElement("div");
    ring.className = "light-marker";
    ring.title = `${l.kind} light ${l.name}`;
    markerLayer.appendChild(ring);
    const dots = (l.path || []).map(() => {
      const d = document.createElement("div");
      d.className = "path-marker";
      markerLayer.appendChild(d);
      return d;
    });
    return {ring, dots};
  });
  const place = (el, p) => {
    el.hidden = !p;
    if (p) { el.style.left = `${p[0]}px`; el.style.top = `${p[1]}px`; }
  };
  // the gizmo of the selected object: a height handle above it, a turn handle beside its base
  const gizmo = {height: document.createElement("div"), turn: document.createElement("div")};
  gizmo.height.className = "gizmo-height";
  gizmo.height.title = "drag up or down: raise or lower";
  gizmo.turn.className = "gizmo-turn";
  gizmo.turn.title = "drag round the object: turn it";
  markerLayer.append(gizmo.height, gizmo.turn);
  const loadedBoxes = new Map(); // object index -> its box as loaded (8 corners); the shown box from those
  function quickBox(i) { // a box round movable object i at the pose shown (its loaded box's corners moved)
    if (!loadedBoxes.has(i)) {
      const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
      for (let v = 0; v < V; v++) {
        if (objectOf[v] !== i + 1) continue;
        for (let a = 0; a < 3; a++) { lo[a] = Math.min(lo[a], positions[3 * v + a]); hi[a] = Math.max(hi[a], positions[3 * v + a]); }
      }
      const corners = [];
      for (let k = 0; k < 8; k++) corners.push([k & 1 ? hi[0] : lo[0], k & 2 ? hi[1] : lo[1], k & 4 ? hi[2] : lo[2]]);
      loadedBoxes.set(i, corners);
    }
    const m = relative(i), lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (const q of loadedBoxes.get(i)) {
      const p = apply(m, q);
      for (let a = 0; a < 3; a++) { lo[a] = Math.min(lo[a], p[a]); hi[a] = Math.max(hi[a], p[a]); }
    }
    return {lo, hi, centre: scale(add(lo, hi), 0.5)};
  }
  function gizmoPoints(i) { // world positions of the handles of object i
    const b = quickBox(i), size = Math.max(extent(b), 1e-6);
    return {height: [b.centre[0], b.hi[1] + 0.25 * size, b.centre[2]], turn: [b.hi[0] + 0.25 * size, b.lo[1], b.centre[2]],
            centre: b.centre};
  }
  function extent(b) { return Math.max(b.hi[0] - b.lo[0], b.hi[1] - b.lo[1], b.hi[2] - b.lo[2]); }
  function pickGizmo(x, y) { // "height", "turn" or null: the selected object's handle under (x, y)
    if (!selected) return null;
    const g = gizmoPoints(selected - 1);
    for (const kind of ["height", "turn"]) {
      const p = project(g[kind]);
      if (p && Math.hypot(p[0] - x, p[1] - y) <= 10) return kind;
    }
    return null;
  }
  function placeMarkers() {
    const m = viewProjection();
    const g = selected ? gizmoPoints(selected - 1) : null;
    place(gizmo.height, g && project(g.height, m));
    place(gizmo.turn, g && project(g.turn, m));
    lights.forEach((l, i) => {
      place(markers[i].ring, project(state.lights[l.name], m));
      markers[i].ring.classList.toggle("dragged", !!(drag && drag.light === l.name));
      (l.path || []).forEach((q, j) => place(markers[i].dots[j], project(q, m)));
    });
  }
  function pickLight(x, y) { // the light whose marker is under (x, y), or null
    for (const l of lights) {
      const p = project(state.lights[l.name]);
      if (p && Math.hypot(p[0] - x, p[1] - y) <= 10) return l;
    }
    return null;
  }
  function relative(i) { return mul(state.poses[objects[i].name], loadedInverse[i]); }
  function objectBox(i) { // world box of movable object i at the pose shown
    const m = relative(i);
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let v = 0; v < V; v++) {
      if (objectOf[v] !== i + 1) continue;
      const p = apply(m, [positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]]);
      for (let a = 0; a < 3; a++) { lo[a] = Math.min(lo[a], p[a]); hi[a] = Math.max(hi[a], p[a]); }
    }
    return {lo, hi, centre: scale(add(lo, hi), 0.5)};
  }

  // exposure
  let exposure = 1;
  function setExposure(stops) {
    exposure = Math.pow(2, stops);
    redraw = true;
    $("exposure").value = stops;
    $("exposure-value").textContent = `${stops >= 0 ? "+" : ""}${Number(stops).toFixed(1)} EV`;
  }
  function autoExposure() { // the vertices' log-average luminance to middle grey
    let sum = 0, n = 0;
    for (let v = 0; v < V; v++) {
      const y = (0.2126 * colours[3 * v] + 0.7152 * colours[3 * v + 1] + 0.0722 * colours[3 * v + 2]) *
                Math.pow(2, state.scaleExponent);
      if (y > 0) { sum += Math.log(y); n++; }
    }
    setExposure(n ? Math.round(10 * Math.log2(0.18 / Math.exp(sum / n))) / 10 : 0);
  }
  $("exposure").oninput = e => setExposure(Number(e.target.value));
  $("auto-exposure").onclick = autoExposure;
  $("home").onclick = home;

  // drawing: at display rate, whatever the socket is doing
  const modelData = new Float32Array(16 * MAX_OBJECTS);
  let selected = 0;
  function draw(picking, level = shown, motion = shownMotion) {
    const mesh = meshes[level], p = motion ? programs.motion : programs.exact;
    if (!picking) { // a motion frame: fewer pixels, which the browser scales up to the canvas
      const f = motion ? MOTION_SCALE : 1;
      const w = Math.max(1, Math.round(canvas.clientWidth * f)), h = Math.max(1, Math.round(canvas.clientHeight * f));
      if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    }
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.enable(gl.DEPTH_TEST);
    gl.clearColor(0, 0, 0, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.useProgram(p.program);
    modelData.set(columnMajor(translation(0, 0, 0)), 0);
    for (let i = 0; i < objects.length && i + 1 < MAX_OBJECTS; i++) modelData.set(columnMajor(relative(i)), 16 * (i + 1));
    gl.uniformMatrix4fv(p.model, false, modelData);
    gl.uniformMatrix4fv(p.viewProjection, false, columnMajor(viewProjection()));
    gl.uniform1f(p.exposure, exposure * Math.pow(2, mesh.e));
    gl.uniform1i(p.picking, picking ? 1 : 0);
    gl.uniform1i(p.selected, selected);
    gl.bindVertexArray(mesh.vao);
    gl.drawElements(gl.TRIANGLES, mesh.count, gl.UNSIGNED_INT, 0);
    gl.bindVertexArray(null);
  }
  function upload(mesh) {
    if (!mesh.dirty) return;
    gl.bindBuffer(gl.ARRAY_BUFFER, mesh.colourBuffer);
    if (mesh.ranges === null) gl.bufferSubData(gl.ARRAY_BUFFER, 0, mesh.colours);
    else for (const [first, n] of mesh.ranges) gl.bufferSubData(gl.ARRAY_BUFFER, 12 * first, mesh.colours, 3 * first, 3 * n);
    mesh.dirty = false;
    mesh.ranges = [];
  }
  const onePixel = new Uint8Array(4);
  function finish() { // wait for the drawing to be done (a pixel read back: Chrome's finish() does not wait)
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, onePixel);
  }
  function measure(level, motion, n = 3) { // ms to draw a frame, finished (the median of n, after one)
    const t = [];
    finish();
    for (let i = 0; i <= n; i++) {
      const t0 = performance.now();
      draw(false, level, motion);
      finish();
      t.push(performance.now() - t0);
    }
    t.shift();
    t.sort((a, b) => a - b);
    return t[n >> 1];
  }
  function measureLevels() { // the exact frame's draw time; if it misses the budget, the motion frames'
    state.frameMs.full = measure(0, false);
    for (let k = 0; k < meshes.length && state.frameMs.full > FRAME_BUDGET_MS; k++) {
      state.frameMs.motion[k] = measure(k, true);
      if (state.frameMs.motion[k] <= FRAME_BUDGET_MS) break; // the finest that fits: coarser ones are not needed
    }
    chooseLevel();
    redraw = true;
  }
  let pickTarget = null;
  function pick(x, y) { // the movable object under canvas pixel (x, y): 1 + its index, or 0
    const w = canvas.width, h = canvas.height;
    if (!pickTarget || pickTarget.w !== w || pickTarget.h !== h) {
      const fb = gl.createFramebuffer(), colour = gl.createRenderbuffer(), depth = gl.createRenderbuffer();
      gl.bindRenderbuffer(gl.RENDERBUFFER, colour);
      gl.renderbufferStorage(gl.RENDERBUFFER, gl.RGBA8, w, h);
      gl.bindRenderbuffer(gl.RENDERBUFFER, depth);
      gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, w, h);
      gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
      gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.RENDERBUFFER, colour);
      gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, depth);
      pickTarget = {fb, w, h};
    }
    gl.bindFramebuffer(gl.FRAMEBUFFER, pickTarget.fb);
    draw(true, motionLevel, false); // the mesh a drag would draw, at the canvas's size now
    const px = new Uint8Array(4);
    const sx = Math.floor(x * w / canvas.clientWidth), sy = Math.floor(h - 1 - y * h / canvas.clientHeight);
    gl.readPixels(sx, sy, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    return px[0] <= objects.length ? px[0] : 0;
  }

  // the socket
  const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/socket?token=${token}`);
  ws.binaryType = "arraybuffer";
  state.ws = ws;
  const pendingMoves = new Map(); // object name -> matrix: sent once a display frame, the latest only
  const pendingLights = new Map(); // light name -> position: likewise
  const answers = []; // ms from a move sent to its answer, the last 8 (poseInterval)
  const waiting = new Map(); // sync id -> resolve
  let syncs = 0;
  const plot = [];
  const drawnTimes = [];
  let lastMoveSent = 0, statsDirty = false, statsShown = 0;
  function send(msg) { if (ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(msg)); }
  function applyFrame(buf) {
    const view = new DataView(buf);
    if (buf.byteLength >= 20 && view.getUint32(0, true) === 0x5256474f) { showRender(buf); return; } // "OGVR"
    if (buf.byteLength >= 8 && view.getUint32(0, true) === 0x4256474f) { showBake(buf); return; } // "OGVB"
    if (buf.byteLength < 20 || view.getUint32(0, true) !== 0x4356474f) return; // "OGVC"
    const applyStart = performance.now();
    const seq = view.getUint32(4, true), mode = view.getUint32(8, true), e = view.getInt32(12, true);
    const level = view.getUint32(16, true), mesh = meshes[level];
    if (!mesh) return;
    const colours = mesh.colours;
    let sentVertices = mesh.n;
    if (e !== mesh.e) { mesh.e = e; redraw = true; }
    if (mode === 0) {
      colours.set(halves(buf, 24, 3 * mesh.n));
      mesh.ranges = null;
    } else {
      const R = view.getUint32(20, true), S = view.getUint32(24, true);
      const start = new Uint32Array(buf, 28, R), length = new Uint32Array(buf, 28 + 4 * R, R);
      const single = new Uint32Array(buf, 28 + 8 * R, S);
      let at = 0;
      for (let r = 0; r < R; r++) at += length[r];
      const values = halves(buf, 28 + 8 * R + 4 * S, 3 * (at + S));
      sentVertices = at + S;
      at = 0;
      for (let r = 0; r < R; r++) { // a run: one typed-array copy
        colours.set(values.subarray(3 * at, 3 * (at + length[r])), 3 * start[r]);
        at += length[r];
      }
      for (let i = 0; i < S; i++) { // a vertex alone
        const v = 3 * single[i], w = 3 * (at + i);
        colours[v] = values[w]; colours[v + 1] = values[w + 1]; colours[v + 2] = values[w + 2];
      }
      if (mesh.ranges !== null || !mesh.dirty) {
        if (!mesh.dirty) mesh.ranges = [];
        if (mesh.ranges.length + R + S > MAX_RANGE_UPLOADS) mesh.ranges = null;
        else {
          for (let r = 0; r < R; r++) mesh.ranges.push([start[r], length[r]]);
          for (let i = 0; i < S; i++) mesh.ranges.push([single[i], 1]);
        }
      }
    }
    mesh.seq = seq;
    if (level === 0) state.scaleExponent = e;
    state.seq = seq;
    state.frames++;
    state.frameStats = {bytes: buf.byteLength, vertices: sentVertices, level, applyMs: performance.now() - applyStart};
    state.frameAt = performance.now();
    state.moveToFrame = lastMoveSent ? state.frameAt - lastMoveSent : null;
    mesh.dirty = true;
    redraw = true;
    send({type: "ack", seq});
    if (state.frames === 1) { autoExposure(); upload(meshes[0]); measureLevels(); }
  }
  function describe(msg) {
    for (const name in msg.lights || {}) {
      state.serverLights[name] = msg.lights[name];
      if ((!drag || drag.light !== name) && !pendingLights.has(name)) { state.lights[name] = msg.lights[name].slice(); redraw = true; }
    }
    for (const name in msg.poses) {
      state.serverPoses[name] = msg.poses[name];
      if ((!drag || drag.name !== name) && !pendingMoves.has(name)) { state.poses[name] = msg.poses[name].slice(); redraw = true; }
    }
    const method = $("method");
    if (method.options.length !== msg.methods.length) {
      method.innerHTML = "";
      for (const m of msg.methods) method.add(new Option(m, m));
    }
    if (document.activeElement !== method) method.value = msg.method;
    for (const [id, value] of [["radius", msg.radius], ["photons", msg.photons], ["k", msg.k]]) {
      if (document.activeElement !== $(id)) { $(id).value = value == null ? "" : value; $(id).disabled = value == null; }
    }
    state.session = {photons: msg.photons, segments: msg.segments, method: msg.method, radius: msg.radius, k: msg.k};
  }
  function showStats(msg) {
    const s = msg.seconds || {};
    const rows = [];
    for (const k of ["points", "find", "subtract", "retrace", "add", "total", "read", "server"])
      if (k in s) rows.push([`${k} (ms)`, (1e3 * s[k]).toFixed(1)]);
    if (msg.kind === "move") {
      rows.push(["paths re-traced", `${msg.paths.toLocaleString()} / ${msg.photons.toLocaleString()}`]);
      rows.push(["n_Rec / n_R", `${(msg.segments_removed).toLocaleString()} / ${msg.segments.toLocaleString()}`]);
      rows.push(["dynamic points", msg.points.toLocaleString()]);
    }
    if (msg.kind === "light") {
      rows.push([`light ${msg.light}`, msg.reused ? `reused (position ${msg.frame})` : "recomputed"]);
      rows.push(["by", msg.by]);
      rows.push(["paths traced", msg.paths_traced.toLocaleString()]);
      if (msg.why) rows.push(["no reuse", msg.why]);
    }
    if (msg.switched) rows.push(["new session", msg.method]);
    const now = performance.now();
    while (drawnTimes.length && drawnTimes[0] < now - 1000) drawnTimes.shift();
    rows.push(["updates/s (drawn)", drawnTimes.length.toString()]);
    if (msg.kind === "move" && state.moveToFrame != null) rows.push(["move to frame (ms)", state.moveToFrame.toFixed(0)]);
    $("stats").innerHTML = rows.map(([a, b]) => `<tr><td>${a}</td><td>${b}</td></tr>`).join("");
  }
  function drawPlot() {
    const c = $("plot"), g = c.getContext("2d"), now = performance.now();
    while (plot.length && plot[0].t < now - PLOT_SECONDS * 1000) plot.shift();
    g.clearRect(0, 0, c.width, c.height);
    const top = Math.max(50, ...plot.map(p => p.ms));
    g.strokeStyle = "#444";
    g.beginPath(); g.moveTo(0, c.height - 33 / top * c.height); g.lineTo(c.width, c.height - 33 / top * c.height); g.stroke();
    g.fillStyle = "#8cf";
    for (const p of plot) {
      const x = c.width * (1 - (now - p.t) / (PLOT_SECONDS * 1000));
      const h = p.ms / top * c.height;
      g.fillRect(x, c.height - h, 2, h);
    }
    g.fillStyle = "#999";
    g.fillText(`${top.toFixed(0)} ms`, 2, 10);
    g.fillText("33 ms", c.width - 34, c.height - 33 / top * c.height - 2);
  }
  ws.onmessage = e => {
    if (typeof e.data !== "string") { applyFrame(e.data); return; }
    const msg = JSON.parse(e.data);
    state.log.push(msg.type);
    if (msg.type === "hello") {
      state.hello = msg;
      state.connection = msg.connection;
      describe(msg);
      $("status").textContent = `${scene.vertices.toLocaleString()} vertices (${scene.points.toLocaleString()} ` +
        `queried), ${msg.photons.toLocaleString()} photons ` +
        `(${msg.segments.toLocaleString()} segments), session ${msg.connection}`;
      state.ready = true;
    } else if (msg.type === "update") {
      state.updates++;
      state.lastUpdate = msg;
      describe(msg);
      plot.push({t: performance.now(), ms: 1e3 * (msg.seconds.server || msg.seconds.total)});
      statsDirty = true;
      if (msg.kind === "move" || msg.kind === "light") {
        if (moveInFlight) answers.push(performance.now() - lastMoveSent);
        if (answers.length > 8) answers.shift();
        moveInFlight = false;
      }
      $("error").textContent = "";
    } else if (msg.type === "synced") {
      describe(msg);
      const resolve = waiting.get(msg.id);
      waiting.delete(msg.id);
      if (resolve) resolve(msg);
    } else if (msg.type === "render_started") {
      renderStarted = performance.now();
      $("render-progress").hidden = false;
      $("render-progress").value = 0;
      $("render-result").textContent = `rendering ${msg.width} x ${msg.height}...`;
    } else if (msg.type === "render_progress") {
      const seconds = ((performance.now() - renderStarted) / 1000).toFixed(1);
      if (msg.stage === "final") { // the last step: the exact direct light and the gather, nothing to count
        $("render-progress").removeAttribute("value"); // an indeterminate bar
        $("render-result").textContent = `rendering: ${msg.paths.toLocaleString()} paths traced; ` +
          `the direct light and the gathered light (${seconds} s so far)`;
      } else {
        $("render-progress").value = msg.traced / msg.paths;
        $("render-result").textContent = `rendering: ${msg.traced.toLocaleString()} / ${msg.paths.toLocaleString()} ` +
          `paths, ${seconds} s`;
      }
    } else if (msg.type === "rendered") {
      renderInfo = msg;
    } else if (msg.type === "baked") {
      bakeInfo = msg;
    } else if (msg.type === "error") {
      if (msg.request === "render") { $("render-progress").hidden = true; $("render-result").textContent = ""; }
      showError(msg.message);
      moveInFlight = false;
      if ((msg.request === "move" || msg.request === "light") && !drag) {
        for (const name in state.serverPoses) state.poses[name] = state.serverPoses[name].slice();
        for (const name in state.serverLights) state.lights[name] = state.serverLights[name].slice();
        redraw = true;
      }
    }
  };
  ws.onclose = () => { $("status").textContent = "the server closed the connection"; };

  // "render this view": the engine's image from this camera, at the session's poses and lights
  let renders = 0, renderStarted = 0, renderInfo = null;
  const renderWaiting = new Map(); // render id -> resolve
  function renderCamera(width) { // the render request of this view (plain: the photons' estimate alone)
    const f = frame();
    const height = Math.max(1, Math.round(width * canvas.clientHeight / canvas.clientWidth));
    return {camera: {position: f.eye, look_at: camera.target.slice(), up: [0, 1, 0], fov: camera.fov * 180 / Math.PI},
            width, height, plain: $("render-plain").checked};
  }
  function requestRender(width) {
    const id = ++renders;
    send({type: "render", id, ...renderCamera(width)});
    return new Promise(resolve => renderWaiting.set(id, resolve));
  }
  function pfm(radiance, w, h) { // the linear radiance as a PFM (bottom row first), for HDR tools
    const head = new TextEncoder().encode(`PF\n${w} ${h}\n-1.0\n`);
    const out = new Uint8Array(head.length + 12 * w * h);
    out.set(head, 0);
    const body = new Float32Array(3 * w * h);
    for (let y = 0; y < h; y++) body.set(radiance.subarray(3 * w * (h - 1 - y), 3 * w * (h - y)), 3 * w * y);
    out.set(new Uint8Array(body.buffer), head.length);
    return out;
  }
  function showRender(buf) {
    const view = new DataView(buf);
    const index = view.getUint32(4, true), w = view.getUint32(8, true), h = view.getUint32(12, true);
    const n = view.getUint32(16, true);
    const png = new Uint8Array(buf, 20, n);
    const radiance = new Float32Array(buf.slice(20 + n));
    const info = renderInfo || {};
    const url = URL.createObjectURL(new Blob([png], {type: "image/png"}));
    const hdr = URL.createObjectURL(new Blob([pfm(radiance, w, h)], {type: "application/octet-stream"}));
    const name = `oclgi-view-${index}`;
    $("render-progress").hidden = true;
    $("render-result").innerHTML = `${w} x ${h}, ${info.method}, ${(info.photons || 0).toLocaleString()} photons, ` +
      `${(info.seconds || 0).toFixed(1)} s: <a href="${url}" download="${name}.png">PNG</a> ` +
      `<a href="${hdr}" download="${name}.pfm">PFM (linear)</a><img src="${url}" alt="render ${index}">`;
    const entry = {id: info.id, index, width: w, height: h, png, radiance, info};
    state.renders.push(entry);
    const resolve = renderWaiting.get(info.id);
    renderWaiting.delete(info.id);
    if (resolve) resolve(entry);
  }
  // "bake this pose": the tessellation with the colours shown, as a glTF file
  let bakes = 0, bakeInfo = null;
  const bakeWaiting = new Map(); // bake id -> resolve
  function requestBake() {
    const id = ++bakes;
    $("bake-result").textContent = "baking...";
    send({type: "bake", id, exposure});
    return new Promise(resolve => bakeWaiting.set(id, resolve));
  }
  function showBake(buf) {
    const n = new DataView(buf).getUint32(4, true), glb = new Uint8Array(buf, 8, n), info = bakeInfo || {};
    const url = URL.createObjectURL(new Blob([glb], {type: "model/gltf-binary"}));
    $("bake-result").innerHTML = `${(n / 1024).toFixed(0)} KB: <a href="${url}" download="oclgi-bake-${info.id}.glb">` +
      `oclgi-bake-${info.id}.glb</a>`;
    const resolve = bakeWaiting.get(info.id);
    bakeWaiting.delete(info.id);
    if (resolve) resolve({id: info.id, glb, seq: info.seq});
  }
  $("bake").onclick = () => requestBake();

  $("render").onclick = () => {
    const w = Math.round(Number($("render-width").value));
    if (!(w >= 1 && w <= 4096)) { showError("render: the width must be 1 to 4096 pixels"); return; }
    requestRender(w);
  };

  $("apply").onclick = () => {
    const msg = {type: "estimator"};
    const method = $("method").value, radius = Number($("radius").value), k = Number($("k").value);
    if (state.session && method !== state.session.method) msg.method = method;
    if (!$("radius").disabled && radius !== state.session.radius) msg.radius = radius;
    if (!$("k").disabled && k !== state.session.k) msg.k = k;
    if (Object.keys(msg).length > 1) send(msg);
    const photons = Number($("photons").value);
    if (state.session && photons !== state.session.photons) send({type: "photons", count: photons});
  };

  // mouse and keys: orbit, pan, zoom; pick and drag a movable object on its support plane
  let drag = null;
  // A move goes out at once when the server has answered the last one, else
  // it waits (replacing any older one) for that answer: the page keeps at
  // most one move in flight, the server coalesces whatever queues up there.
  let moveInFlight = false;
  function poseInterval() { // how long a pose alone waits after the frame before, while a move is on its way
    const usual = answers.length ? answers.slice().sort((a, b) => a - b)[answers.length >> 1] : 0;
    return Math.min(Math.max(usual + DISPLAY_FRAME_MS, MOTION_INTERVAL_MS), POSE_INTERVAL_MAX_MS);
  }
  function flushMoves() {
    if ((!pendingMoves.size && !pendingLights.size) || moveInFlight || ws.readyState !== WebSocket.OPEN) return;
    for (const [name, matrix] of pendingMoves) send({type: "move", object: name, matrix});
    for (const [name, position] of pendingLights) send({type: "light", light: name, position});
    pendingMoves.clear();
    pendingLights.clear();
    moveInFlight = true;
    lastMoveSent = performance.now();
  }
  function queueMove(name, matrix) {
    state.poses[name] = matrix;
    pendingMoves.set(name, matrix);
    moved();
    flushMoves();
  }
  function queueLight(name, position) {
    state.lights[name] = position;
    pendingLights.set(name, position);
    moved();
    flushMoves();
  }
  function planeHit(r, y) {
    if (Math.abs(r.dir[1]) < 1e-9) return null;
    const t = (y - r.origin[1]) / r.dir[1];
    return t > 0 ? add(r.origin, scale(r.dir, t)) : null;
  }
  canvas.addEventListener("contextmenu", e => e.preventDefault());
  window.addEventListener("resize", changed);
  canvas.addEventListener("pointerdown", e => {
    canvas.setPointerCapture(e.pointerId);
    const x = e.offsetX, y = e.offsetY;
    const hitLight = e.button === 0 && !e.shiftKey ? pickLight(x, y) : null;
    if (hitLight) { drag = {kind: "light", light: hitLight.name, height: state.lights[hitLight.name][1]}; changed(); return; }
    const handle = e.button === 0 && !e.shiftKey ? pickGizmo(x, y) : null;
    if (handle) {
      const i = selected - 1, name = objects[i].name, g = gizmoPoints(i);
      const c = project(g.centre) || [x, y];
      const d = Math.hypot(...sub(g.centre, frame().eye));
      drag = {kind: handle, name, x, y, centre: g.centre, screenCentre: c, matrix: state.poses[name].slice(),
              perPixel: 2 * d * Math.tan(camera.fov / 2) / canvas.clientHeight,
              angle: Math.atan2(-(y - c[1]), x - c[0])};
      return;
    }
    const hitObject = e.button === 0 && !e.shiftKey ? pick(x, y) : 0;
    changed(); // the selection's highlight, and the picking pass drew into another target
    if (hitObject > 0) {
      selected = hitObject;
      const i = hitObject - 1, name = objects[i].name;
      const base = objectBox(i).lo[1]; // the horizontal plane through its base
      const start = planeHit(ray(x, y), base);
      drag = start ? {kind: "object", name, base, start, matrix: state.poses[name].slice()} : null;
    } else {
      if (e.button === 0 && !e.shiftKey) selected = 0;
      drag = {kind: e.button === 2 || e.shiftKey ? "pan" : "orbit", x, y};
    }
  });
  canvas.addEventListener("pointermove", e => {
    if (!drag) return;
    const x = e.offsetX, y = e.offsetY;
    if (drag.kind === "light") {
      const l = lights.find(l => l.name === drag.light);
      // near a precomputed position: exactly there (the server reuses the stored paths)
      const snap = (l.path || []).find(q => { const p = project(q); return p && Math.hypot(p[0] - x, p[1] - y) <= 8; });
      const p = snap ? snap.slice() : planeHit(ray(x, y), drag.height);
      if (p) queueLight(drag.light, p);
      return;
    }
    if (drag.kind === "height") { // the pointer's rise on screen, at the object's depth
      queueMove(drag.name, mul(translation(0, (drag.y - y) * drag.perPixel, 0), drag.matrix));
      return;
    }
    if (drag.kind === "turn") { // about the vertical through its centre, following the pointer round it
      const a = Math.atan2(-(y - drag.screenCentre[1]), x - drag.screenCentre[0]) - drag.angle;
      const c = drag.centre, turn = camera.pitch >= 0 ? a : -a; // seen from below, screen turns flip
      queueMove(drag.name, mul(translation(c[0], 0, c[2]), mul(rotationY(turn), mul(translation(-c[0], 0, -c[2]),
                                                                                      drag.matrix))));
      return;
    }
    if (drag.kind === "object") {
      const p = planeHit(ray(x, y), drag.base);
      if (p) {
        const d = sub(p, drag.start);
        queueMove(drag.name, mul(translation(d[0], 0, d[2]), drag.matrix));
      }
      return;
    }
    const dx = x - drag.x, dy = y - drag.y;
    drag.x = x; drag.y = y;
    moved();
    if (drag.kind === "orbit") {
      camera.yaw -= dx * 0.008;
      camera.pitch = Math.max(-1.5, Math.min(1.5, camera.pitch + dy * 0.008));
    } else {
      const f = frame(), s = 2 * camera.distance * Math.tan(camera.fov / 2) / canvas.clientHeight;
      camera.target = add(camera.target, add(scale(f.rightUnit, -dx * s), scale(f.upUnit, dy * s)));
    }
  });
  canvas.addEventListener("pointerup", () => { drag = null; moved(); });
  canvas.addEventListener("wheel", e => {
    e.preventDefault();
    camera.distance *= Math.exp(e.deltaY * 0.001);
    moved();
  }, {passive: false});
  window.addEventListener("keydown", e => {
    if (!selected || e.target.tagName === "INPUT") return;
    const i = selected - 1, name = objects[i].name, m = state.poses[name];
    const step = 0.01 * scene.diagonal;
    if (e.key === "Escape") { selected = 0; changed(); return; }
    let t = null;
    if (e.key === "r" || e.key === "R" || e.key === "PageUp") t = translation(0, step, 0);
    else if (e.key === "f" || e.key === "F" || e.key === "PageDown") t = translation(0, -step, 0);
    else if (e.key === "q" || e.key === "Q" || e.key === "e" || e.key === "E") {
      const c = objectBox(i).centre, a = (e.key.toLowerCase() === "q" ? 1 : -1) * Math.PI / 18;
      t = mul(translation(c[0], 0, c[2]), mul(rotationY(a), translation(-c[0], 0, -c[2])));
    }
    if (t) queueMove(name, mul(t, m));
  });

  function tick(frameTime) {
    const want = wantedLevel();
    if (want !== serverLevel && ws.readyState === WebSocket.OPEN) { send({type: "level", level: want}); serverLevel = want; }
    const level = levelToShow(), motion = moving();
    if (level !== shown || motion !== shownMotion) { shown = level; shownMotion = motion; redraw = true; }
    upload(meshes[shown]); // a mesh not drawn keeps its changes until it is
    const newColours = meshes[shown].seq !== state.drawnSeq;
    if (redraw && shownMotion && !newColours && moveInFlight && performance.now() - state.drawnAt < poseInterval()) {
      // a new pose only, too soon after the last frame: at a later display frame (redraw stays set)
    } else if (redraw) {
      if (shownMotion && !newColours && moveInFlight) { // a pose alone while its answer is on its way (for tests)
        state.poseGaps.push(performance.now() - state.drawnAt);
        if (state.poseGaps.length > 64) state.poseGaps.shift();
      }
      draw(false);
      placeMarkers();
      redraw = false;
      state.draws++;
      state.drawnAt = performance.now();
      state.drawnLevel = shown;
      state.drawnMotion = shownMotion;
      state.drawsByLevel[shown]++;
      if (state.drawnSeq !== meshes[shown].seq) { // a new update's colours on screen
        if (state.timeDraws) finish(); // (a benchmark's: when the frame is done, not just asked for)
        state.drawnDoneAt = performance.now();
        state.drawnFrameAt = frameTime; // the display frame it is shown in (its rAF time)
        drawnTimes.push(state.drawnAt);
        state.drawnSeq = meshes[shown].seq;
      }
    }
    const now = performance.now();
    if (moveInFlight && now - lastMoveSent > 2000) moveInFlight = false; // an answer lost: never stall a drag
    flushMoves();
    if (statsDirty && now - statsShown > 250) { // text and plot a few times a second, not every frame
      showStats(state.lastUpdate);
      drawPlot();
      statsDirty = false;
      statsShown = now;
    }
    requestAnimationFrame(tick);
  }
  requestAnimationFrame(tick);

  // for tests and benchmarks: the same paths the mouse takes, and a sync
  state.api = {
    project, pick, objectBox, home, gizmoPoints, select(i) { selected = i; changed(); },
    camera: () => ({...camera}),
    orbit(dyaw, dpitch) { camera.yaw += dyaw; camera.pitch += dpitch; moved(); },
    move: queueMove,
    moveLight: queueLight,
    render: requestRender,
    bake: requestBake,
    renderCamera,
    pickLight: (x, y) => { const l = pickLight(x, y); return l ? l.name : null; },
    sync() { // answered once the server has done everything sent before it
      for (const [name, matrix] of pendingMoves) send({type: "move", object: name, matrix});
      for (const [name, position] of pendingLights) send({type: "light", light: name, position});
      pendingMoves.clear();
      pendingLights.clear();
      const id = ++syncs;
      return new Promise(resolve => { waiting.set(id, resolve); send({type: "sync", id}); });
    },
    send,
    drawMs(n = 5, level = 0, motion = false) { // ms of one frame of mesh ``level``, drawn and finished (median)
      upload(meshes[level]);
      const ms = measure(level, motion, n);
      redraw = true;
      return ms;
    },
    frameTimes(full, motion = []) { // the draw times as if measured (a test's fast or slow browser); the level chosen
      state.frameMs = {full, motion: meshes.map((_, k) => motion[k] == null ? null : motion[k])};
      return chooseLevel();
    },
    levels: () => meshes.length - 1,
    levelColours: k => ({colours: Array.from(meshes[k].colours), e: meshes[k].e, seq: meshes[k].seq}),
  };
}

main().catch(err => showError(String(err && err.message || err)));
