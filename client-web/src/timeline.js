// The replay's timeline: shown when the server replays a recording (it sends ReplayStatus ten times a
// second). Play and pause, a slider to seek, the speed, and where the replay is. Each action goes as a
// Control through the controller connection (ControlPanel), taken on first use when the page has the
// token; without it the timeline only shows where the replay is.
import { ControlCommand, PauseT, ResumeT, SeekT, SetSpeedT } from '@tactile/proto';
import { el } from './controls.js';
/** @import { ControlT, ReplayStatusT } from '@tactile/proto' */
/** @import { ControlPanel } from './controls.js' */

export const SPEEDS = [0.25, 0.5, 1, 2, 4];

export class Timeline {
  /** @param {HTMLElement} element @param {ControlPanel} controlPanel */
  constructor(element, controlPanel) {
    this.element = element;
    this.control = controlPanel;
    /** @type {ReplayStatusT | null} */
    this.status = null;
    this.dragging = false;
    this.name = el('div', { className: 'name' });
    this.play = el('button', { textContent: 'pause', name: 'replay-play' });
    this.play.addEventListener('click', () => {
      if (!this.status) return;
      if (this.status.paused) this.send(ControlCommand.Resume, new ResumeT(), 'play');
      else this.send(ControlCommand.Pause, new PauseT(), 'pause');
    });
    this.slider = el('input', { type: 'range', min: '0', max: '1', step: 'any', value: '0', name: 'replay-seek' });
    this.slider.addEventListener('input', () => {
      this.dragging = true;
      this.showTime(Number(this.slider.value));
    });
    this.slider.addEventListener('change', () => {
      this.dragging = false;
      const t = Number(this.slider.value);
      this.send(ControlCommand.Seek, new SeekT(t), `seek to ${t.toFixed(2)} s`);
    });
    this.speed = el('select', { name: 'replay-speed' });
    for (const s of SPEEDS) this.speed.append(el('option', { value: String(s), textContent: `${s}x` }));
    this.speed.value = '1';
    this.speed.addEventListener('change', () => {
      const s = Number(this.speed.value);
      this.send(ControlCommand.SetSpeed, new SetSpeedT(s), `speed ${s}x`);
    });
    this.time = el('span', { className: 'time' });
    element.append(this.name, el('div', { className: 'row' }, this.play, this.slider, this.speed), this.time);
    element.hidden = true;
  }

  /** @param {ControlCommand} type @param {ControlT['command']} command @param {string} what */
  send(type, command, what) {
    if (!this.control.token) {
      this.control.say('steering a replay needs the token (?token=...)');
      return;
    }
    this.control.sendWhenGranted(type, command, what);
  }

  // From the viewer connection, ten times a second.
  /** @param {ReplayStatusT} st */
  update(st) {
    this.status = st;
    this.element.hidden = false;
    this.name.textContent = `replay: ${st.path}`;
    this.play.textContent = st.paused ? 'play' : 'pause';
    this.slider.max = String(st.durationS);
    if (!this.dragging) {
      this.slider.value = String(st.positionS);
      this.showTime(st.positionS);
    }
    if (document.activeElement !== this.speed) this.speed.value = String(st.speed);
  }

  /** @param {number} t */
  showTime(t) {
    const st = this.status;
    this.time.textContent =
      `${t.toFixed(2)} / ${st ? st.durationS.toFixed(2) : '?'} s` +
      (st && st.speed !== 1 ? ` at ${st.speed}x` : '') +
      (st && st.paused ? ', paused' : '');
  }
}
