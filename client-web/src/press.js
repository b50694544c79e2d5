// The geometry of a poke with the pointer, apart from the browser so that node's tests can run it.
/** @import { Ray, Vector3 } from 'three' */

// The channels the page may drive, in the order it tries them: the one `wanted` names (?device=...), or
// else those meant for the page (mouse, pointer, finger, touch, browser). A channel meant for an arm is
// left to its bridge: the page taking it first would shut the arm out (one device drives a channel).
/** @param {string[]} devices @param {string} [wanted] */
export function channelOrder(devices, wanted = '') {
  if (wanted) return devices.includes(wanted) ? [wanted] : [];
  return devices.filter((d) => /mouse|pointer|finger|touch|browser/i.test(d));
}

// Where the proxy's centre goes for a pointer ray: the ray meets the plane tangent to the body where it
// was grabbed (so that a drag strokes along the surface), and the centre stands off that point along the
// plane's outward normal so that a sphere of `radius` reaches `depth` below it. False when the ray runs
// along the plane.
/**
 * @param {Ray} ray @param {Vector3} planePoint @param {Vector3} planeNormal @param {number} radius
 * @param {number} depth @param {Vector3} out
 */
export function pressTarget(ray, planePoint, planeNormal, radius, depth, out) {
  const denom = ray.direction.dot(planeNormal);
  if (Math.abs(denom) < 1e-6) return false;
  const s = planePoint.clone().sub(ray.origin).dot(planeNormal) / denom;
  if (s <= 0) return false;
  out
    .copy(ray.direction)
    .multiplyScalar(s)
    .add(ray.origin)
    .addScaledVector(planeNormal, radius - depth);
  return true;
}
