// The controller's panel: with the token, "take control" opens a controller connection (one at a time on
// a server) and the panel offers what the scene description lists: the scenes this server may load, pause,
// resume and reset, every parameter with its range (switches for the effects), and recording. Each
// change goes as a Control with its own request id; the server answers with the change itself (a new
// description, telemetry showing the pause) or an Error naming what is wrong, shown here.
import {
  ControlCommand,
  ControlT,
  EnvelopeT,
  ErrorCode,
  LoadSceneT,
  Message,
  PauseT,
  ResetT,
  ResumeT,
  Role,
  SetParameterT,
  StartRecordingT,
  StopRecordingT,
  decode,
  messageTypeOf,
} from '@tactile/proto';
import { ClosedError, ServerError, connect } from './connection.js';
/** @import { ErrorT, SceneDescriptionT } from '@tactile/proto' */
/** @import { Connection } from './connection.js' */

// An element with properties and children.
/**
 * @template {keyof HTMLElementTagNameMap} K
 * @param {K} tag @param {Partial<HTMLElementTagNameMap[K]>} [attrs] @param {...(Node | string)} children
 * @returns {HTMLElementTagNameMap[K]}
 */
export const el = (tag, attrs = {}, ...children) => {
  const e = document.createElement(tag);
  Object.assign(e, attrs);
  for (const c of children) e.append(c);
  return e;
};

export class ControlPanel {
  /** @param {HTMLElement} element @param {{ token: string, url: string }} options */
  constructor(element, { token, url }) {
    this.token = token;
    this.url = url;
    /** @type {Connection | null} */
    this.connection = null;
    this.granted = false;
    this.requestId = 0;
    /** @type {Map<number, string>} */
    this.pending = new Map(); // request id -> what it asked, for the answer
    /** @type {SceneDescriptionT | null} */
    this.description = null;
    this.paused = false;
    this.replaying = false; // the server replays a recording: only the timeline steers it
    /** @type {[ControlCommand, ControlT['command'], string][]} */
    this.queued = []; // sent once control is granted (sendWhenGranted)
    this.head = el('div', { className: 'head' });
    this.take = el('button', {
      textContent: 'take control',
      disabled: !token,
      title: token ? '' : 'the controller role needs the token: open the URL with ?token=...',
    });
    this.take.addEventListener('click', () => (this.granted ? this.release() : this.connect()));
    this.head.append(this.take);
    this.body = el('div', { className: 'body' });
    this.message = el('div', { className: 'message' });
    element.append(this.head, this.body, this.message);
    this.say(token ? '' : 'controls need the token (?token=...)');
  }

  /** @param {string} text */
  say(text) {
    this.message.textContent = text;
  }

  connect() {
    const connection = connect(this.url, Role.Controller, {
      token: this.token,
      clientName: 'client-web',
      onMessage: (data) => {
        if (messageTypeOf(data) !== Message.Error) return;
        this.showError(new ServerError(/** @type {ErrorT} */ (decode(data).message)));
      },
      onClose: ({ reason }) => {
        if (this.connection !== connection) return;
        this.connection = null;
        this.granted = false;
        this.take.textContent = 'take control';
        if (reason) this.say(reason); // (refused or evicted, close code 1013)
        this.build();
      },
    });
    this.connection = connection;
    connection.welcome.then(
      () => {
        if (this.connection !== connection) return;
        this.granted = true;
        this.take.textContent = 'release control';
        this.say('in control');
        this.build();
        for (const [type, command, what] of this.queued.splice(0)) this.send(type, command, what);
      },
      (err) => {
        if (!(err instanceof ClosedError)) this.showError(err); // (a close is onClose's)
      },
    );
  }

  // The server's Error, with what the request it answers asked (a refused Hello: another controller, a wrong
  // token), or bytes that are no message.
  /** @param {Error & { code?: ErrorCode, requestId?: number }} err */
  showError(err) {
    const asked = this.pending.get(err.requestId ?? 0);
    this.pending.delete(err.requestId ?? 0);
    this.say(asked ? `${asked}: ${err.message}` : err.message);
    if (!this.granted && err.code === ErrorCode.Busy) this.say('another controller is connected');
  }

  // Sends now if in control, else takes control first (the page has the token) and sends then.
  /** @param {ControlCommand} type @param {ControlT['command']} command @param {string} what */
  sendWhenGranted(type, command, what) {
    if (this.granted) {
      this.send(type, command, what);
      return;
    }
    this.queued.push([type, command, what]);
    if (!this.connection) this.connect();
  }

  /** @param {boolean} replaying */
  setReplaying(replaying) {
    if (replaying === this.replaying) return;
    this.replaying = replaying;
    this.build();
  }

  release() {
    if (this.connection) this.connection.close();
  }

  // From the viewer connection: every description (a load, a reset, a parameter set) and telemetry.
  /** @param {SceneDescriptionT} d */
  setDescription(d) {
    this.description = d;
    this.build();
  }

  /** @param {boolean} paused */
  setPaused(paused) {
    if (paused === this.paused) return;
    this.paused = paused;
    if (this.pauseButton) this.pauseButton.textContent = paused ? 'resume' : 'pause';
  }

  /** @param {ControlCommand} type @param {ControlT['command']} command @param {string} what */
  send(type, command, what) {
    if (!this.connection || !this.granted) return;
    this.requestId += 1;
    this.pending.set(this.requestId, what); // (answered by an Error, or by the change: the latest 64 kept)
    if (this.pending.size > 64) this.pending.delete(/** @type {number} */ (this.pending.keys().next().value));
    this.connection.send(new EnvelopeT(Message.Control, new ControlT(this.requestId, type, command)));
    this.say(`${what}…`);
  }

  build() {
    this.body.replaceChildren();
    const d = this.description;
    if (!this.granted || !d) return;
    if (this.replaying) {
      this.body.append(
        el('div', {
          textContent:
            'replaying a recording: the timeline steers it; scenes, parameters ' + 'and recording need a live session',
        }),
      );
      return;
    }
    // Scenes, and the run.
    const picker = el('select', { name: 'scene' });
    for (const s of d.scenes || []) picker.append(el('option', { value: s, textContent: s }));
    // (The scene running, when the list names its file.)
    const running = (d.scenes || []).find((s) => s.replace(/\.json$/, '') === d.sceneName);
    if (running) picker.value = running;
    const load = el('button', { textContent: 'load', disabled: !(d.scenes || []).length });
    load.addEventListener('click', () => {
      this.send(ControlCommand.LoadScene, new LoadSceneT(picker.value), `load ${picker.value}`);
    });
    this.pauseButton = el('button', { textContent: this.paused ? 'resume' : 'pause', name: 'pause' });
    this.pauseButton.addEventListener('click', () => {
      if (this.paused) this.send(ControlCommand.Resume, new ResumeT(), 'resume');
      else this.send(ControlCommand.Pause, new PauseT(), 'pause');
    });
    const reset = el('button', { textContent: 'reset', name: 'reset' });
    reset.addEventListener('click', () => this.send(ControlCommand.Reset, new ResetT(), 'reset'));
    this.body.append(
      el('div', { className: 'row' }, picker, load),
      el('div', { className: 'row' }, this.pauseButton, reset),
    );
    // Parameters: a switch for on/off, a number field (applied on change) for the rest.
    const table = el('div', { className: 'params' });
    for (const p of d.parameters || []) {
      const name = /** @type {string} */ (p.name);
      /** @type {HTMLInputElement} */
      let input;
      if (p.unit === 'on/off') {
        input = el('input', { type: 'checkbox', checked: p.value !== 0 });
        input.addEventListener('change', () => {
          this.send(ControlCommand.SetParameter, new SetParameterT(name, input.checked ? 1 : 0), `set ${name}`);
        });
      } else {
        input = el('input', {
          type: 'number',
          value: String(p.value),
          min: String(p.min),
          max: String(p.max),
          step: 'any',
        });
        input.addEventListener('change', () => {
          const v = Number(input.value);
          if (!Number.isFinite(v)) {
            this.say(`${name}: not a number`);
            return;
          }
          this.send(ControlCommand.SetParameter, new SetParameterT(name, v), `set ${name}`);
        });
      }
      input.dataset.parameter = name;
      table.append(el('label', { textContent: `${name} ` }, input, el('span', { textContent: ` ${p.unit}` })));
    }
    this.body.append(table);
    // Recording.
    const file = el('input', { type: 'text', value: `${d.sceneName || 'session'}.mcap`, name: 'record-path' });
    const start = el('button', { textContent: 'record' });
    start.addEventListener('click', () => {
      this.send(ControlCommand.StartRecording, new StartRecordingT(file.value), `record ${file.value}`);
    });
    const stop = el('button', { textContent: 'stop recording' });
    stop.addEventListener('click', () =>
      this.send(ControlCommand.StopRecording, new StopRecordingT(), 'stop recording'),
    );
    this.body.append(el('div', { className: 'row' }, file, start, stop));
  }
}
