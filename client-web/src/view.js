// The three.js scene of one SceneDescription: the body's surface, the proxies drawn as their shapes, an
// arrow per proxy for its contact force, each device's own pose where it left its proxy (ghosts.js), and,
// when asked for, the simulation mesh's boundary as a wireframe.
//
// The surface is interpolated on the GPU: each state frame is written once, when it arrives, into one of
// three vertex-buffer slots (positions as 16-bit integers over a box around the body, colours as bytes);
// the vertex shader mixes the older and the newer of the two slots in use with the weight the frame
// buffer gives for the display time, so that a screen frame sends one number, not the surface. The slot
// written is the one no recent frame drew: writing a vertex buffer the GPU may still read makes a software
// renderer wait or copy, which at 20 k vertices costs more than drawing (tens of ms a frame). Normals are
// each triangle's own, from screen-space derivatives (flat shading): nothing is computed per frame on the CPU.
import * as THREE from 'three';

import { viridisBytes } from './colormap.js';
import { frontTriangles } from './cull.js';
import { computeUniqueEdges } from './edges.js';
import { EmbeddedSurfaceView } from './embedded.js';
import { DeviceGhosts } from './ghosts.js';
import { makeProxyGeometry, shapeName } from './shapes.js';
/** @import { ProxyInfoT, SceneDescriptionT } from '@tactile/proto' */

const VIRIDIS = viridisBytes();
const NO_POSES = new Float32Array(0);

// The wireframe's colour: off the colour map (whose blue stays under 0.56) and the background.
export const WIRE_COLOUR = [0.93, 0.95, 1.0];

// The surface's shading where the CPU draws (software renderers): a light at the camera and an ambient
// floor, on each triangle's own normal, in one short shader with two varyings, front faces only. three.js's Lambert, with
// its light loop, colour management and the attributes it declares, cost half the frame rate in
// SwiftShader on the same mesh (client-web/bench/render_bench.mjs, 20 k vertices). The colours are the
// colour map's bytes as they are, so the surface shows the legend's colours exactly.
/** @param {{ [name: string]: THREE.IUniform }} uniforms */
function lowQualityMaterial(uniforms) {
  return new THREE.ShaderMaterial({
    uniforms,
    // The surface is wound outward (the server's SceneDescription): the faces turned away are culled,
    // half of a closed body's triangles, before they cost any pixels.
    side: THREE.FrontSide,
    vertexShader: `
      attribute vec3 posA;
      attribute vec3 posB;
      attribute vec3 colA;
      attribute vec3 colB;
      uniform float surfaceMix;
      uniform vec3 surfaceCentre;
      uniform float surfaceHalf;
      varying vec3 vView;
      varying vec3 vColour;
      void main() {
        vec4 p = modelViewMatrix * vec4(surfaceCentre + surfaceHalf * mix(posA, posB, surfaceMix), 1.0);
        vView = p.xyz;
        vColour = mix(colA, colB, surfaceMix);
        gl_Position = projectionMatrix * p;
      }`,
    fragmentShader: `
      varying vec3 vView;
      varying vec3 vColour;
      void main() {
        vec3 n = normalize(cross(dFdx(vView), dFdy(vView)));
        float light = abs(dot(n, normalize(vec3(0.3, 0.6, 0.75))));  // from above the camera, either side lit
        gl_FragColor = vec4(vColour * (0.35 + 0.65 * light), 1.0);
      }`,
  });
}

// The simulation mesh's edges, placed as the surface is (the same slots, mixed with the same weight), in
// one colour. Each vertex is drawn `wireLift` [m] nearer the eye than it is, so that the edges of the faces
// turned to the eye pass the depth test against a fine surface they lie just under (a chord of a curved
// surface) or on (the boundary itself), while those of the far side stay hidden behind the body.
/** @param {{ [name: string]: THREE.IUniform }} uniforms */
function wireMaterial(uniforms) {
  return new THREE.ShaderMaterial({
    uniforms,
    vertexShader: `
      attribute vec3 posA;
      attribute vec3 posB;
      uniform float surfaceMix;
      uniform vec3 surfaceCentre;
      uniform float surfaceHalf;
      uniform float wireLift;
      void main() {
        vec4 p = modelViewMatrix * vec4(surfaceCentre + surfaceHalf * mix(posA, posB, surfaceMix), 1.0);
        p.xyz *= max(0.0, 1.0 - wireLift / max(length(p.xyz), 1e-9));
        gl_Position = projectionMatrix * p;
      }`,
    fragmentShader: `
      uniform vec3 wireColour;
      void main() {
        gl_FragColor = vec4(wireColour, 1.0);
      }`,
  });
}

export class SceneView {
  // `quality`: 'high' shades physically (MeshStandardMaterial) with shadows; 'low' (software renderers)
  // with a camera light in a shader of its own (lowQualityMaterial), a fraction of the cost.
  /** @param {THREE.Scene} scene @param {SceneDescriptionT} description @param {string} [quality] */
  constructor(scene, description, quality = 'high') {
    this.root = new THREE.Group();
    scene.add(this.root);
    const rest = new Float32Array(description.restPositions);
    const n = rest.length / 3;
    this.rest = rest; // the rest shape [m] (readers: tests pick vertices by it)
    this.positions = new Float32Array(rest); // the newest state's positions [m] (CPU copy: picking, readers)
    this.scalars = new Float32Array(n); // and its scalars
    this.scalarRange = [0, 1e-9];
    // The box positions are quantized over: a cube around the rest shape, three times its size; widened
    // when a state leaves it.
    const box = new THREE.Box3().setFromArray(rest);
    this.centre = box.getCenter(new THREE.Vector3());
    this.half = Math.max(1e-3, 1.5 * Math.max(...box.getSize(new THREE.Vector3()).toArray()));
    const index = new THREE.BufferAttribute(new Uint32Array(description.triangles), 1);
    const geometry = new THREE.BufferGeometry();
    geometry.setIndex(index);
    geometry.setAttribute('position', new THREE.BufferAttribute(rest, 3)); // bounds only: the shader moves it
    // Four components a vertex, the fourth unused: SwiftShader reads 4 x int16 and 4 x uint8 as they are,
    // where ANGLE widens 3-component 16- and 8-bit formats on the CPU after every write (render_bench, 20 k
    // vertices: 17.7-19.5 -> 21-27 fps, alternated runs).
    this.slots = [0, 1, 2].map(() => {
      const p = new THREE.BufferAttribute(new Int16Array(4 * n), 4, true);
      const c = new THREE.BufferAttribute(new Uint8Array(4 * n), 4, true);
      p.setUsage(THREE.DynamicDrawUsage);
      c.setUsage(THREE.DynamicDrawUsage);
      return { p, c };
    });
    this.older = 0;
    this.newer = 1;
    this.uniforms = {
      surfaceMix: { value: 1 },
      surfaceCentre: { value: this.centre },
      surfaceHalf: { value: this.half },
    };
    for (const k of [0, 1]) this.writeSlot(this.slots[k], rest, this.scalars);
    this.bindSlots(geometry);
    geometry.computeBoundingSphere();
    this.geometry = geometry;
    /** @param {THREE.WebGLProgramParametersWithUniforms} shader @param {boolean} colours */
    const inject = (shader, colours) => {
      Object.assign(shader.uniforms, this.uniforms);
      shader.vertexShader =
        'attribute vec3 posA;\nattribute vec3 posB;\nattribute vec3 colA;\nattribute vec3 colB;\n' +
        'uniform float surfaceMix;\nuniform vec3 surfaceCentre;\nuniform float surfaceHalf;\n' +
        shader.vertexShader.replace(
          '#include <begin_vertex>',
          'vec3 transformed = surfaceCentre + surfaceHalf * mix(posA, posB, surfaceMix);',
        );
      if (colours) {
        shader.vertexShader = shader.vertexShader.replace(
          '#include <color_vertex>',
          'vColor = mix(colA, colB, surfaceMix);',
        );
      }
    };
    let material;
    if (quality === 'high') {
      material = new THREE.MeshStandardMaterial({
        vertexColors: true,
        roughness: 0.55,
        metalness: 0.0,
        side: THREE.DoubleSide,
        flatShading: true,
      });
      material.onBeforeCompile = (shader) => inject(shader, true);
    } else {
      material = lowQualityMaterial(this.uniforms);
    }
    // Where the CPU draws, only the triangles that face the eye are sent (see cull.js), from one of three
    // index arrays in turn, for the same reason as the slots.
    this.culls =
      quality === 'high'
        ? null
        : [0, 1, 2].map(() =>
            new THREE.BufferAttribute(new Uint32Array(index.count), 1).setUsage(THREE.DynamicDrawUsage),
          );
    this.cullNext = 0;
    this.olderPositions = new Float32Array(rest); // the older state's positions, for the cull
    this.eye = new THREE.Vector3();
    this.eyeXyz = [0, 0, 0];
    this.mesh = new THREE.Mesh(geometry, material);
    this.mesh.frustumCulled = false; // it deforms past its rest bounds; it is the scene's subject anyway
    this.mesh.castShadow = true;
    this.mesh.receiveShadow = true;
    // The shadow pass draws the surface where the shader puts it too.
    const depth = new THREE.MeshDepthMaterial({ depthPacking: THREE.RGBADepthPacking });
    depth.onBeforeCompile = (shader) => inject(shader, false);
    this.mesh.customDepthMaterial = depth;
    this.root.add(this.mesh);
    // A fine surface the body carries (protocol 1.7) is what the body looks like: the boundary above is
    // then not drawn (its frames still move the fine surface, and a pointer still picks on it).
    /** @type {EmbeddedSurfaceView | null} */
    this.embedded = null;
    if (description.embedded && description.embedded.triangles && description.embedded.triangles.length > 0) {
      this.embedded = new EmbeddedSurfaceView(description.embedded, rest, this.uniforms.surfaceMix, quality);
      for (const k of [0, 1]) this.embedded.write(k, rest, /** @type {Uint8Array} */ (this.slots[k].c.array));
      this.embedded.bind(this.older, this.newer);
      this.mesh.visible = false;
      this.root.add(this.embedded.mesh);
    }
    // What a pointer picks: the newest state's surface, on the CPU (never drawn).
    const pickGeometry = new THREE.BufferGeometry();
    pickGeometry.setIndex(index);
    this.pickAttr = new THREE.BufferAttribute(this.positions, 3);
    pickGeometry.setAttribute('position', this.pickAttr);
    this.pick = new THREE.Mesh(pickGeometry, new THREE.MeshBasicMaterial({ side: THREE.DoubleSide }));
    this.size = /** @type {THREE.Sphere} */ (geometry.boundingSphere).radius || 0.05; // (computed above)

    this.proxies = (description.proxies || []).map((p) => this.makeProxy(p));
    this.arrows = this.proxies.map(() => {
      const a = new THREE.ArrowHelper(new THREE.Vector3(0, 1, 0), new THREE.Vector3(), 0.001, 0xff5533);
      a.visible = false;
      this.root.add(a);
      return a;
    });
    this.forces = new Float32Array(3 * this.proxies.length);
    this.tmp = new THREE.Vector3();
    this.ghosts = new DeviceGhosts(this.root, description, this.size);

    // The simulation mesh (the boundary's edges over the frame vertices), hidden until asked for. It reads
    // the surface's slots: a state costs it nothing more. Lifted toward the eye by 4 % of the body's size
    // over a fine surface (the coarse faces' chords lie under it by their sagitta, a few mm on the organ
    // scene), by 0.4 % over the boundary itself (only to win the depth test).
    const wireGeometry = new THREE.BufferGeometry();
    wireGeometry.setIndex(new THREE.BufferAttribute(computeUniqueEdges(description.triangles), 1));
    wireGeometry.setAttribute('position', geometry.getAttribute('position'));
    this.wireUniforms = {
      ...this.uniforms,
      wireLift: { value: (this.embedded ? 0.04 : 0.004) * this.size },
      wireColour: { value: new THREE.Color().fromArray(WIRE_COLOUR) },
    };
    this.wire = new THREE.LineSegments(wireGeometry, wireMaterial(this.wireUniforms));
    this.wire.name = 'simulation mesh';
    this.wire.frustumCulled = false; // the shader moves it, as the surface
    this.wire.visible = false;
    this.edges = wireGeometry.index ? wireGeometry.index.count / 2 : 0;
    this.bindSlots();
    this.root.add(this.wire);
  }

  // Shows or hides the simulation mesh's wireframe.
  /** @param {boolean} shown */
  setWire(shown) {
    this.wire.visible = shown;
  }

  /** @param {ProxyInfoT} info */
  makeProxy(info) {
    const plane = shapeName(info) === 'plane';
    const material = new THREE.MeshStandardMaterial({
      color: 0xd0d4dc,
      roughness: 0.3,
      metalness: 0.2,
      transparent: plane,
      opacity: plane ? 0.3 : 1,
    });
    const mesh = new THREE.Mesh(makeProxyGeometry(info, this.size), material);
    mesh.castShadow = !plane;
    mesh.name = /** @type {string | null} */ (info.name) || '';
    this.root.add(mesh);
    return mesh;
  }

  bindSlots(geometry = this.geometry) {
    const a = this.slots[this.older];
    const b = this.slots[this.newer];
    geometry.setAttribute('posA', a.p);
    geometry.setAttribute('posB', b.p);
    geometry.setAttribute('colA', a.c);
    geometry.setAttribute('colB', b.c);
    if (this.wire) {
      this.wire.geometry.setAttribute('posA', a.p);
      this.wire.geometry.setAttribute('posB', b.p);
    }
    if (this.embedded) this.embedded.bind(this.older, this.newer);
  }

  // Positions quantized over the box, and scalars as colours over the range seen so far (it only widens,
  // so that colours do not flicker).
  /**
   * @param {{ p: THREE.BufferAttribute, c: THREE.BufferAttribute }} slot
   * @param {ArrayLike<number>} positions @param {ArrayLike<number>} scalars
   */
  writeSlot(slot, positions, scalars) {
    const p = slot.p.array;
    const k = 32767 / this.half;
    const c = this.centre;
    for (let i = 0, j = 0; i < positions.length; i += 3, j += 4) {
      p[j] = Math.round((positions[i] - c.x) * k);
      p[j + 1] = Math.round((positions[i + 1] - c.y) * k);
      p[j + 2] = Math.round((positions[i + 2] - c.z) * k);
    }
    slot.p.needsUpdate = true;
    const [lo, hi] = this.scalarRange;
    const scale = 255 / (hi - lo || 1);
    const col = slot.c.array;
    for (let i = 0; i < scalars.length; i++) {
      const u = (scalars[i] - lo) * scale;
      const k = 3 * (u >= 255 ? 255 : u > 0 ? Math.round(u) : 0); // (NaN reads as 0)
      col[4 * i] = VIRIDIS[k];
      col[4 * i + 1] = VIRIDIS[k + 1];
      col[4 * i + 2] = VIRIDIS[k + 2];
    }
    slot.c.needsUpdate = true;
    if (this.embedded) this.embedded.write(this.slots.indexOf(slot), positions, /** @type {Uint8Array} */ (col));
  }

  // Another field chosen: its colours span the range it shows from the next state on (from zero, for a
  // magnitude such as the displacement, so that rest is the map's first colour).
  /** @param {boolean} fromZero */
  resetScalarRange(fromZero) {
    this.scalarRange[0] = fromZero ? 0 : Infinity;
    this.scalarRange[1] = fromZero ? 1e-9 : -Infinity;
  }

  // A new state (positions [m], n x 3; scalars, n): written once into the free slot, which becomes the
  // newer; `older` (the frame before it, as the frame buffer holds it) is rewritten only when the box or
  // the colour range had to widen.
  /**
   * @param {Float32Array} positions @param {Float32Array} scalars
   * @param {Float32Array} older @param {Float32Array} olderScalars
   */
  pushState(positions, scalars, older, olderScalars) {
    let far = 0;
    const c = this.centre;
    for (let i = 0; i < positions.length; i += 3) {
      far = Math.max(
        far,
        Math.abs(positions[i] - c.x),
        Math.abs(positions[i + 1] - c.y),
        Math.abs(positions[i + 2] - c.z),
      );
    }
    let lo = this.scalarRange[0];
    let hi = this.scalarRange[1];
    for (let i = 0; i < scalars.length; i++) {
      if (scalars[i] < lo) lo = scalars[i];
      if (scalars[i] > hi) hi = scalars[i];
    }
    const widened = far > this.half || lo < this.scalarRange[0] || hi > this.scalarRange[1];
    if (far > this.half) {
      while (this.half < far) this.half *= 2;
      this.uniforms.surfaceHalf.value = this.half;
    }
    this.scalarRange[0] = lo;
    this.scalarRange[1] = hi;
    const free = 3 - this.older - this.newer;
    this.writeSlot(this.slots[free], positions, scalars);
    this.older = this.newer;
    this.newer = free;
    if (widened) this.writeSlot(this.slots[this.older], older, olderScalars);
    this.bindSlots();
    this.olderPositions.set(older);
    this.positions.set(positions);
    this.scalars.set(scalars);
    this.pickAttr.needsUpdate = true;
    this.pick.geometry.computeBoundingSphere();
  }

  // Sends only the triangles that face `eye` (a THREE.Vector3 in world space) in the two states mixed on
  // screen, where the CPU draws; the count sent, or all of them where it does not cull.
  /** @param {THREE.Vector3} eye */
  cullFor(eye) {
    const all = /** @type {THREE.BufferAttribute} */ (this.pick.geometry.index); // (set in the constructor)
    if (this.embedded) return this.embedded.triangles; // the GPU culls it (its vertices are placed there)
    if (!this.culls) return all.count / 3;
    this.root.worldToLocal(this.eye.copy(eye));
    const out = this.culls[this.cullNext];
    this.cullNext = (this.cullNext + 1) % 3;
    const k = frontTriangles(all.array, this.olderPositions, this.positions, this.eye.toArray(this.eyeXyz), out.array);
    out.clearUpdateRanges();
    out.addUpdateRange(0, k);
    out.needsUpdate = true;
    this.geometry.setIndex(out);
    this.geometry.setDrawRange(0, k);
    return k / 3;
  }

  // The weight of the newer state on screen now (0..1).
  /** @param {number} w */
  setMix(w) {
    this.uniforms.surfaceMix.value = w;
  }

  // Proxy poses (n x 7: position, orientation w x y z), forces (n x 3) and the device channels' own poses
  // (n_devices x 7; empty before protocol 1.8) from a state frame.
  /** @param {Float32Array} poses @param {Float32Array} forces @param {Float32Array} [devicePoses] */
  updateProxies(poses, forces, devicePoses = NO_POSES) {
    for (let j = 0; j < this.proxies.length && 7 * j + 6 < poses.length; j++) {
      const m = this.proxies[j];
      m.position.set(poses[7 * j], poses[7 * j + 1], poses[7 * j + 2]);
      m.quaternion.set(poses[7 * j + 4], poses[7 * j + 5], poses[7 * j + 6], poses[7 * j + 3]);
      const a = this.arrows[j];
      const fx = forces[3 * j] || 0;
      const fy = forces[3 * j + 1] || 0;
      const fz = forces[3 * j + 2] || 0;
      this.forces[3 * j] = fx;
      this.forces[3 * j + 1] = fy;
      this.forces[3 * j + 2] = fz;
      const f = Math.hypot(fx, fy, fz);
      a.visible = f > 1e-4;
      if (a.visible) {
        // Proportional below a newton or so, and never longer than 0.8 of the body's size: 1 N is 0.27 of
        // it, 2 N 0.4, 8 N 0.64 (the force's value is in the scene panel).
        const len = (0.8 * this.size * f) / (f + 2);
        a.position.copy(m.position);
        a.setDirection(this.tmp.set(fx / f, fy / f, fz / f));
        a.setLength(len, Math.min(0.3 * len, 0.2 * this.size), Math.min(0.15 * len, 0.1 * this.size));
      }
    }
    this.ghosts.update(devicePoses, poses);
  }

  dispose() {
    if (this.embedded) this.embedded.dispose();
    this.pick.geometry.dispose();
    this.pick.material.dispose();
    this.root.traverse((o) => {
      // The surface, the proxies and the arrows' lines and cones, each with a geometry and a material of its own.
      const drawn = /** @type {THREE.Object3D & { geometry?: THREE.BufferGeometry, material?: THREE.Material }} */ (o);
      if (drawn.geometry) drawn.geometry.dispose();
      if (drawn.material) drawn.material.dispose();
    });
    this.root.removeFromParent();
  }
}
