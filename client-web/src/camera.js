// Camera presets and fit-to-body: where the camera stands to frame the body's bounding sphere from a given
// direction, whatever the window's shape.
/** @import { PerspectiveCamera } from 'three' */
/** @import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js' */

// Directions from the body's centre to the camera (y up; unnormalized). 'top' leans a hair toward +z so
// that the look-at frame is defined (x to the right, -z up on screen).
export const PRESETS = {
  front: [0, 0, 1],
  top: [0, 1, 1e-3],
  side: [1, 0, 0],
  iso: [1, 1, 1],
};
// The first view of a scene: from the front, above and to the right.
export const START = [1.6, 1.4, 2.6];

/** @typedef {{ centre: number[], radius: number }} Sphere */

// A sphere around `positions` (x, y, z a point, n x 3) [m]: centred on their bounding box, out to the
// farthest point (as three.js's BufferGeometry.computeBoundingSphere). A point's sphere has radius 0.
/** @param {ArrayLike<number>} positions @returns {Sphere} */
export function computeBoundingSphere(positions) {
  const lo = [Infinity, Infinity, Infinity];
  const hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i + 2 < positions.length; i += 3) {
    for (let c = 0; c < 3; c++) {
      const v = positions[i + c];
      if (v < lo[c]) lo[c] = v;
      if (v > hi[c]) hi[c] = v;
    }
  }
  if (!(lo[0] <= hi[0])) return { centre: [0, 0, 0], radius: 0 };
  const centre = [0, 1, 2].map((c) => (lo[c] + hi[c]) / 2);
  let r2 = 0;
  for (let i = 0; i + 2 < positions.length; i += 3) {
    const dx = positions[i] - centre[0];
    const dy = positions[i + 1] - centre[1];
    const dz = positions[i + 2] - centre[2];
    r2 = Math.max(r2, dx * dx + dy * dy + dz * dz);
  }
  return { centre, radius: Math.sqrt(r2) };
}

// How far from a sphere of `radius` a perspective camera stands to see all of it: the sphere touches the
// narrower of the two fields of view (vertical `fovYDeg`, horizontal from `aspect` = width / height), times
// `margin`.
/** @param {number} radius @param {number} fovYDeg @param {number} aspect @param {number} [margin] */
export function computeFitDistance(radius, fovYDeg, aspect, margin = 1.05) {
  const halfY = (fovYDeg * Math.PI) / 360;
  const halfX = Math.atan(Math.tan(halfY) * aspect);
  return (margin * radius) / Math.sin(Math.min(halfY, halfX));
}

// Places `camera` to look at `sphere`'s centre from `direction` at the fitting distance, and the orbit
// controls' target on that centre (near and far planes follow the sphere).
/**
 * @param {PerspectiveCamera} camera @param {OrbitControls} controls @param {Sphere} sphere
 * @param {ArrayLike<number>} direction
 */
export function applyFraming(camera, controls, sphere, direction) {
  const r = sphere.radius || 0.05;
  const d = computeFitDistance(r, camera.fov, camera.aspect);
  const len = Math.hypot(direction[0], direction[1], direction[2]) || 1;
  const [cx, cy, cz] = sphere.centre;
  controls.target.set(cx, cy, cz);
  camera.position.set(cx + (d * direction[0]) / len, cy + (d * direction[1]) / len, cz + (d * direction[2]) / len);
  camera.near = r / 100;
  camera.far = d + r * 100;
  camera.updateProjectionMatrix();
  controls.update();
}

// The direction the camera now looks at its target from (camera - target), for a fit that keeps it.
/** @param {PerspectiveCamera} camera @param {OrbitControls} controls */
export function viewDirection(camera, controls) {
  const p = camera.position;
  const t = controls.target;
  return [p.x - t.x, p.y - t.y, p.z - t.z];
}
