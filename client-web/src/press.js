// The geometry of a poke with the pointer, apart from the browser so that node's tests can run it.

// The order channels are tried in: one meant for the mouse first, then any other free one.
export function channelOrder(devices) {
  const preferred = devices.filter((d) => /mouse|pointer|browser/i.test(d));
  return [...preferred, ...devices.filter((d) => !preferred.includes(d))];
}

// Where the proxy's centre goes for a pointer ray: the ray meets the plane tangent to the body where it
// was grabbed (so that a drag strokes along the surface), and the centre stands off that point along the
// plane's outward normal so that a sphere of `radius` reaches `depth` below it. False when the ray runs
// along the plane.
export function pressTarget(ray, planePoint, planeNormal, radius, depth, out) {
  const denom = ray.direction.dot(planeNormal);
  if (Math.abs(denom) < 1e-6) return false;
  const s = planePoint.clone().sub(ray.origin).dot(planeNormal) / denom;
  if (s <= 0) return false;
  out.copy(ray.direction).multiplyScalar(s).add(ray.origin).addScaledVector(planeNormal, radius - depth);
  return true;
}
