"""Two recordings of one session side by side (proto/RECORDING.md): typically a live recording (A) and a
re-simulation of its device inputs (B) with another material or mesh.

    comparison = compare(open_recording(a_path), open_recording(b_path))   # CompareError: nothing to compare
    write_csv(comparison, "compare.csv"); plot(comparison, "compare.png"); print(summarize(comparison))

Pairing: the frames of each file's first scene_id (the first SceneDescription's; a file that holds several
scenes gets a note) are paired by simulated time, each of A's HapticFrames and StateFrames with B's frame of
its kind nearest in sim_time, within a tolerance: half a step by default, the larger of the two scenes' dt.
A frame of A with none within it is unpaired; the summary counts both.

What is compared, per paired time:
  - forces: each device channel's (HapticFrame.devices, named by SceneDescription.devices) and each proxy's
    (HapticFrame.proxies, named by SceneDescription.proxies), A's and B's [N] and |F_A - F_B| [N]; each
    proxy's pose: |p_A - p_B| [m] and the angle between the orientations [rad]. Channels and proxies are
    matched by name; those only one file has are noted and left out.
  - the surface, when both scenes have as many vertices: max and RMS over the vertices of |x_A - x_B| [m]
    (StateFrame.positions, n_vertices x 3). When the counts differ (another mesh), the displacement at each
    proxy instead: the surface vertex nearest the proxy's position (StateFrame.proxies) in each file, and
    its displacement from its own rest position (SceneDescription.rest_positions), |u_A|, |u_B| and
    |u_A - u_B| [m].
  - bit for bit: a paired state is identical when its sim_time, positions, scalar, proxy poses and contact
    forces are; a paired haptic frame when its sim_time and every field of each device's and proxy's
    haptics (force, torque, pose, stiffness, contacts) are: the raw float32 values compared exactly.

compare.csv: one row per sim time of A that paired a haptic frame or a state, in sim-time order. Columns:
`sim_time_s` (A's), `haptic.sim_time_B_s` and `state.sim_time_B_s` (the paired frames' of B), then for each
device channel d `A.device.d.fx_N`, fy, fz, `B.device.d.fx_N`..., `device.d.dF_N` (|F_A - F_B|); for each
proxy p the same as `A.proxy.p.fx_N`..., `proxy.p.dF_N`, and `proxy.p.dposition_m`, `proxy.p.drotation_rad`;
then, when the vertex counts agree, `surface.dx_max_m` and `surface.dx_rms_m`, else per proxy
`A.proxy.p.u_m`, `B.proxy.p.u_m`, `proxy.p.du_m`. A row that paired only one kind of frame leaves the other
kind's columns empty. Floats as the shortest text that reads back as the same value (float32 fields as
float32, the differences, computed in float64, as float64).
compare.png (matplotlib, the `plot` extra): stacked panels on the sim-time axis: |F| of each device channel
in A and B; |F_A - F_B| per channel; the surface difference (max, RMS) or the displacement difference at
each proxy.

HapticFrames come at every step (some 8 kHz): they are read here through the generated table accessors,
their device and proxy structs as numpy records straight from the message's bytes, not through
codec.decode's object API, which takes about 0.8 ms a frame (6 minutes per file for a minute of session at
8 kHz) where this takes under 0.1 ms. The records' layout (DEVICE_HAPTICS, PROXY_HAPTICS) is tactile.fbs's:
its sizes are checked against the generated code on import, its fields by tests/test_recording_compare.py.
Each file is read twice: once for all but the surfaces (the nearest vertex to each proxy is found then),
once for the paired surfaces, two at a time, so that no file's surfaces are all held in memory.
"""

from __future__ import annotations

import csv
import importlib
import math
import pathlib
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tactile_proto.codec import FILE_IDENTIFIER, ProtocolError, decode
from tactile_proto.generated.DeviceHaptics import DeviceHaptics
from tactile_proto.generated.Envelope import Envelope
from tactile_proto.generated.HapticFrame import HapticFrame
from tactile_proto.generated.Message import Message
from tactile_proto.generated.ProxyHaptics import ProxyHaptics
from tactile_proto.generated.ProxyPose import ProxyPose
from tactile_proto.generated.SceneDescription import SceneDescriptionT
from tactile_proto.generated.StateFrame import StateFrame
from tactile_proto.generated.Vec3f import Vec3f

from .export import _f32, _f64
from .reader import Recording

# tactile.fbs's structs as numpy records (little-endian, 4-byte fields, no padding).
POSE = np.dtype([("position", "<f4", (3,)), ("orientation", "<f4", (4,))])  # ProxyPose: [m], quaternion w x y z
DEVICE_HAPTICS = np.dtype([("force", "<f4", (3,)), ("torque", "<f4", (3,)), ("stiffness", "<f4", (9,)),
                           ("contacts", "<u4")])  # [N], [N m], [N/m] row-major
PROXY_HAPTICS = np.dtype([("force", "<f4", (3,)), ("torque", "<f4", (3,)), ("pose", POSE), ("stiffness", "<f4", (9,)),
                          ("contacts", "<u4")])
VEC3F = np.dtype(("<f4", (3,)))
for _dtype, _struct in ((POSE, ProxyPose), (DEVICE_HAPTICS, DeviceHaptics), (PROXY_HAPTICS, ProxyHaptics),
                        (VEC3F, Vec3f)):
    assert _dtype.itemsize == _struct.SizeOf(), f"{_struct.__name__}: the generated code has another layout"

_READ_ERRORS = (struct.error, IndexError, ValueError, TypeError, OverflowError)  # of a damaged message


class CompareError(ValueError):
    """Two recordings that cannot be compared; the message says why."""


# ---- one recording's frames of its first scene -----------------------------------------------------------

@dataclass
class Frames:
    """What compare needs of one recording: the frames of its first scene, their arrays in file order."""

    path: str
    metadata: dict[str, str]         # the `tactile` metadata record
    scene: SceneDescriptionT | None  # the first SceneDescription of the compared scene_id
    scene_id: int | None             # the compared scene (the first SceneDescription's, else the first frame's)
    scene_ids: list[int]             # every scene_id of the file, in order of appearance
    devices: list[str]               # device channel names (n_devices)
    proxies: list[str]               # proxy names (n_proxies)
    haptic_t: np.ndarray             # sim_time [s] (n_haptic)
    haptic_devices: np.ndarray       # DEVICE_HAPTICS records (n_haptic x n_devices)
    haptic_proxies: np.ndarray       # PROXY_HAPTICS records (n_haptic x n_proxies)
    state_t: np.ndarray              # sim_time [s] (n_state)
    state_ordinal: np.ndarray        # each state's index among the file's /state messages (n_state)
    state_vertices: np.ndarray       # vertex count (n_state)
    state_proxies: np.ndarray        # POSE records (n_state x n_proxies)
    state_contact: np.ndarray        # contact force on each proxy [N] (n_state x n_proxies x 3), NaN: absent
    u_at_proxy: np.ndarray           # u of the vertex nearest each proxy [m] (n_state x n_proxies x 3), NaN: unknown
    notes: list[str]

    @property
    def name(self) -> str:
        return pathlib.Path(self.path).name

    @property
    def scene_name(self) -> str:
        return (self.scene.sceneName if self.scene is not None and self.scene.sceneName else "") \
            or self.metadata.get("scene_name", "") or "?"

    @property
    def dt_s(self) -> float | None:
        """The scene's step [s]; without a scene, the median interval of its haptic frames (one per step)."""
        if self.scene is not None and self.scene.dt > 0:
            return float(self.scene.dt)
        steps = np.diff(self.haptic_t)
        return float(np.median(steps)) if len(steps) and np.median(steps) > 0 else None

    @property
    def rest_positions(self) -> np.ndarray | None:
        """X [m] (n_vertices x 3), None without a scene."""
        return _rest_positions(self.scene)

    @property
    def n_vertices(self) -> int | None:
        """The surface's vertex count: the scene's, else the first state's."""
        X = self.rest_positions
        if X is not None and len(X):
            return len(X)
        return int(self.state_vertices[0]) if len(self.state_vertices) else None


def _message(data: bytes, kind: int) -> Any:
    """The table of one Envelope through the generated accessors (no object API), None when it holds
    another message type; raises ProtocolError when the bytes are no Envelope."""
    if len(data) < 8 or data[4:8] != FILE_IDENTIFIER:
        raise ProtocolError("not an Envelope (short, or another file identifier)")
    envelope = Envelope.GetRootAs(data, 0)
    if envelope.MessageType() != kind:
        return None
    table = envelope.Message()
    frame = HapticFrame() if kind == Message.HapticFrame else StateFrame()
    frame.Init(table.Bytes, table.Pos)
    return frame


def _structs(data: bytes, first: Any, n: int, dtype: np.dtype) -> bytes:
    """The raw bytes of a vector of n structs whose first element is `first` (a generated struct accessor)."""
    if n == 0:
        return b""
    start = first._tab.Pos
    if start < 0 or start + n * dtype.itemsize > len(data):
        raise ProtocolError(f"a vector of {n} structs runs past the {len(data)}-byte message")
    return data[start:start + n * dtype.itemsize]


class _Reader:
    """Pass 1 over one recording: the first scene's frames into numpy arrays."""

    def __init__(self, recording: Recording) -> None:
        self.recording = recording
        self.scene: SceneDescriptionT | None = None
        self.scene_id: int | None = None
        self.scene_ids: list[int] = []
        self.devices: list[str] = []
        self.proxies: list[str] = []
        self.haptic_t: list[float] = []
        self.haptic_devices: list[bytes] = []
        self.haptic_proxies: list[bytes] = []
        self.haptic_shape: tuple[int, int] | None = None
        self.state_t: list[float] = []
        self.state_ordinal: list[int] = []
        self.state_vertices: list[int] = []
        self.state_proxies: list[bytes] = []
        self.state_contact: list[bytes] = []
        self.u_at_proxy: list[np.ndarray] = []
        self.n_state_proxies: int | None = None
        self.skipped: dict[str, int] = {}  # why -> frames
        self.redescribed = 0  # SceneDescriptions of the compared scene after its first

    def skip(self, why: str) -> None:
        self.skipped[why] = self.skipped.get(why, 0) + 1

    def is_compared(self, scene_id: int) -> bool:
        """Whether a frame of scene_id is compared; the first frame seen before any scene picks its scene."""
        if scene_id not in self.scene_ids:
            self.scene_ids.append(scene_id)
        if self.scene_id is None:
            self.scene_id = scene_id
        return scene_id == self.scene_id

    def read(self) -> Frames:
        state_ordinal = -1
        for topic, _, _, data in self.recording.messages(["/scene", "/state", "/haptic"]):
            if topic == "/state":
                state_ordinal += 1
            try:
                if topic == "/scene":
                    self.add_scene(data)
                elif topic == "/haptic":
                    self.add_haptic(data)
                else:
                    self.add_state(data, state_ordinal)
            except (ProtocolError, *_READ_ERRORS):
                self.skip(f"{topic} messages that do not read as an Envelope of their topic's type")
        return self.finish()

    def add_scene(self, data: bytes) -> None:
        scene = decode(data).message
        if not isinstance(scene, SceneDescriptionT):
            raise ProtocolError("not a SceneDescription")
        if self.scene is None and (self.scene_id is None or self.scene_id == scene.sceneId):
            self.scene = scene
            self.devices = list(scene.devices or [])
            self.proxies = [p.name or "" for p in scene.proxies or []]
        elif self.scene is not None and scene.sceneId == self.scene_id:
            self.redescribed += 1  # a parameter change: the body goes on in the same timeline
        self.is_compared(scene.sceneId)

    def add_haptic(self, data: bytes) -> None:
        frame = _message(data, Message.HapticFrame)
        if frame is None:
            raise ProtocolError("not a HapticFrame")
        if not self.is_compared(frame.SceneId()):
            return
        t = frame.SimTime()
        if self.haptic_t and not t > self.haptic_t[-1]:
            self.skip("/haptic frames whose sim_time does not follow the one before")
            return
        shape = (frame.DevicesLength(), frame.ProxiesLength())
        if self.haptic_shape is None:
            self.haptic_shape = shape
        elif shape != self.haptic_shape:
            self.skip(f"/haptic frames with other device or proxy counts than the first's {self.haptic_shape}")
            return
        self.haptic_devices.append(_structs(data, frame.Devices(0), shape[0], DEVICE_HAPTICS))
        self.haptic_proxies.append(_structs(data, frame.Proxies(0), shape[1], PROXY_HAPTICS))
        self.haptic_t.append(t)

    def add_state(self, data: bytes, ordinal: int) -> None:
        frame = _message(data, Message.StateFrame)
        if frame is None:
            raise ProtocolError("not a StateFrame")
        if not self.is_compared(frame.SceneId()):
            return
        t = frame.SimTime()
        if self.state_t and not t > self.state_t[-1]:
            self.skip("/state frames whose sim_time does not follow the one before")
            return
        n_proxies = frame.ProxiesLength()
        if self.n_state_proxies is None:
            self.n_state_proxies = n_proxies
        elif n_proxies != self.n_state_proxies or frame.ContactForcesLength() not in (0, n_proxies):
            self.skip(f"/state frames with other proxy counts than the first's ({self.n_state_proxies})")
            return
        poses = np.frombuffer(_structs(data, frame.Proxies(0), n_proxies, POSE), POSE)
        n_contact = frame.ContactForcesLength()
        contact = _structs(data, frame.ContactForces(0), n_contact, VEC3F) if n_contact else \
            np.full((n_proxies, 3), np.nan, np.float32).tobytes()
        x = _positions(frame)
        self.state_proxies.append(poses.tobytes())
        self.state_contact.append(contact)
        self.u_at_proxy.append(compute_u_at_proxies(x, _rest_positions(self.scene), poses["position"]))
        self.state_vertices.append(len(x))
        self.state_t.append(t)
        self.state_ordinal.append(ordinal)

    def finish(self) -> Frames:
        n_h, (n_dev, n_prx) = len(self.haptic_t), self.haptic_shape or (0, 0)
        n_s, n_sp = len(self.state_t), self.n_state_proxies or 0
        # Names from the scene when it has as many as the frames, else by index (as export.py names them).
        devices = self.devices if len(self.devices) == n_dev else [f"device{i}" for i in range(n_dev)]
        proxies = self.proxies if len(self.proxies) == max(n_prx, n_sp) else \
            [f"proxy{i}" for i in range(max(n_prx, n_sp))]
        notes = []
        if len(self.scene_ids) > 1:
            notes.append(f"it holds {len(self.scene_ids)} scenes (scene_id {', '.join(map(str, self.scene_ids))}): "
                         f"the first, {self.scene_id}, is compared")
        if self.scene is None:
            notes.append("no SceneDescription of its compared scene was read: no device or proxy names, no rest "
                         "positions (no displacement at the proxies)")
        if self.redescribed:
            notes.append(f"{self.redescribed} later SceneDescriptions of scene_id {self.scene_id} (a parameter "
                         "changed, the timeline went on): compared all the same; the first names the devices, "
                         "proxies, step and rest positions")
        notes += [f"{n} {why}: skipped" for why, n in self.skipped.items()]
        return Frames(
            self.recording.path, self.recording.metadata, self.scene, self.scene_id, self.scene_ids,
            [name or f"device{i}" for i, name in enumerate(devices)],
            [name or f"proxy{i}" for i, name in enumerate(proxies)],
            np.asarray(self.haptic_t, np.float64),
            np.frombuffer(b"".join(self.haptic_devices), DEVICE_HAPTICS).reshape(n_h, n_dev),
            np.frombuffer(b"".join(self.haptic_proxies), PROXY_HAPTICS).reshape(n_h, n_prx),
            np.asarray(self.state_t, np.float64),
            np.asarray(self.state_ordinal, np.int64),
            np.asarray(self.state_vertices, np.int64),
            np.frombuffer(b"".join(self.state_proxies), POSE).reshape(n_s, n_sp),
            np.frombuffer(b"".join(self.state_contact), np.float32).reshape(n_s, n_sp, 3),
            np.asarray(self.u_at_proxy, np.float64).reshape(n_s, n_sp, 3),
            notes)


def _rest_positions(scene: SceneDescriptionT | None) -> np.ndarray | None:
    """X [m] (n_vertices x 3), None without a scene."""
    if scene is None or scene.restPositions is None:
        return None
    return np.asarray(scene.restPositions, np.float32).reshape(-1, 3)


def _positions(frame: StateFrame) -> np.ndarray:
    """x [m] (n_vertices x 3), a view into the message's bytes (empty when absent)."""
    x = frame.PositionsAsNumpy()
    if isinstance(x, int) or len(x) % 3:
        return np.zeros((0, 3), np.float32)
    return x.reshape(-1, 3)


def _scalar(frame: StateFrame) -> np.ndarray:
    s = frame.ScalarAsNumpy()
    return np.zeros(0, np.float32) if isinstance(s, int) else s


def compute_u_at_proxies(x: np.ndarray, X: np.ndarray | None, p: np.ndarray) -> np.ndarray:
    """u [m] (n_proxies x 3) at each proxy: x - X of the surface vertex nearest the proxy's position p
    (n_proxies x 3) in x (n_vertices x 3); NaN when x has no vertices or X does not match it."""
    u = np.full((len(p), 3), np.nan)
    if X is None or len(x) == 0 or x.shape != X.shape:
        return u
    for j, p_j in enumerate(p.astype(np.float64)):
        v = int(np.argmin(np.sum((x - p_j) ** 2, axis=1)))
        u[j] = x[v].astype(np.float64) - X[v]
    return u


def read_frames(recording: Recording) -> Frames:
    """The frames of `recording`'s first scene (what a read could not decode is counted in its notes)."""
    return _Reader(recording).read()


def _surfaces(recording: Recording, ordinals: np.ndarray) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """Pass 2: (ordinal, positions (n_vertices x 3), scalar) of the /state messages at `ordinals`
    (increasing, as pass 1 numbered the /state messages), in order."""
    wanted = iter(ordinals.tolist())
    next_ordinal = next(wanted, None)
    for ordinal, (_, _, _, data) in enumerate(recording.messages(["/state"])):
        if next_ordinal is None:
            return
        if ordinal == next_ordinal:
            frame = _message(data, Message.StateFrame)
            yield ordinal, _positions(frame), _scalar(frame)
            next_ordinal = next(wanted, None)


# ---- the comparison ----------------------------------------------------------------------------------------

def pair_nearest(t_a: np.ndarray, t_b: np.ndarray, tolerance: float) -> np.ndarray:
    """For each time of t_a, the index of t_b's nearest time (t_b increasing), or -1 when none lies
    within `tolerance` (|t_b - t_a| <= tolerance; a tie goes to the earlier)."""
    if len(t_b) == 0:
        return np.full(len(t_a), -1, np.int64)
    i = np.searchsorted(t_b, t_a)
    lo, hi = np.clip(i - 1, 0, len(t_b) - 1), np.clip(i, 0, len(t_b) - 1)
    nearest = np.where(np.abs(t_b[hi] - t_a) < np.abs(t_b[lo] - t_a), hi, lo)
    return np.where(np.abs(t_b[nearest] - t_a) <= tolerance, nearest, -1).astype(np.int64)


def compute_norm(v: np.ndarray) -> np.ndarray:
    """|v| over the last axis, in float64."""
    v = np.asarray(v, np.float64)
    return np.sqrt(np.sum(v * v, axis=-1))


def compute_rotation_angle(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """The angle [rad] of the rotation between unit quaternions (... x 4, w x y z): 4 atan2(|q_a - s q_b|,
    |q_a + s q_b|), s the sign of their dot product (the halves of the chord are sin and cos of a quarter
    of the angle); exactly 0 for equal quaternions, which 2 acos(q_a . q_b) is not for float32 ones."""
    q_a, q_b = np.asarray(q_a, np.float64), np.asarray(q_b, np.float64)
    s = np.where(np.sum(q_a * q_b, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    return 4 * np.arctan2(compute_norm(q_a - s * q_b), compute_norm(q_a + s * q_b))


def _same_bits(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per row (first axis): whether a and b hold the same bytes; a and b of one shape and dtype."""
    n = len(a)
    a_bytes = np.ascontiguousarray(a).view(np.uint8).reshape(n, -1)
    b_bytes = np.ascontiguousarray(b).view(np.uint8).reshape(n, -1)
    return np.all(a_bytes == b_bytes, axis=1)


def _match(names_a: list[str], names_b: list[str]) -> tuple[list[tuple[str, int, int]], list[str]]:
    """(name, index in A, index in B) of the names both have, in A's order; and those only one has."""
    matched = [(name, i, names_b.index(name)) for i, name in enumerate(names_a) if name in names_b]
    only = [f"{name} (A only)" for name in names_a if name not in names_b] + \
           [f"{name} (B only)" for name in names_b if name not in names_a]
    return matched, only


@dataclass
class Comparison:
    a: Frames
    b: Frames
    tolerance_s: float
    mode: str                            # "vertices": x compared vertex by vertex; "proxies": u at the proxies
    devices: list[tuple[str, int, int]]  # (name, index in A, index in B) of the channels both have
    proxies: list[tuple[str, int, int]]  # (name, index in A's haptic frames, in B's) likewise
    state_proxies: list[tuple[str, int, int]]  # likewise, in the state frames' proxy poses
    haptic_pairs: np.ndarray             # for each of A's haptic frames, B's index or -1 (n_haptic_A)
    state_pairs: np.ndarray              # likewise for the states (n_state_A)
    haptic_same: np.ndarray              # per paired haptic frame: bit for bit equal (n_haptic_pairs)
    state_same: np.ndarray               # per paired state (n_state_pairs)
    dx_max: np.ndarray                   # [m] per paired state, NaN where the counts differ (n_state_pairs)
    dx_rms: np.ndarray                   # [m] likewise
    notes: list[str] = field(default_factory=list)

    @property
    def identical(self) -> bool:
        """Every frame of each file paired, one to one, and bit for bit equal."""
        return (len(self.a.haptic_t) == len(self.b.haptic_t) == len(self.haptic_same)
                and len(self.a.state_t) == len(self.b.state_t) == len(self.state_same)
                and bool(np.all(self.haptic_same)) and bool(np.all(self.state_same))
                and len(np.unique(self.haptic_pairs[self.haptic_pairs >= 0])) == len(self.haptic_same)
                and len(np.unique(self.state_pairs[self.state_pairs >= 0])) == len(self.state_same))


def _span(t: np.ndarray) -> str:
    return f"{t[0]:.6g} to {t[-1]:.6g} s" if len(t) else "none"


def compare(recording_a: Recording, recording_b: Recording, tolerance_s: float | None = None) -> Comparison:
    """Pairs and compares the frames of the first scene of each recording (the module's docstring says
    what), reading each twice. Raises CompareError when no frame pairs, or no step is known to pair them by."""
    a, b = read_frames(recording_a), read_frames(recording_b)
    for f, which in ((a, "A"), (b, "B")):
        if not len(f.haptic_t) and not len(f.state_t):
            raise CompareError(f"{which} ({f.path}) holds no state or haptic frame that reads")
    if tolerance_s is None:
        steps = [dt for dt in (a.dt_s, b.dt_s) if dt is not None]
        if not steps:
            raise CompareError("neither recording says its step (no SceneDescription, under two haptic frames): "
                               "give the pairing tolerance")
        tolerance_s = max(steps) / 2
    haptic_pairs = pair_nearest(a.haptic_t, b.haptic_t, tolerance_s)
    state_pairs = pair_nearest(a.state_t, b.state_t, tolerance_s)
    if not np.any(haptic_pairs >= 0) and not np.any(state_pairs >= 0):
        raise CompareError(f"no common time span: no frame of A pairs with one of B within {tolerance_s:.6g} s of "
                           f"sim time (A: haptic frames {_span(a.haptic_t)}, states {_span(a.state_t)}; B: haptic "
                           f"frames {_span(b.haptic_t)}, states {_span(b.state_t)})")
    devices, devices_only = _match(a.devices[:a.haptic_devices.shape[1]], b.devices[:b.haptic_devices.shape[1]])
    proxies, proxies_only = _match(a.proxies[:a.haptic_proxies.shape[1]], b.proxies[:b.haptic_proxies.shape[1]])
    state_proxies, _ = _match(a.proxies[:a.state_proxies.shape[1]], b.proxies[:b.state_proxies.shape[1]])
    notes = []
    if devices_only:
        notes.append(f"device channels in one file only, not compared: {', '.join(devices_only)}")
    if proxies_only:
        notes.append(f"proxies in one file only, not compared: {', '.join(proxies_only)}")

    ia, ib = np.flatnonzero(haptic_pairs >= 0), haptic_pairs[haptic_pairs >= 0]
    haptic_same = a.haptic_t[ia] == b.haptic_t[ib]
    if a.haptic_devices.shape[1] == b.haptic_devices.shape[1] and a.devices == b.devices:
        haptic_same &= _same_bits(a.haptic_devices[ia], b.haptic_devices[ib])
    else:
        haptic_same[:] = False
    if a.haptic_proxies.shape[1] == b.haptic_proxies.shape[1] and a.proxies == b.proxies:
        haptic_same &= _same_bits(a.haptic_proxies[ia], b.haptic_proxies[ib])
    else:
        haptic_same[:] = False

    n_a, n_b = a.n_vertices, b.n_vertices
    mode = "vertices" if n_a is not None and n_a == n_b else "proxies"
    if mode == "vertices":
        X_a, X_b = a.rest_positions, b.rest_positions
        if X_a is not None and X_b is not None and not np.array_equal(X_a, X_b):
            notes.append(f"the surfaces have {n_a} vertices each but other rest positions: compared vertex by "
                         "vertex all the same")
    else:
        notes.append(f"the surfaces differ ({n_a} vertices in A, {n_b} in B): compared at the proxies instead "
                     "(pose, force, and the displacement of the surface vertex nearest each proxy)")
    sa, sb = np.flatnonzero(state_pairs >= 0), state_pairs[state_pairs >= 0]
    state_same = (a.state_t[sa] == b.state_t[sb]) & (a.state_vertices[sa] == b.state_vertices[sb])
    if a.state_proxies.shape[1] == b.state_proxies.shape[1]:
        state_same &= _same_bits(a.state_proxies[sa], b.state_proxies[sb])
        state_same &= _same_bits(a.state_contact[sa], b.state_contact[sb])
    else:
        state_same[:] = False
    dx_max, dx_rms = np.full(len(sa), np.nan), np.full(len(sa), np.nan)
    # Pass 2: the positions of both files, pair by pair (sb is non-decreasing since both times increase).
    surfaces_a = _surfaces(recording_a, a.state_ordinal[sa])
    surfaces_b = _surfaces(recording_b, np.unique(b.state_ordinal[sb]))
    ordinal_b, x_b, scalar_b = -1, np.zeros((0, 3), np.float32), np.zeros(0, np.float32)
    uncounted = 0  # pairs of states whose surfaces cannot be set vertex by vertex
    for k, (_, x_a, scalar_a) in enumerate(surfaces_a):
        while ordinal_b != b.state_ordinal[sb[k]]:
            ordinal_b, x_b, scalar_b = next(surfaces_b, (-2, x_b, scalar_b))
            if ordinal_b == -2:
                raise CompareError(f"B ({b.path}) holds fewer states on a second read: did it change?")
        state_same[k] &= bool(np.array_equal(x_a.view(np.uint32), x_b.view(np.uint32))
                              and np.array_equal(scalar_a.view(np.uint32), scalar_b.view(np.uint32)))
        if mode == "vertices" and x_a.shape == x_b.shape and len(x_a):
            d = compute_norm(x_a.astype(np.float64) - x_b)
            dx_max[k], dx_rms[k] = d.max(), math.sqrt(float(np.mean(d * d)))
        elif mode == "vertices":
            uncounted += 1
    if uncounted:
        notes.append(f"{uncounted} paired states whose vertex counts differ (or hold no positions): no surface "
                     "difference there")
    return Comparison(a, b, tolerance_s, mode, devices, proxies, state_proxies, haptic_pairs, state_pairs,
                      haptic_same, state_same, dx_max, dx_rms, notes)


# ---- the table, the plot, the summary -----------------------------------------------------------------------

@dataclass
class _Series:
    """The differences over time, per paired frame (what the CSV, the plot and the summary show)."""

    haptic_t: np.ndarray                                  # A's sim_time [s] (n_haptic_pairs)
    haptic_t_b: np.ndarray
    device_force: dict[str, tuple[np.ndarray, np.ndarray]]  # name -> F_A, F_B [N] (n_haptic_pairs x 3)
    proxy_force: dict[str, tuple[np.ndarray, np.ndarray]]
    device_dF: dict[str, np.ndarray]                      # name -> |F_A - F_B| [N] (n_haptic_pairs)
    proxy_dF: dict[str, np.ndarray]
    proxy_dposition: dict[str, np.ndarray]               # [m] (n_haptic_pairs)
    proxy_drotation: dict[str, np.ndarray]               # [rad]
    state_t: np.ndarray                                   # (n_state_pairs)
    state_t_b: np.ndarray
    u: dict[str, tuple[np.ndarray, np.ndarray]]           # name -> u_A, u_B at the proxy [m] (n_state_pairs x 3)
    du: dict[str, np.ndarray]                             # name -> |u_A - u_B| [m] (n_state_pairs), NaN: unknown


def _series(c: Comparison) -> _Series:
    ia, ib = np.flatnonzero(c.haptic_pairs >= 0), c.haptic_pairs[c.haptic_pairs >= 0]
    sa, sb = np.flatnonzero(c.state_pairs >= 0), c.state_pairs[c.state_pairs >= 0]
    da, db = c.a.haptic_devices, c.b.haptic_devices
    pa, pb = c.a.haptic_proxies, c.b.haptic_proxies
    device_force = {name: (da[ia, i]["force"], db[ib, j]["force"]) for name, i, j in c.devices}
    proxy_force = {name: (pa[ia, i]["force"], pb[ib, j]["force"]) for name, i, j in c.proxies}
    u = {name: (c.a.u_at_proxy[sa, i], c.b.u_at_proxy[sb, j]) for name, i, j in c.state_proxies}
    return _Series(
        c.a.haptic_t[ia], c.b.haptic_t[ib], device_force, proxy_force,
        {name: compute_norm(f_a.astype(np.float64) - f_b) for name, (f_a, f_b) in device_force.items()},
        {name: compute_norm(f_a.astype(np.float64) - f_b) for name, (f_a, f_b) in proxy_force.items()},
        {name: compute_norm(pa[ia, i]["pose"]["position"].astype(np.float64) - pb[ib, j]["pose"]["position"])
         for name, i, j in c.proxies},
        {name: compute_rotation_angle(pa[ia, i]["pose"]["orientation"], pb[ib, j]["pose"]["orientation"])
         for name, i, j in c.proxies},
        c.a.state_t[sa], c.b.state_t[sb], u, {name: compute_norm(u_a - u_b) for name, (u_a, u_b) in u.items()})


def write_csv(c: Comparison, path: str | pathlib.Path) -> int:
    """compare.csv (the module's docstring gives its columns); returns the rows written."""
    s = _series(c)
    xyz = ("fx_N", "fy_N", "fz_N")
    haptic_cols = ["haptic.sim_time_B_s"]
    for kind, forces in (("device", s.device_force), ("proxy", s.proxy_force)):
        for name in forces:
            haptic_cols += [f"A.{kind}.{name}.{a}" for a in xyz] + [f"B.{kind}.{name}.{a}" for a in xyz]
            haptic_cols.append(f"{kind}.{name}.dF_N")
            if kind == "proxy":
                haptic_cols += [f"proxy.{name}.dposition_m", f"proxy.{name}.drotation_rad"]
    state_cols = ["state.sim_time_B_s"]
    if c.mode == "vertices":
        state_cols += ["surface.dx_max_m", "surface.dx_rms_m"]
    else:
        for name in s.u:
            state_cols += [f"A.proxy.{name}.u_m", f"B.proxy.{name}.u_m", f"proxy.{name}.du_m"]

    haptic_rows: dict[float, list[str]] = {}
    for k, t in enumerate(s.haptic_t.tolist()):
        row = [_f64(s.haptic_t_b[k])]
        for kind, forces in (("device", s.device_force), ("proxy", s.proxy_force)):
            for name, (f_a, f_b) in forces.items():
                row += [_f32(v) for v in f_a[k]] + [_f32(v) for v in f_b[k]]
                row.append(_f64((s.device_dF if kind == "device" else s.proxy_dF)[name][k]))
                if kind == "proxy":
                    row += [_f64(s.proxy_dposition[name][k]), _f64(s.proxy_drotation[name][k])]
        haptic_rows[t] = row
    state_rows: dict[float, list[str]] = {}
    for k, t in enumerate(s.state_t.tolist()):
        row = [_f64(s.state_t_b[k])]
        if c.mode == "vertices":
            row += [_number(c.dx_max[k]), _number(c.dx_rms[k])]
        else:
            for name, (u_a, u_b) in s.u.items():
                row += [_number(float(compute_norm(u_a[k]))), _number(float(compute_norm(u_b[k]))),
                        _number(s.du[name][k])]
        state_rows[t] = row
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(["sim_time_s", *haptic_cols, *state_cols])
        times = sorted(set(haptic_rows) | set(state_rows))
        for t in times:
            writer.writerow([_f64(t), *haptic_rows.get(t, [""] * len(haptic_cols)),
                             *state_rows.get(t, [""] * len(state_cols))])
    return len(times)


def _number(x: float) -> str:
    return "" if math.isnan(x) else _f64(x)


def _describe(f: Frames) -> str:
    """What a file's compared scene is, in one line."""
    dt = f.dt_s
    parts = [f"scene {f.scene_name} (scene_id {f.scene_id})", f"{f.n_vertices} vertices" if f.n_vertices else None,
             f"dt {dt * 1e6:.4g} \u00b5s" if dt else None, f"material {_material(f)}" if _material(f) else None]
    return ", ".join(p for p in parts if p)


def _material(f: Frames) -> str:
    """E and nu of the scene's material, with their units, when its parameters name them ("material.E"...)."""
    found = {p.name: p for p in (f.scene.parameters or [] if f.scene is not None else []) if p.name}
    units = {k: f" {p.unit}" if p.unit not in (None, "", "-") else "" for k, p in found.items()}
    return ", ".join(f"{k.split('.', 1)[1]} {found[k].value:.4g}{units[k]}" for k in ("material.E", "material.nu")
                     if k in found)


def plot_available() -> bool:
    try:
        importlib.import_module("matplotlib")
    except ImportError:
        return False
    return True


def plot(c: Comparison, path: str | pathlib.Path) -> None:
    """compare.png: |F| per device channel of A and B, |F_A - F_B|, and the surface or proxy displacement
    differences, on one sim-time axis. Raises RuntimeError when matplotlib is not installed."""
    try:
        figure_module = importlib.import_module("matplotlib.figure")
    except ImportError as e:
        raise RuntimeError("compare.png needs matplotlib (pip install 'tactile-proto[plot]', or "
                           "matplotlib==3.10.3 as tests/requirements.txt pins it)") from e
    s = _series(c)
    fig = figure_module.Figure(figsize=(11, 8.5), dpi=110, layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    colors = [f"C{i}" for i in range(10)]
    legend = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "fontsize": "small", "frameon": False}
    ms = 1e3  # plotted in mm

    ax = axes[0]
    for k, (name, (f_a, f_b)) in enumerate(s.device_force.items()):
        color = colors[k % len(colors)]
        ax.plot(s.haptic_t, compute_norm(f_a), color=color, lw=1.2, label=f"{name}: A")
        ax.plot(s.haptic_t, compute_norm(f_b), color=color, lw=1.2, ls="--", label=f"{name}: B")
    ax.set_ylabel("force |F| [N]")
    ax.set_title("force of each device channel, A solid, B dashed", fontsize="medium", loc="left")

    ax = axes[1]
    for k, (name, dF) in enumerate(s.device_dF.items()):
        ax.plot(s.haptic_t, dF, color=colors[k % len(colors)], lw=1.2, label=name)
    ax.set_ylabel("|F_A \u2212 F_B| [N]")
    ax.set_title("force difference of each device channel", fontsize="medium", loc="left")

    ax = axes[2]
    if c.mode == "vertices":
        ax.plot(s.state_t, c.dx_max * ms, color="C3", marker=".", lw=1.2, label="max over vertices")
        ax.plot(s.state_t, c.dx_rms * ms, color="C0", marker=".", lw=1.2, label="RMS over vertices")
        ax.set_ylabel("|x_A \u2212 x_B| [mm]")
        ax.set_title(f"surface position difference, vertex by vertex ({c.a.n_vertices} vertices)",
                     fontsize="medium", loc="left")
    else:
        for k, (name, du) in enumerate(s.du.items()):
            ax.plot(s.state_t, du * ms, color=colors[k % len(colors)], marker=".", lw=1.2,
                    label=name)
        ax.set_ylabel("|u_A \u2212 u_B| [mm]")
        ax.set_title(f"displacement at each proxy (nearest surface vertex; {c.a.n_vertices} vs {c.b.n_vertices} "
                     "vertices)", fontsize="medium", loc="left")
    ax.set_xlabel("sim time [s]")
    empty = ["no haptic frames paired" if not len(s.haptic_t) else "no device channel in both files"] * 2
    empty.append("no states paired" if not len(s.state_t) else "no proxy in both files")
    for k, ax in enumerate(axes):
        values = np.concatenate([np.zeros(0)] + [np.asarray(line.get_ydata(), np.float64) for line in ax.lines])
        known = values[~np.isnan(values)]
        if not len(values):
            ax.text(0.5, 0.5, empty[k], transform=ax.transAxes, ha="center", va="center")
        else:
            ax.legend(**legend)
            if not len(known):
                ax.text(0.5, 0.5, "not known (no rest positions, or other vertex counts)", transform=ax.transAxes,
                        ha="center", va="center")
            elif np.all(known == 0):
                ax.text(0.5, 0.5, "zero throughout" if k else "no force in either file", transform=ax.transAxes,
                        ha="center", va="center")
        ax.grid(True, alpha=0.3)
        ax.set_ylim(bottom=0)
    verdict = ("identical bit for bit" if c.identical else
               f"paired within \u00b1{c.tolerance_s * 1e6:.3g} \u00b5s of sim time: {len(c.haptic_same)} of A's "
               f"{len(c.a.haptic_t)} haptic frames, {len(c.state_same)} of its {len(c.a.state_t)} states")
    fig.suptitle(f"A: {c.a.name}: {_describe(c.a)}\nB: {c.b.name}: {_describe(c.b)}\n{verdict}", fontsize="medium")
    fig.savefig(path)


def summarize(c: Comparison) -> str:
    """The summary `compare` prints: the files, what was paired and compared, and either that they are
    identical or their largest differences with their times."""
    lines = [f"A: {c.a.path}: {_describe(c.a)}", f"B: {c.b.path}: {_describe(c.b)}"]
    lines.append(f"paired by sim_time within {c.tolerance_s:.6g} s: {len(c.haptic_same)} of {len(c.a.haptic_t)} "
                 f"haptic frames of A (B has {len(c.b.haptic_t)}), {len(c.state_same)} of {len(c.a.state_t)} "
                 f"state frames of A (B has {len(c.b.state_t)})")
    names = ", ".join(n for n, _, _ in c.devices) or "none"
    proxies = ", ".join(n for n, _, _ in c.proxies) or "none"
    lines.append(f"compared: forces of device channels {names}; force and pose of proxies {proxies}; "
                 + ("the surface vertex by vertex" if c.mode == "vertices" else
                    "the displacement of the surface vertex nearest each proxy (the meshes differ)"))
    if c.identical:
        lines.append(f"identical: {len(c.state_same)} of {len(c.a.state_t)} state frames and {len(c.haptic_same)} "
                     f"of {len(c.a.haptic_t)} haptic frames bit for bit")
        return "\n".join(lines)
    lines.append(f"bit for bit equal: {int(np.sum(c.state_same))} of {len(c.state_same)} paired state frames, "
                 f"{int(np.sum(c.haptic_same))} of {len(c.haptic_same)} paired haptic frames")
    s = _series(c)
    lines.append("largest differences:")

    def largest(what: str, t: np.ndarray, values: np.ndarray, unit: str) -> None:
        if len(values) == 0 or np.all(np.isnan(values)):
            return
        k = int(np.nanargmax(values))
        lines.append(f"  {what:<30} " + (f"{values[k]:.4g} {unit} at sim time {t[k]:.6g} s" if values[k]
                                          else "0 throughout"))

    for name, dF in s.device_dF.items():
        largest(f"device {name} |F_A - F_B|", s.haptic_t, dF, "N")
    for name, dF in s.proxy_dF.items():
        largest(f"proxy {name} |F_A - F_B|", s.haptic_t, dF, "N")
        largest(f"proxy {name} |p_A - p_B|", s.haptic_t, s.proxy_dposition[name], "m")
        largest(f"proxy {name} rotation", s.haptic_t, s.proxy_drotation[name], "rad")
    if c.mode == "vertices":
        largest("surface max |x_A - x_B|", s.state_t, c.dx_max, "m")
        largest("surface RMS |x_A - x_B|", s.state_t, c.dx_rms, "m")
    else:
        for name, du in s.du.items():
            largest(f"proxy {name} |u_A - u_B|", s.state_t, du, "m")
    return "\n".join(lines)


__all__ = ["DEVICE_HAPTICS", "POSE", "PROXY_HAPTICS", "CompareError", "Comparison", "Frames", "compare",
           "compute_norm", "compute_rotation_angle", "compute_u_at_proxies", "pair_nearest", "plot",
           "plot_available", "read_frames", "summarize", "write_csv"]
