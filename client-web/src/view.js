// The three.js scene of one SceneDescription: the body's surface (positions and colours updated in
// place each frame), the proxies drawn as their shapes, and an arrow per proxy for its contact force.
import * as THREE from 'three';

import { viridis } from './colormap.js';

const SHAPES = ['sphere', 'capsule', 'box', 'plane'];

export class SceneView {
  // `quality`: 'high' shades physically (MeshStandardMaterial); 'low' (software renderers) with Lambert's
  // diffuse light, a fraction of the cost per pixel.
  constructor(scene, description, quality = 'high') {
    this.root = new THREE.Group();
    scene.add(this.root);
    const rest = description.restPositions;
    const n = rest.length / 3;
    this.scalars = new Float32Array(n);
    this.colors = new Float32Array(3 * n);
    this.scalarRange = [0, 1e-9];
    this.smooth = quality === 'high';
    // Two copies of the surface, drawn in turn: each frame writes the one the previous frame did not draw.
    // (A vertex buffer that the frame before drew from is still in use; writing it makes a software
    // renderer wait or copy, which at 10 k vertices costs more than the drawing.) The colours, which
    // change at the state rate, are one buffer both share; the triangles too.
    this.colorAttr = new THREE.BufferAttribute(this.colors, 3);
    this.colorAttr.setUsage(THREE.DynamicDrawUsage);
    const index = new THREE.BufferAttribute(new Uint32Array(description.triangles), 1);
    // Software renderers (quality low): Lambert's diffuse light with each triangle's own normal, taken from
    // screen-space derivatives, so that no normals are computed or sent per frame; GPUs: smooth normals and
    // physically based shading.
    const material = this.smooth
      ? new THREE.MeshStandardMaterial({ vertexColors: true, roughness: 0.55, metalness: 0.0, side: THREE.DoubleSide })
      : new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide, flatShading: true });
    this.surfaces = [0, 1].map(() => {
      const geometry = new THREE.BufferGeometry();
      const positions = new Float32Array(rest);
      const attr = new THREE.BufferAttribute(positions, 3);
      attr.setUsage(THREE.DynamicDrawUsage);
      geometry.setAttribute('position', attr);
      geometry.setAttribute('color', this.colorAttr);
      geometry.setIndex(index);
      if (this.smooth) geometry.computeVertexNormals();
      geometry.computeBoundingSphere();
      const mesh = new THREE.Mesh(geometry, material);
      mesh.castShadow = true;
      mesh.receiveShadow = true;
      mesh.frustumCulled = false;  // it deforms past its rest bounds; it is the scene's subject anyway
      this.root.add(mesh);
      return { geometry, positions, attr, mesh };
    });
    this.front = 0;  // the copy drawn last, and the one raycasts and readers see
    this.surfaces[1].mesh.visible = false;
    const geometry = this.geometry;
    this.size = geometry.boundingSphere.radius || 0.05;

    this.proxies = (description.proxies || []).map((p) => this.makeProxy(p));
    this.arrows = this.proxies.map(() => {
      const a = new THREE.ArrowHelper(new THREE.Vector3(0, 1, 0), new THREE.Vector3(), 0.001, 0xff5533);
      a.visible = false;
      this.root.add(a);
      return a;
    });
    this.forces = new Float32Array(3 * this.proxies.length);
    this.tmp = new THREE.Vector3();
    this.setScalars(this.scalars);
  }

  makeProxy(info) {
    const shape = SHAPES[info.shape] ?? 'sphere';
    let geometry;
    const r = info.radius || 0.005;
    if (shape === 'capsule') geometry = new THREE.CapsuleGeometry(r, 2 * (info.halfLength || 0), 8, 16);
    else if (shape === 'box') {
      const h = info.halfExtents || { x: r, y: r, z: r };
      geometry = new THREE.BoxGeometry(2 * h.x, 2 * h.y, 2 * h.z);
    } else if (shape === 'plane') geometry = new THREE.PlaneGeometry(4 * this.size, 4 * this.size).rotateX(-Math.PI / 2);
    else geometry = new THREE.SphereGeometry(r, 32, 16);
    const material = new THREE.MeshStandardMaterial({ color: 0xd0d4dc, roughness: 0.3, metalness: 0.2,
                                                     transparent: shape === 'plane', opacity: shape === 'plane' ? 0.3 : 1 });
    const mesh = new THREE.Mesh(geometry, material);
    mesh.castShadow = shape !== 'plane';
    mesh.name = info.name || '';
    this.root.add(mesh);
    return mesh;
  }

  // Scalars to colours, over the range seen so far (it only widens, so colours do not flicker).
  setScalars(scalars) {
    let lo = this.scalarRange[0];
    let hi = this.scalarRange[1];
    for (let i = 0; i < scalars.length; i++) {
      const v = scalars[i];
      if (v < lo) lo = v;
      if (v > hi) hi = v;
    }
    this.scalarRange[0] = lo;
    this.scalarRange[1] = hi;
    const span = hi - lo || 1;
    for (let i = 0; i < scalars.length; i++) viridis((scalars[i] - lo) / span, this.colors, 3 * i);
    this.colorAttr.needsUpdate = true;
  }

  // The copy drawn last: its positions are the latest drawn [m] (n x 3).
  get geometry() { return this.surfaces[this.front].geometry; }
  get mesh() { return this.surfaces[this.front].mesh; }
  get positions() { return this.surfaces[this.front].positions; }
  // Where the next frame's positions go: the copy not drawn last.
  get nextPositions() { return this.surfaces[1 - this.front].positions; }

  // After nextPositions (and, when `scalarsChanged`, this.scalars) were written: that copy is drawn next.
  updateSurface(scalarsChanged = true) {
    const next = this.surfaces[1 - this.front];
    next.attr.needsUpdate = true;
    if (this.smooth) next.geometry.computeVertexNormals();
    next.mesh.visible = true;
    this.surfaces[this.front].mesh.visible = false;
    this.front = 1 - this.front;
    if (scalarsChanged) this.setScalars(this.scalars);
  }

  // Proxy poses (n x 7: position, orientation w x y z) and forces (n x 3) from a state frame.
  updateProxies(poses, forces) {
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
        // 1 N is drawn as half the body's size.
        const len = 0.5 * this.size * f;
        a.position.copy(m.position);
        a.setDirection(this.tmp.set(fx / f, fy / f, fz / f));
        a.setLength(len, Math.min(0.3 * len, 0.2 * this.size), Math.min(0.15 * len, 0.1 * this.size));
      }
    }
  }

  dispose() {
    this.root.traverse((o) => {
      if (o.geometry) o.geometry.dispose();
      if (o.material) o.material.dispose();
    });
    this.root.removeFromParent();
  }
}
