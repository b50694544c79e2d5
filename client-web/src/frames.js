// The latest two state frames of one scene and the positions between them.
//
// States arrive at up to 30 Hz, unevenly; the display runs at the screen's
// rate. Like the device bridge's one-step delay, the view shows the body one
// frame interval late and interpolates linearly between the two frames that
// bracket the display time, so that motion is smooth rather than stepped.
// Every array is allocated once per scene; push() and sample() allocate
// nothing.

export class FrameBuffer {
  // nValues: floats per frame (3 x surface vertices); nScalars: per-vertex scalars.
  /** @param {number} nValues @param {number} [nScalars] */
  constructor(nValues, nScalars = 0) {
    this.a = new Float32Array(nValues); // older frame
    this.b = new Float32Array(nValues); // newer frame
    this.sa = new Float32Array(nScalars);
    this.sb = new Float32Array(nScalars);
    this.ta = 0; // their simulated times [s]
    this.tb = 0;
    this.count = 0; // frames pushed
    this.arrival = 0; // when the newer arrived, local clock [s]
    this.interval = 1 / 30; // between frames, smoothed [s]
  }

  // Forgets the frames (a replay sought back in time): the next push starts over.
  reset() {
    this.count = 0;
  }

  // Adds a frame (positions, scalars: array-likes of the right lengths; simTime [s]; now: local clock [s]).
  /**
   * @param {ArrayLike<number>} positions @param {ArrayLike<number> | null} scalars
   * @param {number} simTime @param {number} now
   */
  push(positions, scalars, simTime, now) {
    if (positions.length !== this.a.length) {
      throw new RangeError(`frame has ${positions.length} position values, the scene ${this.a.length}`);
    }
    if (this.count > 0 && !(simTime > this.tb)) {
      // A repeated or older state (e.g. after a reset the scene id changes and the buffer is remade):
      // the newest stays.
      return false;
    }
    [this.a, this.b] = [this.b, this.a];
    [this.sa, this.sb] = [this.sb, this.sa];
    this.b.set(positions);
    if (scalars && scalars.length === this.sb.length) this.sb.set(scalars);
    this.ta = this.tb;
    this.tb = simTime;
    if (this.count > 0) {
      const gap = simTime - this.ta;
      this.interval = this.count === 1 ? gap : 0.8 * this.interval + 0.2 * gap;
    } else {
      this.a.set(positions);
      if (scalars && scalars.length === this.sa.length) this.sa.set(scalars);
      this.ta = simTime;
    }
    this.arrival = now;
    this.count += 1;
    return true;
  }

  // The simulated time shown at local time `now`: one interval behind the newest frame, advancing with
  // the clock since it arrived, never past it.
  /** @param {number} now */
  displayTime(now) {
    if (this.count === 0) return 0;
    return Math.min(this.tb, this.tb - this.interval + Math.max(0, now - this.arrival));
  }

  // The weight of the newer frame at local time `now` (0..1): what a shader mixes the two with.
  /** @param {number} now */
  weight(now) {
    const t = this.displayTime(now);
    const span = this.tb - this.ta;
    return span > 0 ? Math.min(1, Math.max(0, (t - this.ta) / span)) : 1;
  }

  // Writes the positions (and scalars) at local time `now` into `out` (and `outScalars`); returns the
  // weight of the newer frame (0..1).
  /** @param {number} now @param {Float32Array | number[]} out @param {Float32Array | number[] | null} [outScalars] */
  sample(now, out, outScalars = null) {
    const w = this.weight(now);
    const a = this.a;
    const b = this.b;
    const v = 1 - w;
    for (let i = 0; i < out.length; i++) out[i] = v * a[i] + w * b[i];
    if (outScalars) {
      const sa = this.sa;
      const sb = this.sb;
      for (let i = 0; i < outScalars.length; i++) outScalars[i] = v * sa[i] + w * sb[i];
    }
    return w;
  }
}
