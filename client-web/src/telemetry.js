// The telemetry panel: the server's figures as text, and the step time and real-time factor over the
// last minute as a plot (a 2D canvas, redrawn when a Telemetry arrives, about once a second). Safety
// events relayed from device bridges are listed with their time and cause.

import { SafetyKind } from '../../proto/js/src/index.ts';

const SPAN = 60; // samples kept (about a minute)
// 'ContinuousLimit' -> 'continuous limit'
const kindName = (k) => (SafetyKind[k] ?? `kind ${k}`).replace(/([a-z])([A-Z])/g, '$1 $2').toLowerCase();

export class TelemetryPanel {
  constructor(element) {
    this.text = element.querySelector('.figures');
    this.canvas = element.querySelector('canvas');
    this.events = element.querySelector('.events');
    this.stepUs = new Float64Array(SPAN);
    this.rtf = new Float64Array(SPAN);
    this.count = 0;
    this.latest = null;
  }

  // A TelemetryT (object API).
  update(t) {
    this.latest = t;
    const k = this.count % SPAN;
    this.stepUs[k] = t.stepTimeMeanUs;
    this.rtf[k] = t.realTimeFactor;
    this.count += 1;
    const costs = (t.effectCosts || []).filter((c) => c.nsPerStep > 0)
      .map((c) => `${c.name} ${(c.nsPerStep / 1000).toFixed(1)}`).join(', ');
    this.text.textContent =
      `step ${t.stepTimeMeanUs.toFixed(1)} us (max ${t.stepTimeMaxUs.toFixed(0)}), real-time factor ` +
      `${t.realTimeFactor.toFixed(3)}, missed ${t.missedDeadlines}${t.paused ? ', paused' : ''}\n` +
      `clients: ${t.viewers} viewers, ${t.devices} devices, ${t.controllers} controllers\n` +
      (costs ? `cost per step (us): ${costs}\n` : '') +
      ((t.faults || []).length ? `faults: ${t.faults.join('; ')}` : '');
    this.draw();
  }

  // A SafetyEventT (object API), newest on top, the latest 8 kept.
  safety(e) {
    const li = document.createElement('li');
    const kind = kindName(e.kind);
    li.textContent = `${new Date().toLocaleTimeString()} ${e.device}: ${kind}: ${e.message} (${e.forceN.toFixed(2)} N)`;
    this.events.prepend(li);
    while (this.events.children.length > 8) this.events.lastChild.remove();
  }

  draw() {
    const c = this.canvas;
    const g = c.getContext('2d');
    const w = c.width;
    const h = c.height;
    g.clearRect(0, 0, w, h);
    const n = Math.min(this.count, SPAN);
    if (n < 2) return;
    let top = 0;
    for (let i = 0; i < n; i++) top = Math.max(top, this.stepUs[i]);
    top = top * 1.2 || 1;
    const series = (values, scale, colour) => {
      g.strokeStyle = colour;
      g.beginPath();
      for (let i = 0; i < n; i++) {
        const v = values[(this.count - n + i) % SPAN];
        const x = (i / (SPAN - 1)) * w;
        const y = h - Math.min(1, v / scale) * (h - 2) - 1;
        if (i === 0) g.moveTo(x, y);
        else g.lineTo(x, y);
      }
      g.stroke();
    };
    series(this.stepUs, top, '#7fc8ff');
    series(this.rtf, 1.25, '#ffd166');
    g.fillStyle = '#aab';
    g.fillText(`step time (0-${top.toFixed(0)} us)`, 4, 10);
    g.fillStyle = '#ffd166';
    g.fillText('real-time factor (0-1.25)', 4, 22);
  }
}
