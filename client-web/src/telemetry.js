// The telemetry panel: the server's figures as text, and the step time, the real-time factor, (while
// this page drives a device) the input-to-force latency, and (while a device bridge reports, protocol 1.3)
// the bridge's tick lateness and display delay over the last minute as a plot (a 2D canvas, redrawn when a
// Telemetry arrives, about once a second). Safety events relayed from device bridges are listed with their
// time and cause.

import { SafetyKind } from '@tactile/proto';
/** @import { DeviceStatusT, SafetyEventT, TelemetryT } from '@tactile/proto' */

const SPAN = 60; // samples kept (about a minute)
// 'ContinuousLimit' -> 'continuous limit'
/** @param {SafetyKind} k */
const kindName = (k) => (SafetyKind[k] ?? `kind ${k}`).replace(/([a-z])([A-Z])/g, '$1 $2').toLowerCase();

export class TelemetryPanel {
  /** @param {HTMLElement} element */
  constructor(element) {
    // (index.html has each of them.)
    this.text = /** @type {HTMLElement} */ (element.querySelector('.figures'));
    this.canvas = /** @type {HTMLCanvasElement} */ (element.querySelector('canvas'));
    this.events = /** @type {HTMLElement} */ (element.querySelector('.events'));
    this.stepUs = new Float64Array(SPAN);
    this.rtf = new Float64Array(SPAN);
    this.latency = new Float64Array(SPAN).fill(NaN);
    this.bridgeLate = new Float64Array(SPAN).fill(NaN);   // tick lateness p99 [ms], the first bridge's
    this.bridgeDelay = new Float64Array(SPAN).fill(NaN);  // its display delay [ms]
    /** @type {Map<DeviceStatusT['device'], DeviceStatusT>} */
    this.devices = new Map();  // channel -> its latest DeviceStatusT
    this.count = 0;
    /** @type {TelemetryT | null} */
    this.latest = null;
  }

  // A TelemetryT (object API); `latencies`: this page's latest input-to-force round trips [ms] (the
  // ones since the previous call are summarised: median and 95th percentile).
  /** @param {TelemetryT} t @param {number[]} [latencies] */
  update(t, latencies = []) {
    this.latest = t;
    const k = this.count % SPAN;
    this.stepUs[k] = t.stepTimeMeanUs;
    this.rtf[k] = t.realTimeFactor;
    const fresh = latencies.splice(0).sort((a, b) => a - b);
    const pick = (/** @type {number} */ q) => fresh[Math.min(fresh.length - 1, Math.floor(q * fresh.length))];
    this.latency[k] = fresh.length ? pick(0.5) : NaN;
    const bridge = this.devices.values().next().value;
    const current = bridge && Number(t.serverTimeNs - bridge.serverTimeNs) < 3e9;  // reported in the last 3 s
    this.bridgeLate[k] = current ? bridge.latenessP99Us / 1000 : NaN;
    this.bridgeDelay[k] = current ? bridge.displayDelayMs : NaN;
    this.count += 1;
    const bridges = [...this.devices.values()]
      .filter((d) => Number(t.serverTimeNs - d.serverTimeNs) < 3e9)
      .map((d) => `bridge ${d.device}: tick ${d.tickRateHz.toFixed(0)} Hz, late p99 ${d.latenessP99Us.toFixed(0)} us ` +
                  `(max ${d.latenessMaxUs.toFixed(0)}), missed ${d.missedTicks}, delay ${d.displayDelayMs.toFixed(2)} ms ` +
                  `(${d.stateIntervalMs.toFixed(2)} + ${d.jitterAllowanceMs.toFixed(2)}), ${d.mode}, ${d.forceN.toFixed(2)} N\n`)
      .join('');
    const costs = (t.effectCosts || []).filter((c) => c.nsPerStep > 0)
      .map((c) => `${c.name} ${(c.nsPerStep / 1000).toFixed(1)}`).join(', ');
    this.text.textContent =
      `step ${t.stepTimeMeanUs.toFixed(1)} us (max ${t.stepTimeMaxUs.toFixed(0)}), real-time factor ` +
      `${t.realTimeFactor.toFixed(3)}, missed ${t.missedDeadlines}${t.paused ? ', paused' : ''}\n` +
      `clients: ${t.viewers} viewers, ${t.devices} devices, ${t.controllers} controllers\n` +
      (t.faultResets ? `reset after a fault: ${t.faultResets} time${t.faultResets === 1 ? '' : 's'}\n` : '') +
      (costs ? `cost per step (us): ${costs}\n` : '') +
      bridges +
      (fresh.length ? `input to force: median ${pick(0.5).toFixed(1)} ms, p95 ${pick(0.95).toFixed(1)} ms\n` : '') +
      ((t.faults || []).length ? `faults: ${t.faults.join('; ')}` : '');
    this.draw();
  }

  // A DeviceStatusT (object API): a bridge's loop timing, shown and plotted with the next Telemetry.
  /** @param {DeviceStatusT} d */
  deviceStatus(d) {
    this.devices.set(d.device, d);
  }

  // A SafetyEventT (object API), newest on top, the latest 8 kept.
  /** @param {SafetyEventT} e */
  safety(e) {
    const li = document.createElement('li');
    const kind = kindName(e.kind);
    li.textContent = `${new Date().toLocaleTimeString()} ${e.device}: ${kind}: ${e.message} (${e.forceN.toFixed(2)} N)`;
    this.events.prepend(li);
    while (this.events.children.length > 8) /** @type {ChildNode} */ (this.events.lastChild).remove();
  }

  draw() {
    const c = this.canvas;
    const g = /** @type {CanvasRenderingContext2D} */ (c.getContext('2d'));
    const w = c.width;
    const h = c.height;
    g.clearRect(0, 0, w, h);
    const n = Math.min(this.count, SPAN);
    if (n < 2) return;
    let top = 0;
    for (let i = 0; i < n; i++) top = Math.max(top, this.stepUs[i]);
    top = top * 1.2 || 1;
    /** @param {Float64Array} values @param {number} scale @param {string} colour */
    const series = (values, scale, colour) => {
      g.strokeStyle = colour;
      g.beginPath();
      let open = false;
      for (let i = 0; i < n; i++) {
        const v = values[(this.count - n + i) % SPAN];
        if (!Number.isFinite(v)) { open = false; continue; }
        const x = (i / (SPAN - 1)) * w;
        const y = h - Math.min(1, v / scale) * (h - 2) - 1;
        if (!open) g.moveTo(x, y);
        else g.lineTo(x, y);
        open = true;
      }
      g.stroke();
    };
    series(this.stepUs, top, '#7fc8ff');
    series(this.rtf, 1.25, '#ffd166');
    series(this.latency, 50, '#ef6f6c');
    series(this.bridgeDelay, 10, '#9be564');
    series(this.bridgeLate, 2, '#c792ea');
    g.fillStyle = '#aab';
    g.fillText(`step time (0-${top.toFixed(0)} us)`, 4, 10);
    g.fillStyle = '#ffd166';
    g.fillText('real-time factor (0-1.25)', 4, 22);
    g.fillStyle = '#ef6f6c';
    g.fillText('input to force (0-50 ms)', 4, 34);
    g.fillStyle = '#9be564';
    g.fillText('bridge delay (0-10 ms)', 4, 46);
    g.fillStyle = '#c792ea';
    g.fillText('bridge tick late p99 (0-2 ms)', 4, 58);
  }
}
