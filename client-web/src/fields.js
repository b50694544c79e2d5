// What the body is coloured by: its displacement, which the page has from the frames (|x - X| per vertex,
// nothing asked of the server), or a per-vertex field the server computes only while a viewer asks for it
// (protocol 1.8: Hello.fields, then ViewFields on each change). The description lists those it can send.
/** @import { SceneDescriptionT, StateFrameView } from '@tactile/proto' */

export const DISPLACEMENT = 'displacement';
// Which body each point is on (a scene of several bodies): the body's place in the scene's list, drawn in
// the legend's colours at evenly spaced stops, the first body at the map's start and the last at its end.
export const BODY = 'body';

/** @typedef {{ name: string, unit: string, description: string }} FieldChoiceInfo */

export class FieldChoice {
  // `wanted`: the field to start with (the page's ?field=); displacement when the scene has no such field.
  /** @param {string} [wanted] */
  constructor(wanted = DISPLACEMENT) {
    this.wanted = wanted;
    this.name = DISPLACEMENT;
    /** @type {FieldChoiceInfo[]} */
    this.available = [{ name: DISPLACEMENT, unit: 'm', description: 'how far each point moved from rest' }];
    /** @type {string[]} */
    this.bodyNames = [];
    /** @type {Float32Array | null} */
    this.bodyOf = null; // per frame vertex: its body's place in the scene's list (several bodies)
  }

  // A new scene: what it offers; the wanted field (the menu's last choice, or ?field=) when the scene has
  // it, else the current one if it has that, else displacement.
  /** @param {SceneDescriptionT} d */
  setDescription(d) {
    this.available = [this.available[0]];
    const bodies = d.bodies || [];
    /** @type {string[]} */
    this.bodyNames = bodies.map((b, k) => /** @type {string | null} */ (b.name) || `body ${k + 1}`);
    /** @type {Float32Array | null} */
    this.bodyOf = null;
    if (bodies.length > 1) {
      this.bodyOf = new Float32Array(Math.max(...bodies.map((b) => b.vertexEnd)));
      bodies.forEach((b, k) => this.bodyOf?.fill(k, b.vertexBegin, b.vertexEnd));
      this.available.push({
        name: BODY,
        unit: '',
        description: `which body each point is on: ${this.bodyNames.join(', ')}, in the legend's colours from its start`,
      });
    }
    for (const f of d.fields || []) {
      const name = /** @type {string | null} */ (f.name) || '';
      if (name)
        this.available.push({
          name,
          unit: /** @type {string} */ (f.unit) || '',
          description: /** @type {string} */ (f.description) || '',
        });
    }
    const has = (/** @type {string} */ n) => this.available.some((f) => f.name === n);
    if (has(this.wanted)) this.name = this.wanted;
    else if (!has(this.name)) this.name = DISPLACEMENT;
  }

  // The field names to ask the server for (none for displacement).
  asked() {
    return this.name === DISPLACEMENT || this.name === BODY ? [] : [this.name];
  }

  // Whether the colours span from zero (a magnitude, or the bodies' places) rather than the range seen.
  fromZero() {
    return this.name === DISPLACEMENT || this.name === BODY;
  }

  // What the legend's ends say: the first and the last body's names for the bodies, else null (the range).
  ends() {
    const n = this.bodyNames ? this.bodyNames.length : 0;
    return this.name === BODY && n > 1 ? [this.bodyNames[0], this.bodyNames[n - 1]] : null;
  }

  info() {
    return /** @type {FieldChoiceInfo} */ (this.available.find((f) => f.name === this.name));
  }

  // The chosen field's value at each frame vertex, into `out` (n); false when the frame does not carry it
  // yet (the server answers a change with its next frame).
  /** @param {StateFrameView} frame @param {Float32Array} rest @param {Float32Array} out */
  values(frame, rest, out) {
    if (this.name === DISPLACEMENT) {
      const p = frame.positions;
      for (let i = 0, j = 0; i < out.length; i++, j += 3) {
        out[i] = Math.hypot(p[j] - rest[j], p[j + 1] - rest[j + 1], p[j + 2] - rest[j + 2]);
      }
      return true;
    }
    if (this.name === BODY) {
      if (!this.bodyOf || this.bodyOf.length !== out.length) return false;
      out.set(this.bodyOf);
      return true;
    }
    const v = frame.fields.get(this.name);
    if (!v || v.length !== out.length) return false;
    out.set(v);
    return true;
  }
}
