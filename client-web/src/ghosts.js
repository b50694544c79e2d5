// The device's own pose beside its proxy (StateFrame.device_poses, protocol 1.8). A coupled proxy is pulled
// toward its device through a spring-damper and stopped by the body, so the hand can be well inside the body
// while its proxy rests on the surface. Where they differ by more than a small distance, an outline of the
// proxy's shape is drawn at the device's pose with a line to the proxy; nothing otherwise, and nothing from
// a server before 1.8 (no device poses). Both are drawn through the body (no depth test): a device pushed
// into it is where it matters most.
import * as THREE from 'three';

import { computeProxySize, makeProxyGeometry } from './shapes.js';
/** @import { ProxyInfoT, SceneDescriptionT } from '@tactile/proto' */

export const GHOST_COLOUR = 0x8fd3ff;

// The proxy each device channel drives (SceneDescription.proxies[j].device names its channel): its index,
// or -1 for a channel with none (n_devices).
/** @param {string[]} devices @param {ProxyInfoT[]} proxies */
export function channelProxies(devices, proxies) {
  return Int32Array.from(devices, (d) => proxies.findIndex((p) => p.device === d));
}

// How far the device may be from its proxy before it is drawn [m]: a tenth of the proxy's size, and no
// less than half a millimetre (a coupling's lag at rest, which would make the outline flicker).
/** @param {ProxyInfoT} info */
export const ghostGap = (info) => Math.max(0.1 * computeProxySize(info), 5e-4);

export class DeviceGhosts {
  /** @param {THREE.Object3D} root @param {SceneDescriptionT} description @param {number} bodySize [m] */
  constructor(root, description, bodySize) {
    const proxies = description.proxies || [];
    this.proxyOf = channelProxies(description.devices || [], proxies);
    this.gaps = Float32Array.from(this.proxyOf, (j) => (j >= 0 ? ghostGap(proxies[j]) : Infinity));
    this.shown = 0; // how many are drawn (tests read it)
    this.outlines = Array.from(this.proxyOf, (j, k) => {
      if (j < 0) return null;
      const material = new THREE.MeshBasicMaterial({
        color: GHOST_COLOUR,
        wireframe: true,
        transparent: true,
        opacity: 0.8,
        depthTest: false,
        depthWrite: false,
      });
      const outline = new THREE.Mesh(makeProxyGeometry(proxies[j], bodySize, 0.4), material);
      outline.name = `device ${description.devices[k]}`;
      outline.visible = false;
      outline.renderOrder = 2; // over the body, which is drawn first
      root.add(outline);
      return outline;
    });
    this.lines = Array.from(this.proxyOf, (j) => {
      if (j < 0) return null;
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6), 3));
      const line = new THREE.Line(
        geometry,
        new THREE.LineBasicMaterial({
          color: GHOST_COLOUR,
          transparent: true,
          opacity: 0.9,
          depthTest: false,
          depthWrite: false,
        }),
      );
      line.frustumCulled = false; // its ends move; it is short and drawn rarely
      line.renderOrder = 2;
      line.visible = false;
      root.add(line);
      return line;
    });
  }

  // From a state frame: each device's pose and the proxies' (n x 7: position [m], orientation w x y z).
  /** @param {Float32Array} devicePoses @param {Float32Array} proxyPoses */
  update(devicePoses, proxyPoses) {
    this.shown = 0;
    for (let k = 0; k < this.proxyOf.length; k++) {
      const outline = this.outlines[k];
      const line = this.lines[k];
      if (!outline || !line) continue;
      const j = this.proxyOf[k];
      const d = 7 * k;
      const p = 7 * j;
      const present = d + 6 < devicePoses.length && p + 6 < proxyPoses.length;
      const gap = present
        ? Math.hypot(
            devicePoses[d] - proxyPoses[p],
            devicePoses[d + 1] - proxyPoses[p + 1],
            devicePoses[d + 2] - proxyPoses[p + 2],
          )
        : 0;
      const show = gap > this.gaps[k];
      outline.visible = show;
      line.visible = show;
      if (!show) continue;
      this.shown += 1;
      outline.position.set(devicePoses[d], devicePoses[d + 1], devicePoses[d + 2]);
      outline.quaternion.set(devicePoses[d + 4], devicePoses[d + 5], devicePoses[d + 6], devicePoses[d + 3]);
      const ends = /** @type {THREE.BufferAttribute} */ (line.geometry.getAttribute('position'));
      ends.array.set(devicePoses.subarray(d, d + 3), 0);
      ends.array.set(proxyPoses.subarray(p, p + 3), 3);
      ends.needsUpdate = true;
    }
  }
}
