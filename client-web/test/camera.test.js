// Camera presets and fit-to-body: the body's bounding sphere seen whole and filling the narrower side of the
// view, whatever the window's shape, from each preset's direction.
import assert from 'node:assert/strict';
import test from 'node:test';

import * as THREE from 'three';

import { PRESETS, START, applyFraming, computeBoundingSphere, computeFitDistance } from '../src/camera.js';

test('the bounding sphere holds every point and touches the farthest', () => {
  const points = [0, 0, 0, 2, 0, 0, 0, 1, 0, 1, 1, 3];
  const s = computeBoundingSphere(points);
  let far = 0;
  for (let i = 0; i < points.length; i += 3) {
    far = Math.max(far, Math.hypot(points[i] - s.centre[0], points[i + 1] - s.centre[1], points[i + 2] - s.centre[2]));
  }
  assert.ok(Math.abs(far - s.radius) < 1e-12, `farthest ${far}, radius ${s.radius}`);
  assert.deepEqual(s.centre, [1, 0.5, 1.5]);
  assert.deepEqual(computeBoundingSphere([]), { centre: [0, 0, 0], radius: 0 });
});

test('at the fit distance the sphere subtends the narrower field of view, times the margin', () => {
  for (const aspect of [0.46, 1, 1.78]) {
    const d = computeFitDistance(0.1, 40, aspect, 1);
    const halfY = (40 * Math.PI) / 360;
    const halfX = Math.atan(Math.tan(halfY) * aspect);
    assert.ok(Math.abs(Math.asin(0.1 / d) - Math.min(halfX, halfY)) < 1e-12, `aspect ${aspect}`);
  }
  assert.ok(Math.abs(computeFitDistance(0.1, 40, 1, 1.1) - 1.1 * computeFitDistance(0.1, 40, 1, 1)) < 1e-12);
});

test('each preset looks at the centre along its direction, the whole sphere in view and filling it', () => {
  const sphere = { centre: [0.3, -0.2, 0.1], radius: 0.12 };
  for (const aspect of [390 / 844, 1366 / 768]) {
    /** @type {[string, number[]][]} */
    const views = [...Object.entries(PRESETS), ['start', START]];
    for (const [name, dir] of views) {
      const camera = new THREE.PerspectiveCamera(40, aspect, 0.01, 100);
      const controls = {
        target: new THREE.Vector3(),
        update() {
          camera.lookAt(this.target);
        },
      };
      applyFraming(camera, /** @type {any} */ (controls), sphere, dir);
      camera.updateMatrixWorld();
      const c = new THREE.Vector3(...sphere.centre);
      const at = c.clone().project(camera);
      assert.ok(Math.hypot(at.x, at.y) < 1e-9, `${name}: the centre is drawn at ${at.x}, ${at.y}`);
      // The eye is along the preset's direction.
      const eye = camera.position.clone().sub(c).normalize();
      const want = new THREE.Vector3(...dir).normalize();
      assert.ok(eye.dot(want) > 1 - 1e-9, `${name}: seen from ${eye.toArray()}`);
      // Points of the sphere all fall in the view; the outermost near its narrower edge.
      let most = 0;
      for (let i = 0; i < 2000; i++) {
        const u = 1 - (2 * (i + 0.5)) / 2000; // (a Fibonacci sphere: even over the surface)
        const phi = i * 2.399963;
        const p = new THREE.Vector3(Math.sqrt(1 - u * u) * Math.cos(phi), u, Math.sqrt(1 - u * u) * Math.sin(phi))
          .multiplyScalar(sphere.radius)
          .add(c)
          .project(camera);
        assert.ok(
          Math.abs(p.x) <= 1 && Math.abs(p.y) <= 1,
          `${name}, aspect ${aspect.toFixed(2)}: a point at ${p.x}, ${p.y}`,
        );
        most = Math.max(most, aspect < 1 ? Math.abs(p.x) : Math.abs(p.y));
      }
      assert.ok(
        most > 0.85,
        `${name}, aspect ${aspect.toFixed(2)}: the sphere reaches ${most} of the narrower half-view`,
      );
    }
  }
});
