// A proxy's shape (SceneDescription.proxies[k]) as a three.js geometry, and its size.
import * as THREE from 'three';

/** @import { ProxyInfoT } from '@tactile/proto' */

export const SHAPES = ['sphere', 'capsule', 'box', 'plane'];

// The shape's name ('sphere' for one this page does not know).
/** @param {ProxyInfoT} info */
export const shapeName = (info) => SHAPES[info.shape] ?? 'sphere';

// How large the proxy is [m]: its radius (sphere), out to a cap's end (capsule), its largest half extent (box).
/** @param {ProxyInfoT} info */
export function computeProxySize(info) {
  const r = info.radius || 0.005;
  const shape = shapeName(info);
  if (shape === 'capsule') return r + (info.halfLength || 0);
  if (shape === 'box') {
    const h = info.halfExtents;
    return h ? Math.max(h.x, h.y, h.z) : r;
  }
  return r;
}

// Its geometry in its own frame; a plane is drawn as a square of 4 x `bodySize` [m]. `detail` 1 for the
// proxy itself, less for an outline (fewer segments).
/** @param {ProxyInfoT} info @param {number} bodySize @param {number} [detail] */
export function makeProxyGeometry(info, bodySize, detail = 1) {
  const shape = shapeName(info);
  const r = info.radius || 0.005;
  if (shape === 'capsule') {
    return new THREE.CapsuleGeometry(
      r,
      2 * (info.halfLength || 0),
      Math.max(2, Math.round(8 * detail)),
      Math.max(6, Math.round(16 * detail)),
    );
  }
  if (shape === 'box') {
    const h = info.halfExtents || { x: r, y: r, z: r };
    return new THREE.BoxGeometry(2 * h.x, 2 * h.y, 2 * h.z);
  }
  if (shape === 'plane') return new THREE.PlaneGeometry(4 * bodySize, 4 * bodySize).rotateX(-Math.PI / 2);
  return new THREE.SphereGeometry(r, Math.max(8, Math.round(32 * detail)), Math.max(6, Math.round(16 * detail)));
}
