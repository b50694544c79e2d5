// The browser view: connects to the server that serves this page, says Hello as a viewer, builds the
// scene from its SceneDescription and draws the body from its state frames, interpolated to the
// screen's rate. Around it: panels that fold away (panels.js), camera presets and fit-to-body (camera.js),
// the simulation mesh as a wireframe, and the keys for them.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

import {
  ControlCommand,
  Message,
  ResetT,
  Role,
  decode,
  makeViewFields,
  messageTypeOf,
  readStateFrame,
  checkVersion,
} from '@tactile/proto';
import 'uplot/dist/uPlot.min.css'; // (esbuild writes it to dist/app.css, which index.html links)

import { describeBodies } from './bodies.js';
import { PRESETS, START, applyFraming, computeBoundingSphere, viewDirection } from './camera.js';
import { cssGradient } from './colormap.js';
import { ClosedError, ServerError, connect } from './connection.js';
import { ControlPanel } from './controls.js';
import { FieldChoice } from './fields.js';
import { FrameBuffer } from './frames.js';
import { Panels } from './panels.js';
import { PointerDevice } from './pointer.js';
import { TelemetryPanel } from './telemetry.js';
import { Timeline } from './timeline.js';
import { SceneView } from './view.js';
/**
 * @import { DeviceStatusT, ErrorT, ReplayStatusT, SafetyEventT, SceneDescriptionT, TelemetryT }
 *   from '@tactile/proto'
 */
/** @import { Connection } from './connection.js' */

// (index.html has every element the page asks for by id.)
const $ = (/** @type {string} */ id) => /** @type {HTMLElement} */ (document.getElementById(id));
// A phone, or a window as narrow: the panels start folded, but for the legend (index.html's breakpoint).
const small = window.matchMedia('(max-width: 600px)').matches;
const panels = new Panels(document, small);
const status = (/** @type {string} */ text) => {
  $('status').textContent = text;
};

// Shadows and multisampling where a GPU draws; without them where the CPU does (SwiftShader, llvmpipe:
// headless browsers, remote desktops), which they would slow to a few frames a second.
// ?quality=high or ?quality=low overrides.
function softwareRendering() {
  const gl = document.createElement('canvas').getContext('webgl2');
  if (!gl) return true;
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  const name = info ? String(gl.getParameter(info.UNMASKED_RENDERER_WEBGL)) : '';
  gl.getExtension('WEBGL_lose_context')?.loseContext();
  return /swiftshader|llvmpipe|software/i.test(name);
}
const query = new URLSearchParams(location.search);
const quality = query.get('quality') ?? (softwareRendering() ? 'low' : 'high');
// The device and controller roles need the server's token: ?token=... (scripts/run.sh prints the URL with it).
const token = query.get('token') || '';
const wsUrl = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/`;
// The drawing buffer is not kept after it is shown (tests screenshot the page, never the canvas): keeping it
// costs SwiftShader a copy of the whole canvas a frame.
const renderer = new THREE.WebGLRenderer({ antialias: quality === 'high' });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.shadowMap.enabled = quality === 'high';
$('view').appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x20242c);
const camera = new THREE.PerspectiveCamera(40, 1, 0.001, 100);
const controls = new OrbitControls(camera, renderer.domElement);
scene.add(new THREE.HemisphereLight(0xdde6ff, 0x303030, 1.2));
const sun = new THREE.DirectionalLight(0xffffff, 2.0);
sun.castShadow = true;
sun.shadow.mapSize.set(1024, 1024);
scene.add(sun);
scene.add(sun.target);
$('legend-bar').style.background = cssGradient();
// What the body is coloured by (?field=von_mises, ... to start with one; the legend's menu changes it).
const fieldChoice = new FieldChoice(query.get('field') || undefined);
const fieldMenu = /** @type {HTMLSelectElement} */ ($('legend-field'));
const telemetry = new TelemetryPanel($('telemetry'));
// ?device=NAME: the channel the mouse drives (default: one meant for the page, such as 'mouse').
const pointer = new PointerDevice({
  canvas: renderer.domElement,
  camera,
  controls,
  token,
  wanted: query.get('device') || '',
  onStatus: (/** @type {string} */ text) => {
    $('poke').textContent = text;
  },
});

// What the tests read (and a person can, in the console).
/**
 * @type {{ frames: number, rendered: number, sceneId: number, sceneName: string, vertices: number,
 *   errors: ErrorT['message'][], lastStep: number, quality: string, decodeMs: number[], slotMs: number[],
 *   frameMs: number[], timeline?: Timeline, pointer?: PointerDevice, controls?: ControlPanel,
 *   project?: (x: number, y: number, z: number) => number[], fault?: string, view?: SceneView,
 *   drawnTriangles?: number, telemetry?: TelemetryT, deviceStatus?: DeviceStatusT, replay?: ReplayStatusT,
 *   camera: THREE.PerspectiveCamera, panels: Panels, plots: TelemetryPanel['plots'], wire: boolean,
 *   fit?: (preset?: string) => void }}
 */
const stats = {
  frames: 0,
  rendered: 0,
  sceneId: -1,
  sceneName: '',
  vertices: 0,
  errors: [],
  lastStep: 0,
  quality,
  decodeMs: [],
  slotMs: [],
  frameMs: [],
  camera,
  panels,
  plots: telemetry.plots,
  wire: false,
};
const controlPanel = new ControlPanel($('controls'), { token, url: wsUrl });
const timeline = new Timeline($('timeline'), controlPanel);
stats.timeline = timeline;
stats.pointer = pointer;
stats.controls = controlPanel;
// Where a scene point [m] is drawn, in CSS pixels of the page (for tests that point at the body).
stats.project = (x, y, z) => {
  camera.updateMatrixWorld(); // (a preset moves the camera between renders)
  const v = new THREE.Vector3(x, y, z).project(camera);
  const r = renderer.domElement.getBoundingClientRect();
  return [r.left + ((v.x + 1) / 2) * r.width, r.top + ((1 - v.y) / 2) * r.height];
};
/** @type {Window & { tactile?: typeof stats }} */ (window).tactile = stats;

// A fault that stopped the simulation (the telemetry names it until the scene is reset or another loaded):
// said in the middle of the page, with a reset, which takes control (with the token) and resets.
stats.fault = '';
const faultReset = /** @type {HTMLButtonElement} */ ($('fault-reset'));
faultReset.disabled = !token;
faultReset.title = token ? '' : 'resetting needs the token: open the URL with ?token=...';
faultReset.addEventListener('click', () => {
  controlPanel.sendWhenGranted(ControlCommand.Reset, new ResetT(), 'reset');
});
/** @param {string[]} faults */
function showFault(faults) {
  const text = faults.length ? `the simulation stopped: ${faults.join('; ')}` : '';
  if (text === stats.fault) return;
  stats.fault = text;
  $('fault-text').textContent = text;
  $('fault').hidden = !text;
}

/** @type {Connection | null} */
let socket = null;
let sentFields = ''; // the fields the server was last asked for, joined
/** @type {Float32Array} */
let scalarsNow = new Float32Array(0); // the chosen field at each frame vertex, of the newest frame

// Asks the server for the chosen field (or for none, for displacement) when that changed.
function askFields() {
  const asked = fieldChoice.asked();
  if (asked.join(',') === sentFields || !socket || !socket.open) return;
  socket.send(makeViewFields(asked));
  sentFields = asked.join(',');
}

function showFieldChoice() {
  fieldMenu.replaceChildren(
    ...fieldChoice.available.map((f) => {
      const o = document.createElement('option');
      o.value = f.name;
      o.textContent = f.name.replace(/_/g, ' ');
      o.title = f.description;
      return o;
    }),
  );
  fieldMenu.value = fieldChoice.name;
  const info = fieldChoice.info();
  $('legend-unit').textContent = info.unit ? `[${info.unit}]` : '';
  fieldMenu.title = info.description;
}
fieldMenu.addEventListener('change', () => {
  fieldChoice.name = fieldMenu.value;
  fieldChoice.wanted = fieldMenu.value;
  showFieldChoice();
  askFields();
  if (view) view.resetScalarRange(fieldChoice.fromZero());
  legendRange[0] = NaN; // (the ends' text is rewritten at the next screen frame)
});

/** @type {SceneView | null} */
let view = null;
/** @type {FrameBuffer | null} */
let buffer = null;
let cameraMoved = false; // since the last cull
const legendRange = [NaN, NaN]; // as the legend shows it
controls.addEventListener('change', () => {
  cameraMoved = true;
});
// Whether the camera stands where a preset or a fit put it (a resize then frames the body again); a person
// turning or moving the view takes it over.
let framed = false;
controls.addEventListener('start', () => {
  framed = false;
});
/** @type {THREE.Mesh<THREE.PlaneGeometry, THREE.ShadowMaterial> | null} */
let ground = null;

function resize() {
  const w = $('view').clientWidth;
  const h = $('view').clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(1, h);
  camera.updateProjectionMatrix();
  if (framed) frameBody(viewDirection(camera, controls));
  telemetry.resize();
}
window.addEventListener('resize', resize);
$('telemetry').addEventListener('toggle', () => telemetry.resize());

// Frames the bounding sphere of the body as drawn (its newest state's: the fine surface where the scene has
// one) from `direction` (camera - centre; the current one by default).
/** @param {ArrayLike<number>} [direction] */
function frameBody(direction = viewDirection(camera, controls)) {
  if (!view) return;
  const sphere = computeBoundingSphere(view.embedded ? view.embedded.place(view.positions) : view.positions);
  const d = Math.hypot(direction[0], direction[1], direction[2]) > 0 ? direction : START;
  applyFraming(camera, controls, sphere, d);
  framed = true;
  cameraMoved = true;
}
/** @type {{ [name: string]: ArrayLike<number> }} */
const presets = PRESETS;
stats.fit = (preset) => frameBody(preset ? presets[preset] : undefined);
for (const name of [...Object.keys(PRESETS), 'fit']) {
  $('camera')
    .querySelector(`button[name=view-${name}]`)
    ?.addEventListener('click', () => stats.fit?.(name === 'fit' ? undefined : name));
}

// The simulation mesh as a wireframe. By default off over a fine surface (it would hide what the body looks
// like), on over a bare boundary coarse enough for its edges to be told apart (WIRE_EDGES); off over a finer
// one, whose edges would paint the body over (and where the CPU draws, cost a third of the frame rate at
// 20 k vertices: render_bench --wire 1). The checkbox, the W key or ?wire=1 / ?wire=0 choose.
const WIRE_EDGES = 6000;
const wireBox = /** @type {HTMLInputElement} */ ($('wire'));
/** @type {boolean | null} */
let wireWanted = query.has('wire') ? query.get('wire') !== '0' : null;
function showWire() {
  stats.wire = wireWanted ?? (view !== null && !view.embedded && view.edges <= WIRE_EDGES);
  wireBox.checked = stats.wire;
  if (view) view.setWire(stats.wire);
}
wireBox.addEventListener('change', () => {
  wireWanted = wireBox.checked;
  showWire();
});

// Keys (not while typing in a field): 1-4 the presets, F fit, W the wireframe, H folds or opens the panels.
window.addEventListener('keydown', (e) => {
  const t = /** @type {HTMLElement | null} */ (e.target);
  if (e.ctrlKey || e.metaKey || e.altKey || (t && /^(INPUT|SELECT|TEXTAREA)$/.test(t.tagName) && t !== wireBox)) return;
  const key = e.key.toLowerCase();
  const preset = ['front', 'top', 'side', 'iso'][Number(key) - 1];
  if (preset) stats.fit?.(preset);
  else if (key === 'f') stats.fit?.();
  else if (key === 'w') {
    wireWanted = !stats.wire;
    showWire();
  } else if (key === 'h') {
    panels.toggleAll();
    telemetry.resize();
  } else return;
  e.preventDefault();
});

/** @param {SceneDescriptionT} d */
function onScene(d) {
  // The same body again (a reset, a parameter set) keeps the camera where it was; another is framed.
  const same =
    view !== null &&
    stats.sceneName === /** @type {string | null} */ (d.sceneName || '') &&
    view.rest.length === d.restPositions.length;
  if (view) view.dispose();
  view = new SceneView(scene, d, quality);
  stats.view = view;
  buffer = new FrameBuffer(view.positions.length, view.scalars.length);
  stats.sceneId = d.sceneId;
  stats.sceneName = /** @type {string | null} */ (d.sceneName) || '';
  showFault([]);
  stats.vertices = view.positions.length / 3;
  const bodies = describeBodies(d.bodies);
  $('scene').textContent =
    (view.embedded
      ? `${stats.sceneName}: ${view.embedded.triangles} triangles on ${stats.vertices} frame vertices, step ${(d.dt * 1e3).toFixed(3)} ms`
      : `${stats.sceneName}: ${stats.vertices} surface vertices, step ${(d.dt * 1e3).toFixed(3)} ms`) +
    (bodies ? `; ${bodies}` : '');
  fieldChoice.setDescription(d);
  showFieldChoice();
  askFields();
  view.resetScalarRange(fieldChoice.fromZero());
  scalarsNow = new Float32Array(view.scalars.length);
  showWire();
  resize();
  if (!same) frameBody(START);
  const s = /** @type {THREE.Sphere} */ (view.geometry.boundingSphere); // (SceneView computes it)
  const c = s.center;
  const r = s.radius || 0.05;
  sun.position.set(c.x + 2 * r, c.y + 5 * r, c.z + 3 * r);
  sun.target.position.copy(c);
  const cam = sun.shadow.camera;
  cam.left = cam.bottom = -3 * r;
  cam.right = cam.top = 3 * r;
  cam.near = r / 10;
  cam.far = 20 * r;
  cam.updateProjectionMatrix();
  if (ground) {
    ground.geometry.dispose();
    ground.material.dispose();
    scene.remove(ground);
    ground = null;
  }
  // The ground only catches the body's shadow: without shadows it would be a transparent pass over most
  // of the screen that draws nothing.
  if (renderer.shadowMap.enabled) {
    view.geometry.computeBoundingBox();
    ground = new THREE.Mesh(
      new THREE.PlaneGeometry(12 * r, 12 * r).rotateX(-Math.PI / 2),
      new THREE.ShadowMaterial({ opacity: 0.35 }),
    );
    ground.position.set(c.x, /** @type {THREE.Box3} */ (view.geometry.boundingBox).min.y - 1e-4, c.z);
    ground.receiveShadow = true;
    scene.add(ground);
  }
  pointer.setScene(d, view, wsUrl);
  controlPanel.setDescription(d);
}

/** @param {Uint8Array} data */
function onMessage(data) {
  const type = messageTypeOf(data);
  if (type === Message.StateFrame) {
    if (!buffer || !view) return; // (onScene makes both)
    const t0 = performance.now();
    const f = readStateFrame(data);
    if (f.sceneId !== stats.sceneId) return;
    if (buffer.count > 0 && f.simTime < buffer.tb) buffer.reset(); // a replay sought back
    const coloured = fieldChoice.values(f, view.rest, scalarsNow);
    const kept = buffer.push(f.positions, coloured ? scalarsNow : null, f.simTime, performance.now() / 1000);
    stats.decodeMs.push(performance.now() - t0); // read in place and copied into the buffer
    if (stats.decodeMs.length > 256) stats.decodeMs.shift();
    if (kept) {
      const t1 = performance.now();
      view.pushState(buffer.b, buffer.sb, buffer.a, buffer.sa);
      stats.drawnTriangles = view.cullFor(camera.position);
      cameraMoved = false;
      stats.slotMs.push(performance.now() - t1); // quantized and coloured into the free slot
      if (stats.slotMs.length > 256) stats.slotMs.shift();
      stats.frames += 1;
      stats.lastStep = Number(f.step);
      view.updateProxies(f.proxies, f.contactForces, f.devicePoses);
      pointer.observe(f.proxies);
      const forces = [];
      for (let j = 0; j < view.proxies.length; j++) {
        const n = Math.hypot(f.contactForces[3 * j], f.contactForces[3 * j + 1], f.contactForces[3 * j + 2]);
        forces.push(`${view.proxies[j].name || 'proxy ' + j}: ${n.toFixed(3)} N`);
      }
      $('forces').textContent = forces.join('  ');
      $('time').textContent = `t = ${f.simTime.toFixed(3)} s`;
    }
    return;
  }
  // The message is of the type the Envelope names (decode checked that it holds one); flatc types it as
  // the union of them all.
  const m = decode(data);
  switch (m.messageType) {
    case Message.SceneDescription:
      onScene(/** @type {SceneDescriptionT} */ (m.message));
      break;
    case Message.Error:
      serverSaid(/** @type {ErrorT} */ (m.message).message);
      break;
    case Message.Telemetry: {
      const t = /** @type {TelemetryT} */ (m.message);
      telemetry.update(t, pointer.latencies);
      controlPanel.setPaused(t.paused);
      showFault(t.faults || []);
      stats.telemetry = t;
      break;
    }
    case Message.SafetyEvent:
      telemetry.safety(/** @type {SafetyEventT} */ (m.message));
      break;
    case Message.DeviceStatus: {
      const d = /** @type {DeviceStatusT} */ (m.message);
      telemetry.deviceStatus(d);
      stats.deviceStatus = d;
      break;
    }
    case Message.ReplayStatus: {
      const r = /** @type {ReplayStatusT} */ (m.message);
      timeline.update(r);
      controlPanel.setReplaying(true);
      stats.replay = r;
      break;
    }
    default:
      break;
  }
}

// What went wrong, in the status line and in the errors the tests read: the server's word (an Error, or the
// reason it closed the connection), or what could not be read.
/** @param {ErrorT['message']} text */
function serverSaid(text) {
  status(`server: ${text}`);
  stats.errors.push(text);
}
/** @param {unknown} err */
function badMessage(err) {
  status(`bad message: ${/** @type {Error} */ (err).message}`);
  stats.errors.push(String(/** @type {Error} */ (err).message));
}

function connectViewer() {
  const url = wsUrl;
  const fields = fieldChoice.asked();
  // (Off loopback every role needs the token, the viewer's too.)
  const connection = connect(url, Role.Viewer, {
    token,
    clientName: 'client-web',
    fields,
    onOpen: () => {
      status(`connected to ${url}`);
      sentFields = fields.join(',');
    },
    onMessage: (data) => {
      try {
        onMessage(data);
      } catch (err) {
        badMessage(err);
      }
    },
    onClose: ({ reason }) => {
      // (A connection the server refused or evicted, close code 1013, is told why.)
      status(reason ? `server: ${reason} (reconnecting)` : 'disconnected: reconnecting');
      if (reason) stats.errors.push(reason);
      setTimeout(connectViewer, 1000);
    },
  });
  socket = connection;
  connection.welcome.then(checkVersion).catch((err) => {
    if (err instanceof ServerError) serverSaid(err.message);
    else if (!(err instanceof ClosedError)) badMessage(err); // (another major version too; a close is onClose's)
  });
}

function frame() {
  requestAnimationFrame(frame);
  const now = performance.now();
  pointer.tick(now);
  if (pointer.channel) {
    const f = pointer.force.length();
    $('feel').textContent =
      `${pointer.channel} feels ${f.toFixed(3)} N` +
      (Number.isFinite(pointer.latencyMs) ? `, input to force ${pointer.latencyMs.toFixed(1)} ms` : '');
  }
  if (view && buffer && buffer.count > 0) {
    view.setMix(buffer.weight(now / 1000));
    // Written only when the range widens: new text each frame would lay out and raster the legend again.
    const [lo, hi] = view.scalarRange;
    if (lo !== legendRange[0] || hi !== legendRange[1]) {
      legendRange[0] = lo;
      legendRange[1] = hi;
      const ends = fieldChoice.ends();
      $('legend-lo').textContent = ends ? ends[0] : lo.toPrecision(3);
      $('legend-hi').textContent = ends ? ends[1] : hi.toPrecision(3);
    }
  }
  controls.update();
  if (cameraMoved && view) {
    stats.drawnTriangles = view.cullFor(camera.position);
    cameraMoved = false;
  }
  renderer.render(scene, camera);
  stats.rendered += 1;
  stats.frameMs.push(performance.now() - now); // this frame's work: interpolate, normals, colours, draw
  if (stats.frameMs.length > 256) stats.frameMs.shift();
}

resize();
connectViewer();
frame();
