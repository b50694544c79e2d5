"""The network side of the bridge: the WebSocket link to the server, the clock sync, the display delay.

It runs on asyncio, apart from the tick. It turns each HapticFrame into one state per bridge device in the
Exchange, stamped in the bridge's clock (the server's production time minus the estimated clock offset),
sends each tick's pose as a DeviceInput as soon as the tick wakes it, relays the tick's safety events (to
the log, and to the server for the viewers), and reconnects when the link drops, with the link word down
in the meantime so the tick fades the force to zero.

Display delay (the 'delay' mode): one state interval plus the 99th percentile of how late states arrive
(arrival minus stamp) over the latest `lateness_window` states, recomputed every 100 ms: the state after
the one being displayed has then nearly always arrived. The state interval is the simulation step when the
server sends a state every step (the paper's one-step delay), and the interval it sends them at when its
step is shorter than a haptic tick needs (it says so by the stamps: the median interval is measured). Both
parts are reported.
"""

from __future__ import annotations

import asyncio
import collections
import gc
import itertools
import logging
import math
import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import websockets

from tactile_proto import PROTOCOL_MAJOR, PROTOCOL_MINOR, ProtocolError, check_version, decode, encode, make_hello
from tactile_proto.generated.DeviceLimits import DeviceLimitsT
from tactile_proto.generated.Ping import PingT
from tactile_proto.generated.Pong import PongT
from tactile_proto.generated.Role import Role
from tactile_proto.generated.SceneDescription import SceneDescriptionT
from tactile_proto.generated.Telemetry import TelemetryT
from tactile_proto.generated.Welcome import WelcomeT

from . import exchange as ex
from .clock import ClockSync
from .interpolation import COUPLED_MODES
from .profile import Profile
from .safety import Kind
from .wire import HAPTIC_FRAME, HapticReader, InputTemplate, message_type

log = logging.getLogger("tactile_bridge")

try:  # protocol 1.2: safety events for the viewers
    from tactile_proto.generated.SafetyEvent import SafetyEventT
except ImportError:  # pragma: no cover - an older generated codec
    SafetyEventT = None
try:  # protocol 1.3: the loop's timing for the viewers
    from tactile_proto.generated.DeviceStatus import DeviceStatusT
except ImportError:  # pragma: no cover - an older generated codec
    DeviceStatusT = None


class LinkError(RuntimeError):
    """The server refused or dropped us; the message says why."""


class Network:
    def __init__(self, url: str, token: str, profiles: Sequence[Profile], exchange: ex.Exchange, wake_fd: int,
                 *, client_name: str = "tactile-bridge", lateness_window: int = 2000, mode: str = "model",
                 status_s: float = 1.0, max_rate_hz: float = 0.0,
                 reconnect_s: float = 0.5, ping_s: float = 0.2,
                 clock: Callable[[], int] = time.monotonic_ns) -> None:
        self.url = url
        self.token = token
        self.profiles = list(profiles)
        self.ex = exchange
        self.wake_fd = wake_fd
        self.client_name = client_name
        self.reconnect_s = reconnect_s
        self.ping_s = ping_s
        self.clock = clock
        self.mode = mode
        self.max_rate_hz = max_rate_hz  # haptic states a second asked of the server (0: all; protocol 1.10)
        self.status_s = status_s
        self._status_at = (time.monotonic(), exchange.i[ex.H_TICKS], exchange.histogram())
        self.sync = ClockSync()
        self.reader = HapticReader(len(self.profiles))
        self.channels = [-1] * len(self.profiles)     # wire device index per bridge device
        self.templates = [InputTemplate(p.channel) for p in self.profiles]
        self.sent_sequence = [0] * len(self.profiles)
        self.last_pose_seq = [-1] * len(self.profiles)
        self.lateness: collections.deque[int] = collections.deque(maxlen=lateness_window)
        self.stamps: collections.deque[int] = collections.deque(maxlen=lateness_window)
        self.dt_ns = 0
        self.interval_ns = 0                        # between states, measured [ns]
        self.allowance_ns = 0
        self.events_read = 0
        self.pending_events: collections.deque[bytes] = collections.deque(maxlen=256)
        self.scene_name = ""
        self.server_minor = 0
        self.frames = 0
        self.bad_frames = 0
        self.connects = 0
        self.last_error = ""
        self.fault = ""
        self._wake = asyncio.Event()
        self._ws: Any = None
        self._ping_sent: dict[int, int] = {}
        self._ping_id = 0

    # ---- the link ------------------------------------------------------------------------------------

    async def run(self, stop: asyncio.Event) -> None:
        """Connects, serves, and reconnects until `stop` is set."""
        # What lives as long as the process (modules, the websockets library, the codec) is frozen out of the
        # cyclic collector's scans, here and at each scene: a full collection of it stops this loop, and poses
        # that stop leave the server's device path extrapolating past the hand (bridge_bench.py loop --cases
        # free guards it).
        gc.collect()
        gc.freeze()
        loop = asyncio.get_running_loop()
        loop.add_reader(self.wake_fd, self._on_wake)
        pump = asyncio.create_task(self._pump(stop))
        try:
            while not stop.is_set():
                try:
                    await self._connection(stop)
                except (TimeoutError, OSError, websockets.exceptions.WebSocketException, LinkError, ProtocolError) as e:
                    msg = str(e) or type(e).__name__
                    if msg != self.last_error:
                        log.warning("link: %s; retrying every %.1f s", msg, self.reconnect_s)
                    self.last_error = msg
                finally:
                    self._link_down()
                try:
                    await asyncio.wait_for(stop.wait(), self.reconnect_s)
                except TimeoutError:
                    pass
        finally:
            loop.remove_reader(self.wake_fd)
            pump.cancel()
            await asyncio.gather(pump, return_exceptions=True)
            self._drain_events(send=False)

    def _link_down(self) -> None:
        self.ex.i[ex.H_LINK] = 0
        self._ws = None

    async def _connection(self, stop: asyncio.Event) -> None:
        async with websockets.connect(self.url, max_size=64 << 20, compression=None, open_timeout=3,
                                      ping_interval=None) as ws:
            hello = make_hello(Role.Device, self.token, self.client_name, [p.channel for p in self.profiles])
            hello.deviceLimits = [self._limits(p) for p in self.profiles]
            hello.maxRateHz = self.max_rate_hz
            await ws.send(encode(hello))
            welcome = await self._expect(ws, WelcomeT)
            check_version(welcome)
            if welcome.role != Role.Device:
                raise LinkError(f"the server granted role {welcome.role}, not device")
            self.server_minor = welcome.protocolMinor
            scene = await self._expect(ws, SceneDescriptionT)
            self._on_scene(scene)
            self._ws = ws
            self.connects += 1
            self.last_error = ""
            log.info("link: connected to %s (protocol %d.%d; we speak %d.%d), scene %r", self.url,
                     welcome.protocolMajor, welcome.protocolMinor, PROTOCOL_MAJOR, PROTOCOL_MINOR, self.scene_name)
            pinger = asyncio.create_task(self._pinger())
            stopper = asyncio.create_task(stop.wait())
            try:
                reader = asyncio.create_task(self._read(ws))
                done, _ = await asyncio.wait({reader, stopper}, return_when=asyncio.FIRST_COMPLETED)
                if reader in done:
                    reader.result()  # raises what ended it
                    raise LinkError("the server closed the connection")
                reader.cancel()
            finally:
                pinger.cancel()
                stopper.cancel()
                await asyncio.gather(pinger, stopper, return_exceptions=True)

    def _limits(self, profile: Profile) -> Any:
        """What the device renders, for the server's coupling; or, in the other modes, that it drives directly."""
        limits = DeviceLimitsT()
        limits.maxForceN, limits.maxTorqueNm, limits.stiffnessNPerM = profile.scene_limits()
        limits.direct = self.mode not in COUPLED_MODES
        return limits

    async def _expect(self, ws: Any, kind: type, timeout: float = 5.0) -> Any:
        """The next message of type `kind`, skipping others; LinkError on an Error message."""
        deadline = time.monotonic() + timeout
        while True:
            raw = await asyncio.wait_for(ws.recv(), max(0.01, deadline - time.monotonic()))
            m = decode(raw).message
            if isinstance(m, kind):
                return m
            if type(m).__name__ == "ErrorT":
                raise LinkError(f"the server refused: {m.message}")

    # ---- from the server -----------------------------------------------------------------------------

    def _on_scene(self, scene: Any) -> None:
        wire_devices = list(scene.devices or [])
        self.channels = [wire_devices.index(p.channel) if p.channel in wire_devices else -1 for p in self.profiles]
        for p, w in zip(self.profiles, self.channels, strict=True):
            if w < 0:
                log.warning("scene %r has no device channel %r (it has: %s): that device gets no force",
                            scene.sceneName, p.channel, ", ".join(wire_devices) or "none")
        self.scene_name = scene.sceneName or ""
        self.dt_ns = int(round(scene.dt * 1e9))
        self.lateness.clear()
        self.stamps.clear()
        self.allowance_ns = 0
        x = self.ex.i
        x[ex.H_DT_NS] = self.dt_ns
        x[ex.H_DELAY_NS] = self.dt_ns + 500_000  # until lateness is measured: half a millisecond of allowance
        x[ex.H_FAULT] = 0
        self.fault = ""
        x[ex.H_SCENE_GEN] += 1
        x[ex.H_LINK] = 1
        gc.freeze()

    async def _read(self, ws: Any) -> None:
        async for raw in ws:
            if isinstance(raw, str):
                log.warning("link: a text message from the server (ignored)")
                continue
            arrival = self.clock()
            try:
                kind, table = message_type(raw)
                if kind == HAPTIC_FRAME and table is not None:
                    self._on_haptic(table, arrival)
                    continue
                m = decode(raw).message
            except (ProtocolError, ValueError) as e:  # struct.error is a ValueError... of sorts
                self.bad_frames += 1
                log.warning("link: an unreadable message dropped (%s)", e)
                continue
            self._on_message(m, arrival)

    def _on_haptic(self, table: Any, arrival: int) -> None:
        r = self.reader
        r.read(table, self.channels)
        t = self.sync.to_bridge(r.server_time_ns, arrival) if self.sync.synced else arrival
        self.frames += 1
        self.lateness.append(arrival - t)
        self.stamps.append(r.server_time_ns)
        for k in range(len(self.profiles)):
            if r.contacts[k] < 0:
                continue
            pos = r.position[k]
            if not r.has_pose[k]:  # a 1.1 server: the pose we sent last stands for the one it used
                pose = self.ex.read_pose(k)
                if pose is not None:
                    pos[0], pos[1], pos[2] = pose[4]
            self.ex.write_state(k, t, arrival, r.step, r.contacts[k], r.force[k], r.stiffness[k], pos,
                                r.coupled[k], r.max_force[k], r.model[k])

    def _on_message(self, m: Any, arrival: int) -> None:
        if isinstance(m, PongT):
            sent = self._ping_sent.pop(m.id, None)
            if sent is not None and self.sync.add(m.clientTimeNs, m.serverReceiveNs, m.serverSendNs, arrival):
                pass
        elif isinstance(m, TelemetryT):
            if m.faults:
                self.fault = "; ".join(m.faults)
                self.ex.i[ex.H_FAULT] = 1
                log.error("server fault: %s", self.fault)
        elif isinstance(m, SceneDescriptionT):
            log.info("link: new scene %r (id %d)", m.sceneName, m.sceneId)
            self._on_scene(m)
        elif type(m).__name__ == "ErrorT":
            log.warning("server: %s", m.message)

    # ---- to the server -------------------------------------------------------------------------------

    def _on_wake(self) -> None:
        try:
            os.read(self.wake_fd, 4096)
        except BlockingIOError:
            pass
        self._wake.set()

    async def _pump(self, stop: asyncio.Event) -> None:
        """Sends each new pose, relays events, and re-estimates the display delay every 100 ms."""
        next_delay = 0.0
        while not stop.is_set():
            await self._wake.wait()
            self._wake.clear()
            ws = self._ws
            if ws is not None:
                for k, tmpl in enumerate(self.templates):
                    pose = self.ex.read_pose(k)
                    if pose is None or not pose[3] or pose[1] == self.last_pose_seq[k] or self.channels[k] < 0:
                        continue
                    self.last_pose_seq[k] = pose[1]
                    self.sent_sequence[k] += 1
                    try:
                        await ws.send(tmpl.encode(self.sent_sequence[k], pose[0], pose[4], pose[5], pose[2]))
                    except websockets.exceptions.ConnectionClosed:
                        break
            self._drain_events(send=ws is not None)
            now = time.monotonic()
            if now >= next_delay:
                next_delay = now + 0.1
                self._update_delay()
            if now >= self._status_at[0] + self.status_s:
                self._send_status(now)

    def status_messages(self, now: float) -> list[Any]:
        """Per channel, how the loop kept time since the previous call (DeviceStatusT)."""
        x = self.ex
        t0, ticks0, hist0 = self._status_at
        ticks, hist = x.i[ex.H_TICKS], x.histogram()
        self._status_at = (now, ticks, hist)
        h = [b - a for a, b in zip(hist0, hist, strict=True)]
        p99 = ex.percentile_us(h, 0.99)
        top = max((us for us, n in enumerate(h) if n), default=math.nan)
        out = []
        for k, p in enumerate(self.profiles):
            _, bd = x.status_base(k)
            m = DeviceStatusT()
            m.device, m.deviceTimeNs, m.mode = p.channel, self.clock(), self.mode
            m.tickRateHz = (ticks - ticks0) / max(1e-9, now - t0)
            m.latenessP99Us = 0.0 if math.isnan(p99) else p99
            m.latenessMaxUs = 0.0 if math.isnan(top) else float(top)
            m.missedTicks = int(x.i[ex.H_MISSED])
            m.stateIntervalMs = x.i[ex.H_DT_NS] / 1e6
            m.jitterAllowanceMs = x.i[ex.H_ALLOW_NS] / 1e6
            m.displayDelayMs = x.i[ex.H_DELAY_NS] / 1e6
            m.forceN = math.sqrt(sum(v * v for v in x.d[bd + 3: bd + 6]))
            out.append(m)
        return out

    def _send_status(self, now: float) -> None:
        if DeviceStatusT is None:  # an older generated codec: nothing to send them with
            self._status_at = (now, self.ex.i[ex.H_TICKS], self.ex.histogram())
            return
        messages = self.status_messages(now)  # (also starts the next window)
        ws = self._ws
        if ws is None or self.server_minor < 3:
            return
        for m, channel in zip(messages, self.channels, strict=True):
            if channel >= 0:
                asyncio.ensure_future(self._send_quietly(ws, encode(m)))

    def _update_delay(self) -> None:
        if len(self.lateness) < 20:
            return
        s = sorted(self.lateness)
        self.allowance_ns = max(0, s[min(len(s) - 1, int(0.99 * len(s)))])
        st = list(self.stamps)
        gaps = sorted(b - a for a, b in itertools.pairwise(st) if b > a)
        self.interval_ns = max(self.dt_ns, gaps[len(gaps) // 2]) if gaps else self.dt_ns
        self.ex.i[ex.H_DT_NS] = self.interval_ns
        self.ex.i[ex.H_ALLOW_NS] = self.allowance_ns
        self.ex.i[ex.H_DELAY_NS] = self.interval_ns + self.allowance_ns

    def _drain_events(self, send: bool) -> None:
        x = self.ex
        while self.events_read < x.i[ex.H_EVENTS]:
            e = x.read_event(self.events_read)
            self.events_read += 1
            if e is None:
                log.warning("safety: events were overwritten before they were read")
                continue
            t_ns, kind, dev, force, message = e
            channel = self.profiles[dev].channel if 0 <= dev < len(self.profiles) else "?"
            log.log(logging.WARNING if kind not in (Kind.ENGAGED, Kind.DEVICE_RECONNECTED) else logging.INFO,
                    "safety: t=%.6f s %s %s: %s (|F| %.3f N)", t_ns * 1e-9, channel, Kind(kind).name.lower(),
                    message, force)
            if SafetyEventT is not None:
                m = SafetyEventT()
                m.device, m.deviceTimeNs, m.kind, m.message, m.forceN = channel, t_ns, kind, message, force
                self.pending_events.append(encode(m))
        if send and self.server_minor >= 2 and self._ws is not None:
            ws = self._ws
            while self.pending_events:
                asyncio.ensure_future(self._send_quietly(ws, self.pending_events.popleft()))

    @staticmethod
    async def _send_quietly(ws: Any, data: bytes) -> None:
        try:
            await ws.send(data)
        except websockets.exceptions.ConnectionClosed:
            pass

    async def _pinger(self) -> None:
        """Ping/Pong for the clock offset: quickly at first, then every ping_s."""
        n = 0
        while True:
            ws = self._ws
            if ws is None:
                return
            self._ping_id = (self._ping_id + 1) & 0xFFFFFFFF
            t1 = self.clock()
            self._ping_sent[self._ping_id] = t1
            if len(self._ping_sent) > 64:
                self._ping_sent.pop(next(iter(self._ping_sent)))
            p = PingT()
            p.id, p.clientTimeNs = self._ping_id, t1
            await ws.send(encode(p))
            n += 1
            await asyncio.sleep(0.02 if n < 20 else self.ping_s)
