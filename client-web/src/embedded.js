// The fine surface a scene's body carries (SceneDescription.embedded, protocol 1.7), placed on the GPU.
//
// A state frame carries the frame's vertices only (the coarse boundary and the interior nodes the fine
// surface follows). Each is written once, when it arrives, into a float texture of one of SceneView's three
// slots, with its colour in a byte texture beside it. The vertex shader places every fine vertex from the four
// frame vertices it follows, x = sum_k w_k x_k (the server's barycentric binding), in the two states mixed on
// screen, and turns its rest normal by the deformation of the tet it lies in: n ~ F^-T N, with F = Ds Dm^-1,
// is cof(Ds) (Dm^T N), three cross products of the tet's edges now against a vector fixed at rest. So the
// surface is smooth-shaded with current normals, and a screen frame sends nothing per vertex.
import * as THREE from 'three';

/** @import { EmbeddedSurfaceT } from '@tactile/proto' */

// Texture rows: frame vertex i is texel (i % WIDTH, i / WIDTH).
const WIDTH = 1024;

// The shader code both materials share: the placed position, colour and normal of a fine vertex.
const PLACE = `
  attribute vec4 carriers;
  attribute vec4 weights;
  attribute vec3 restNormalM;
  uniform sampler2D embPosA;
  uniform sampler2D embPosB;
  uniform sampler2D embColA;
  uniform sampler2D embColB;
  uniform float surfaceMix;
  vec3 embFetch(float i) {
    ivec2 t = ivec2(int(mod(i, ${WIDTH}.0)), int(i / ${WIDTH}.0));
    return mix(texelFetch(embPosA, t, 0).xyz, texelFetch(embPosB, t, 0).xyz, surfaceMix);
  }
  vec3 embColour(float i) {
    ivec2 t = ivec2(int(mod(i, ${WIDTH}.0)), int(i / ${WIDTH}.0));
    return mix(texelFetch(embColA, t, 0).rgb, texelFetch(embColB, t, 0).rgb, surfaceMix);
  }
  vec3 embPosition;
  vec3 embNormal;
  vec3 embRgb;
  void embPlace() {
    vec3 x0 = embFetch(carriers.x);
    vec3 x1 = embFetch(carriers.y);
    vec3 x2 = embFetch(carriers.z);
    vec3 x3 = embFetch(carriers.w);
    embPosition = weights.x * x0 + weights.y * x1 + weights.z * x2 + weights.w * x3;
    vec3 d1 = x1 - x0;
    vec3 d2 = x2 - x0;
    vec3 d3 = x3 - x0;
    embNormal = normalize(restNormalM.x * cross(d2, d3) + restNormalM.y * cross(d3, d1) + restNormalM.z * cross(d1, d2));
    embRgb = weights.x * embColour(carriers.x) + weights.y * embColour(carriers.y) +
             weights.z * embColour(carriers.z) + weights.w * embColour(carriers.w);
  }
`;

// Where the CPU draws (software renderers): a light at the camera and an ambient floor on the placed normal.
/** @param {{ [name: string]: THREE.IUniform }} uniforms */
function lowQualityMaterial(uniforms) {
  return new THREE.ShaderMaterial({
    uniforms,
    side: THREE.FrontSide,
    vertexShader:
      PLACE +
      `
      varying vec3 vNormal;
      varying vec3 vColour;
      void main() {
        embPlace();
        vNormal = normalize(normalMatrix * embNormal);
        vColour = embRgb;
        gl_Position = projectionMatrix * modelViewMatrix * vec4(embPosition, 1.0);
      }`,
    fragmentShader: `
      varying vec3 vNormal;
      varying vec3 vColour;
      void main() {
        float light = max(dot(normalize(vNormal), normalize(vec3(0.3, 0.6, 0.75))), 0.0);
        gl_FragColor = vec4(vColour * (0.35 + 0.65 * light), 1.0);
      }`,
  });
}

export class EmbeddedSurfaceView {
  /**
   * @param {EmbeddedSurfaceT} e the binding
   * @param {Float32Array} frameRest the frame vertices at rest (SceneDescription.restPositions)
   * @param {{ value: number }} mix the shared uniform: the newer state's weight on screen
   * @param {string} quality 'high' or 'low', as SceneView's
   */
  constructor(e, frameRest, mix, quality) {
    const rest = new Float32Array(e.restPositions);
    const n = rest.length / 3;
    const carriers = new Float32Array(e.carriers); // (indices below 2^24: exact as floats)
    const weights = new Float32Array(e.weights);
    this.frameVertices = frameRest.length / 3;
    this.triangles = e.triangles.length / 3;
    const geometry = new THREE.BufferGeometry();
    geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(e.triangles), 1));
    geometry.setAttribute('position', new THREE.BufferAttribute(rest, 3)); // bounds and rest normals only
    geometry.computeVertexNormals();
    const normals = /** @type {THREE.BufferAttribute} */ (geometry.getAttribute('normal')).array;
    // Dm^T N per vertex, Dm = [X1 - X0, X2 - X0, X3 - X0] of its tet at rest.
    const m = new Float32Array(3 * n);
    const X = (/** @type {number} */ i, /** @type {number} */ c) => frameRest[3 * i + c];
    for (let v = 0; v < n; v++) {
      const c0 = carriers[4 * v];
      for (let k = 1; k <= 3; k++) {
        const ck = carriers[4 * v + k];
        let dot = 0;
        for (let c = 0; c < 3; c++) dot += (X(ck, c) - X(c0, c)) * normals[3 * v + c];
        m[3 * v + k - 1] = dot;
      }
    }
    this.carriers = carriers;
    this.weights = weights;
    geometry.setAttribute('carriers', new THREE.BufferAttribute(carriers, 4));
    geometry.setAttribute('weights', new THREE.BufferAttribute(weights, 4));
    geometry.setAttribute('restNormalM', new THREE.BufferAttribute(m, 3));
    geometry.deleteAttribute('normal');
    geometry.computeBoundingSphere();
    this.geometry = geometry;
    // Per slot: positions (RGBA float) and colours (RGBA bytes) of the frame vertices.
    const rows = Math.max(1, Math.ceil(this.frameVertices / WIDTH));
    this.slots = [0, 1, 2].map(() => {
      const positions = new Float32Array(4 * WIDTH * rows);
      const colours = new Uint8Array(4 * WIDTH * rows);
      const p = new THREE.DataTexture(positions, WIDTH, rows, THREE.RGBAFormat, THREE.FloatType);
      const c = new THREE.DataTexture(colours, WIDTH, rows, THREE.RGBAFormat, THREE.UnsignedByteType);
      for (const t of [p, c]) {
        t.magFilter = t.minFilter = THREE.NearestFilter;
        t.generateMipmaps = false;
      }
      return { p, c, positions, colours };
    });
    this.uniforms = {
      surfaceMix: mix,
      embPosA: { value: this.slots[0].p },
      embPosB: { value: this.slots[1].p },
      embColA: { value: this.slots[0].c },
      embColB: { value: this.slots[1].c },
    };
    /** @param {THREE.WebGLProgramParametersWithUniforms} shader @param {boolean} shade */
    const inject = (shader, shade) => {
      Object.assign(shader.uniforms, this.uniforms);
      shader.vertexShader = PLACE + shader.vertexShader;
      if (shade) {
        // (three's standard vertex shader sets the colour first, then the normal, then the position.)
        shader.vertexShader = shader.vertexShader
          .replace('#include <color_vertex>', 'embPlace();\nvColor = embRgb;')
          .replace('#include <beginnormal_vertex>', 'vec3 objectNormal = embNormal;');
      } else {
        shader.vertexShader = shader.vertexShader.replace(
          '#include <begin_vertex>',
          'embPlace();\n#include <begin_vertex>',
        );
      }
      shader.vertexShader = shader.vertexShader.replace('#include <begin_vertex>', 'vec3 transformed = embPosition;');
    };
    let material;
    if (quality === 'high') {
      material = new THREE.MeshStandardMaterial({
        vertexColors: true,
        roughness: 0.5,
        metalness: 0.0,
        side: THREE.FrontSide,
      });
      material.onBeforeCompile = (shader) => inject(shader, true);
    } else {
      material = lowQualityMaterial(this.uniforms);
    }
    this.mesh = new THREE.Mesh(geometry, material);
    this.mesh.name = 'embedded surface';
    this.mesh.frustumCulled = false; // the shader moves it past its rest bounds
    this.mesh.castShadow = true;
    this.mesh.receiveShadow = true;
    const depth = new THREE.MeshDepthMaterial({ depthPacking: THREE.RGBADepthPacking });
    depth.onBeforeCompile = (shader) => inject(shader, false);
    this.mesh.customDepthMaterial = depth;
  }

  // A state into slot k: the frame vertices' positions [m] (n x 3) and their colours (n x 4 bytes).
  /** @param {number} k @param {ArrayLike<number>} positions @param {Uint8Array} colours */
  write(k, positions, colours) {
    const slot = this.slots[k];
    const data = slot.positions;
    for (let i = 0, j = 0; i < positions.length; i += 3, j += 4) {
      data[j] = positions[i];
      data[j + 1] = positions[i + 1];
      data[j + 2] = positions[i + 2];
    }
    slot.p.needsUpdate = true;
    slot.colours.set(colours.subarray(0, 4 * this.frameVertices));
    slot.c.needsUpdate = true;
  }

  // The fine vertices placed on the CPU from the frame vertices' positions [m] (n x 3), as the shader places
  // them: what the camera frames (the frame vertices reach past the fine surface where the coarse mesh
  // encloses it, as a coarse TetGen mesh scaled to the fine surface's volume does).
  /** @param {ArrayLike<number>} positions @returns {Float32Array} */
  place(positions) {
    const { carriers, weights } = this;
    const out = new Float32Array((carriers.length / 4) * 3);
    for (let v = 0; v < carriers.length / 4; v++) {
      for (let k = 0; k < 4; k++) {
        const i = 3 * carriers[4 * v + k];
        const w = weights[4 * v + k];
        out[3 * v] += w * positions[i];
        out[3 * v + 1] += w * positions[i + 1];
        out[3 * v + 2] += w * positions[i + 2];
      }
    }
    return out;
  }

  // Which slots the screen mixes: the older and the newer state.
  /** @param {number} older @param {number} newer */
  bind(older, newer) {
    this.uniforms.embPosA.value = this.slots[older].p;
    this.uniforms.embPosB.value = this.slots[newer].p;
    this.uniforms.embColA.value = this.slots[older].c;
    this.uniforms.embColB.value = this.slots[newer].c;
  }

  dispose() {
    for (const { p, c } of this.slots) {
      p.dispose();
      c.dispose();
    }
  }
}
