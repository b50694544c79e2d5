// The telemetry panel: the server's figures as text, and two plots over the last minute (uPlot, redrawn
// when a Telemetry arrives, about once a second): the step time and the real-time factor; and, in ms, the
// input-to-force latency (while this page drives a device) and the first device bridge's display delay and
// tick lateness (while one reports, protocol 1.3). Safety events relayed from device bridges are listed
// with their time and cause.
import uPlot from 'uplot';

import { SafetyKind } from '@tactile/proto';
/** @import { DeviceStatusT, SafetyEventT, TelemetryT } from '@tactile/proto' */

const SPAN = 60; // samples kept (about a minute)
const PLOT_HEIGHT = 96; // each plot's drawing area with its axes [CSS px]
const AXIS = {
  stroke: '#aab2c0',
  font: '10px system-ui, sans-serif',
  labelFont: '10px system-ui, sans-serif',
  grid: { stroke: 'rgba(255, 255, 255, 0.08)', width: 1 },
  ticks: { stroke: 'rgba(255, 255, 255, 0.2)', width: 1 },
};

// The legend's value: the number with its unit, or a dash where there is none.
/** @param {string} unit @param {number} digits */
const shown = (unit, digits) => (/** @type {uPlot} */ _u, /** @type {number | null} */ v) =>
  v === null || v === undefined || !Number.isFinite(v) ? '–' : `${v.toFixed(digits)}${unit ? ' ' + unit : ''}`;

// An axis's tick with its unit, a thousand of it in the next unit up (1500 µs as 1.5 ms), so that the axis
// stays narrow.
/** @param {string[]} units smallest first, each a thousand of the one before */
const ticksIn = (units) => (/** @type {uPlot} */ _u, /** @type {number[]} */ ticks) =>
  ticks.map((t) => {
    let k = 0;
    let v = t;
    while (Math.abs(v) >= 1000 && k + 1 < units.length) {
      v /= 1000;
      k += 1;
    }
    return `${+v.toPrecision(4)} ${units[k]}`;
  });

// A plot of the last minute (x: seconds before the newest sample) with its axes and series.
/**
 * @param {HTMLElement} into @param {uPlot.Scales} scales @param {uPlot.Axis[]} axes @param {uPlot.Series[]} series
 */
function makePlot(into, scales, axes, series) {
  /** @type {uPlot.Options} */
  const options = {
    width: 280,
    height: PLOT_HEIGHT,
    scales: { x: { time: false, range: [-SPAN, 0] }, ...scales },
    axes: [{ ...AXIS, size: 28, values: (_u, ticks) => ticks.map((t) => (t === 0 ? 'now' : `${t} s`)) }, ...axes],
    series: [{ label: 'time', value: shown('s', 0) }, ...series],
    cursor: { drag: { x: false, y: false } },
  };
  return new uPlot(options, [[], ...series.map(() => [])], into);
}

// 'ContinuousLimit' -> 'continuous limit'
/** @param {SafetyKind} k */
const kindName = (k) => (SafetyKind[k] ?? `kind ${k}`).replace(/([a-z])([A-Z])/g, '$1 $2').toLowerCase();

export class TelemetryPanel {
  /** @param {HTMLElement} element */
  constructor(element) {
    // (index.html has each of them.)
    this.text = /** @type {HTMLElement} */ (element.querySelector('.figures'));
    this.plotsElement = /** @type {HTMLElement} */ (element.querySelector('.plots'));
    this.events = /** @type {HTMLElement} */ (element.querySelector('.events'));
    this.timeS = new Float64Array(SPAN); // when each sample was taken: server clock [s]
    this.stepUs = new Float64Array(SPAN);
    this.rtf = new Float64Array(SPAN);
    this.latency = new Float64Array(SPAN).fill(NaN);
    this.bridgeLate = new Float64Array(SPAN).fill(NaN); // tick lateness p99 [ms], the first bridge's
    this.bridgeDelay = new Float64Array(SPAN).fill(NaN); // its display delay [ms]
    /** @type {Map<DeviceStatusT['device'], DeviceStatusT>} */
    this.devices = new Map(); // channel -> its latest DeviceStatusT
    this.count = 0;
    /** @type {TelemetryT | null} */
    this.latest = null;
    const fromZero = /** @type {uPlot.Scale.Range} */ ((_u, _lo, hi) => [0, hi > 0 ? 1.15 * hi : 1]);
    this.plots = [
      makePlot(
        this.plotsElement,
        { us: { range: fromZero }, rtf: { range: [0, 1.25] } },
        [
          { ...AXIS, scale: 'us', size: 54, values: ticksIn(['µs', 'ms', 's']) },
          { ...AXIS, scale: 'rtf', side: 1, size: 34, grid: { show: false } },
        ],
        [
          { label: 'step time', scale: 'us', stroke: '#7fc8ff', width: 1.5, value: shown('µs', 1) },
          { label: 'real-time factor', scale: 'rtf', stroke: '#ffd166', width: 1.5, value: shown('', 3) },
        ],
      ),
      makePlot(
        this.plotsElement,
        { ms: { range: fromZero } },
        [{ ...AXIS, scale: 'ms', size: 54, values: ticksIn(['ms', 's']) }],
        [
          { label: 'input to force', scale: 'ms', stroke: '#ef6f6c', width: 1.5, value: shown('ms', 1) },
          { label: 'bridge delay', scale: 'ms', stroke: '#9be564', width: 1.5, value: shown('ms', 2) },
          { label: 'bridge tick late p99', scale: 'ms', stroke: '#c792ea', width: 1.5, value: shown('ms', 2) },
        ],
      ),
    ];
  }

  // Sizes the plots to the panel (after a resize, or when the panel opens; not while it is folded).
  resize() {
    const w = this.plotsElement.clientWidth;
    if (w > 0) for (const p of this.plots) if (p.width !== w) p.setSize({ width: w, height: PLOT_HEIGHT });
  }

  // A TelemetryT (object API); `latencies`: this page's latest input-to-force round trips [ms] (the
  // ones since the previous call are summarised: median and 95th percentile).
  /** @param {TelemetryT} t @param {number[]} [latencies] */
  update(t, latencies = []) {
    this.latest = t;
    const k = this.count % SPAN;
    this.timeS[k] = Number(t.serverTimeNs) / 1e9;
    this.stepUs[k] = t.stepTimeMeanUs;
    this.rtf[k] = t.realTimeFactor;
    const fresh = latencies.splice(0).sort((a, b) => a - b);
    const pick = (/** @type {number} */ q) => fresh[Math.min(fresh.length - 1, Math.floor(q * fresh.length))];
    this.latency[k] = fresh.length ? pick(0.5) : NaN;
    const bridge = this.devices.values().next().value;
    const current = bridge && Number(t.serverTimeNs - bridge.serverTimeNs) < 3e9; // reported in the last 3 s
    this.bridgeLate[k] = current ? bridge.latenessP99Us / 1000 : NaN;
    this.bridgeDelay[k] = current ? bridge.displayDelayMs : NaN;
    this.count += 1;
    const bridges = [...this.devices.values()]
      .filter((d) => Number(t.serverTimeNs - d.serverTimeNs) < 3e9)
      .map(
        (d) =>
          `bridge ${d.device}: tick ${d.tickRateHz.toFixed(0)} Hz, late p99 ${d.latenessP99Us.toFixed(0)} us ` +
          `(max ${d.latenessMaxUs.toFixed(0)}), missed ${d.missedTicks}, delay ${d.displayDelayMs.toFixed(2)} ms ` +
          `(${d.stateIntervalMs.toFixed(2)} + ${d.jitterAllowanceMs.toFixed(2)}), ${d.mode}, ${d.forceN.toFixed(2)} N\n`,
      )
      .join('');
    const costs = (t.effectCosts || [])
      .filter((c) => c.nsPerStep > 0)
      .map((c) => `${c.name} ${(c.nsPerStep / 1000).toFixed(1)}`)
      .join(', ');
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

  // The samples, oldest first, as the plots' data: x in seconds before the newest; a missing value as null
  // (a gap in its line).
  draw() {
    const n = Math.min(this.count, SPAN);
    const at = (/** @type {number} */ i) => (this.count - n + i) % SPAN;
    const newest = this.timeS[at(n - 1)];
    const x = Array.from({ length: n }, (_, i) => this.timeS[at(i)] - newest);
    /** @param {Float64Array} values */
    const series = (values) =>
      Array.from({ length: n }, (_, i) => {
        const v = values[at(i)];
        return Number.isFinite(v) ? v : null;
      });
    this.plots[0].setData([x, series(this.stepUs), series(this.rtf)]);
    this.plots[1].setData([x, series(this.latency), series(this.bridgeDelay), series(this.bridgeLate)]);
    // The legend shows the newest values, with their units, unless the pointer is over a plot.
    for (const p of this.plots)
      if (n > 0 && !(p.cursor.left !== undefined && p.cursor.left >= 0)) p.setLegend({ idx: n - 1 });
  }
}
