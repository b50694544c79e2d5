// The three.js scene of one SceneDescription: the body's surface (positions and colours updated in
// place each frame), the proxies drawn as their shapes, and an arrow per proxy for its contact force.
import * as THREE from 'three';

import { viridis } from './colormap.js';

const SHAPES = ['sphere', 'capsule', 'box', 'plane'];

export class SceneView {
  constructor(scene, description) {
    this.root = new THREE.Group();
    scene.add(this.root);
    const rest = description.restPositions;
    const n = rest.length / 3;
    this.positions = new Float32Array(rest);
    this.scalars = new Float32Array(n);
    this.colors = new Float32Array(3 * n);
    this.scalarRange = [0, 1e-9];
    const geometry = new THREE.BufferGeometry();
    this.positionAttr = new THREE.BufferAttribute(this.positions, 3);
    this.positionAttr.setUsage(THREE.DynamicDrawUsage);
    this.colorAttr = new THREE.BufferAttribute(this.colors, 3);
    this.colorAttr.setUsage(THREE.DynamicDrawUsage);
    geometry.setAttribute('position', this.positionAttr);
    geometry.setAttribute('color', this.colorAttr);
    geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(description.triangles), 1));
    geometry.computeVertexNormals();
    geometry.computeBoundingSphere();
    this.geometry = geometry;
    const material = new THREE.MeshStandardMaterial({ vertexColors: true, roughness: 0.55, metalness: 0.0,
                                                     side: THREE.DoubleSide });
    this.mesh = new THREE.Mesh(geometry, material);
    this.mesh.castShadow = true;
    this.mesh.receiveShadow = true;
    this.root.add(this.mesh);
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

  // After this.positions and this.scalars were written.
  updateSurface() {
    this.positionAttr.needsUpdate = true;
    this.geometry.computeVertexNormals();
    this.setScalars(this.scalars);
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
