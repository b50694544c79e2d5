"""A recording (proto/RECORDING.md) as files other tools read: CSV tables and a VTU series of the surface.

    export(open_recording(path), out_dir, tables=True, surface=True) -> Export (files written, notes)

CSV, one row per message, in file order; floats as the shortest text that reads back as the same value
(float32 fields as float32):
  forces.csv     /haptic, long (one row per proxy per frame, as the headless simulator's forces.csv has it):
                 log_time_ns, sim_time_s, step, scene_id, proxy, device, fx_N, fy_N, fz_N, tx_Nm, ty_Nm, tz_Nm
                 (about the proxy's position), contacts, px_m, py_m, pz_m (the proxy's position); names from
                 the SceneDescription of the frame's scene_id (else the latest one). A frame whose counts differ
                 from its scene's names gets `proxy<i>` (and an empty device), and a note says so.
  devices.csv    /haptic, long: log_time_ns, sim_time_s, step, scene_id, device, fx_N .. tz_Nm (about the
                 channel's reference point), contacts: one row per device channel per frame (`device<i>`
                 when unnamed).
  energies.csv   /state: log_time_ns, sim_time_s, step, scene_id and each field of StateFrame.energies [J]
                 (`kinetic_J`, ...: the fields the generated code has), then balance_drift_J, their sum as the
                 protocol defines it (kinetic + discrete - restated + elastic + gravity - work_loads -
                 work_essential - work_contact + dissipated). Frames without energies (a server before
                 protocol 1.4) leave those columns empty, and a note counts them.
  telemetry.csv  /telemetry: log_time_ns and every scalar and string field of Telemetry (sim_time as
                 sim_time_s), then fault_count (0 without one) and faults (`; `-joined, empty without one).
  effect_costs.csv  /telemetry, long: log_time_ns, sim_time_s, effect, ns_per_step: one row per effect per
                 message (what each effect of the simulation cost a step, Telemetry.effect_costs).
  inputs.csv     /input: log_time_ns, device, sequence, device_time_ns, position [m], orientation, buttons.
VTU: one series per scene_id (a load or a reset starts a new one, since sim_time restarts and the mesh may
differ): `surface-<scene_id>/<index>.vtu` per StateFrame (points: the rest positions, as the headless
series has them; cells: the scene's triangles; point data: `displacement`, positions minus rest positions
[m], the active vector that ParaView's Warp By Vector deforms the surface by, and the scalar under
SceneDescription.scalar_name, and each per-vertex field the frame carries (1.8: `von_mises`, ... under their
own names)) and `surface-<scene_id>.pvd`, the collection ParaView opens, with sim_time as the timestep. A
scene with an embedded surface (1.7) also gets its fine surface, placed by its binding as the browser places
it: `fine-<scene_id>/<index>.vtu` (points: the fine rest vertices; cells: the fine triangles; point data:
`displacement`, sum_k w_k x_{carrier_k} minus the rest vertex, and the frame's fields interpolated by the same
weights) and `fine-<scene_id>.pvd`.
`surface_every=N` (the CLI's `--every N`) writes the first state of each series and every Nth after it: a
20 k-vertex surface takes about 0.1 s and 0.7 MB per file (meshio's zlib-compressed binary VTU).
The VTU files are written by meshio (imported only for them; tests/requirements.txt pins it); meshio writes
no .pvd, so the collection's few lines of XML are written here.
Existing files of the same names in out_dir are overwritten.
"""

from __future__ import annotations

import csv
import importlib
import pathlib
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TextIO

import numpy as np

from tactile_proto.generated.Energies import EnergiesT
from tactile_proto.generated.HapticFrame import HapticFrameT
from tactile_proto.generated.SceneDescription import SceneDescriptionT
from tactile_proto.generated.StateFrame import StateFrameT
from tactile_proto.generated.Telemetry import TelemetryT

from .reader import Recording


@dataclass
class Export:
    files: dict[str, int] = field(default_factory=dict)  # path relative to out_dir -> rows (CSV) or frames (PVD)
    notes: list[str] = field(default_factory=list)       # what the reader should know about the files


def _f32(x: float) -> str:
    return str(np.float32(x))  # numpy's shortest text that reads back as this float32


def _f64(x: float) -> str:
    return repr(float(x))


def _text(value: Any, kind: str) -> str:
    if kind == "f32":
        return _f32(value)
    if kind == "f64":
        return _f64(value)
    if kind == "bool":
        return "1" if value else "0"
    if kind == "str":
        return value or ""
    return str(int(value))


def _snake(attr: str) -> str:
    """The schema's name of an object API attribute (flatc: work_loads -> workLoads)."""
    return re.sub(r"(?<=[a-z0-9])([A-Z])", r"_\1", attr).lower()


def _camel(name: str) -> str:
    """The object API attribute of a schema field name (work_loads -> workLoads)."""
    head, *rest = name.split("_")
    return head + "".join(w[:1].upper() + w[1:] for w in rest)


def _fields(cls: type) -> list[tuple[str, str]]:
    """(attribute, kind) of each scalar or string field of a generated object API class, in schema order;
    kind ("int", "f32", "f64", "bool", "str") read from the names its table's accessor uses. Vectors, tables,
    structs and unions are left out."""
    table = getattr(importlib.import_module(cls.__module__), cls.__name__[:-1])
    out = []
    for attr in vars(cls()):
        names = getattr(table, attr[0].upper() + attr[1:]).__code__.co_names
        if {"Vector", "Init", "Union"} & set(names):
            continue
        kind = next((k for flag, k in (("String", "str"), ("Float32Flags", "f32"), ("Float64Flags", "f64"),
                                       ("BoolFlags", "bool")) if flag in names), "int")
        out.append((attr, kind))
    return out


def _xyz(v: Any) -> list[str]:
    return ["", "", ""] if v is None else [_f32(v.x), _f32(v.y), _f32(v.z)]


class _Table:
    """One CSV table: `<stem>.csv`, continued in `<stem>.2.csv`... when its columns change."""

    def __init__(self, out_dir: pathlib.Path, stem: str, result: Export) -> None:
        self.out_dir, self.stem, self.result = out_dir, stem, result
        self.header: tuple[str, ...] | None = None
        self.name = ""
        self.parts = 0  # files started
        self.file: TextIO | None = None
        self.writer: Any = None

    def write(self, header: tuple[str, ...], row: list[str], log_time_ns: int) -> None:
        if header != self.header:
            self.close()
            self.parts += 1
            name = f"{self.stem}.csv" if self.parts == 1 else f"{self.stem}.{self.parts}.csv"
            if self.header is not None:
                self.result.notes.append(f"{self.name} ends at log time {log_time_ns} ns: the scene's columns "
                                         f"changed, {name} continues")
            self.header, self.name = header, name
            self.file = open(self.out_dir / name, "w", newline="", encoding="utf-8")
            self.writer = csv.writer(self.file)
            self.writer.writerow(header)
            self.result.files[name] = 0
        self.writer.writerow(row)
        self.result.files[self.name] += 1

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None


def _names(names: list[str] | None, n: int, kind: str) -> list[str]:
    """The scene's names when there are as many as the frame's entries, else kind0, kind1..."""
    if names is not None and len(names) == n:
        return [name or f"{kind}{i}" for i, name in enumerate(names)]
    return [f"{kind}{i}" for i in range(n)]


# The energy balance's terms and signs (proto/tactile.fbs, struct Energies): their sum is the drift.
_BALANCE = {"kinetic": 1, "discrete": 1, "restated": -1, "elastic": 1, "gravity": 1, "work_loads": -1,
            "work_essential": -1, "work_contact": -1, "dissipated": 1}
# Columns whose schema name lacks its unit.
_UNITS = {"sim_time": "sim_time_s"}


class _Tables:
    """The CSV tables of a recording."""

    ENERGIES = _fields(EnergiesT)
    TELEMETRY = _fields(TelemetryT)
    # The headless simulator's forces.csv and devices.csv columns, after the recording's own keys.
    _KEYS = ("log_time_ns", "sim_time_s", "step", "scene_id")
    _WRENCH = ("fx_N", "fy_N", "fz_N", "tx_Nm", "ty_Nm", "tz_Nm", "contacts")
    FORCES = _KEYS + ("proxy", "device") + _WRENCH + ("px_m", "py_m", "pz_m")
    DEVICES = _KEYS + ("device",) + _WRENCH

    def __init__(self, out_dir: pathlib.Path, result: Export) -> None:
        self.result = result
        self.forces = _Table(out_dir, "forces", result)
        self.devices = _Table(out_dir, "devices", result)
        self.energies = _Table(out_dir, "energies", result)
        self.telemetry = _Table(out_dir, "telemetry", result)
        self.effect_costs = _Table(out_dir, "effect_costs", result)
        self.inputs = _Table(out_dir, "inputs", result)
        self.states_without_energies = 0
        self.states = 0
        self.unnamed: set[tuple[int, int, int]] = set()  # (scene_id, devices, proxies) of frames named by index

    def add_haptic(self, t: int, frame: HapticFrameT, scene: SceneDescriptionT | None) -> None:
        devices, proxies = frame.devices or [], frame.proxies or []
        scene_devices = list(scene.devices or []) if scene is not None else None
        scene_proxies = list(scene.proxies or []) if scene is not None else None
        device_names = _names(scene_devices, len(devices), "device")
        named = scene_proxies if scene_proxies is not None and len(scene_proxies) == len(proxies) else None
        proxy_names = _names([p.name or "" for p in named] if named is not None else None, len(proxies), "proxy")
        proxy_devices = [p.device or "" for p in named] if named is not None else [""] * len(proxies)
        if scene_devices is None or len(scene_devices) != len(devices) or named is None:
            shape = (frame.sceneId, len(devices), len(proxies))
            if shape not in self.unnamed:
                self.unnamed.add(shape)
                self.result.notes.append(f"forces: haptic frames of scene_id {frame.sceneId} (from log time {t} ns) "
                                         f"have {len(devices)} devices and {len(proxies)} proxies, which no scene "
                                         "read names: they are named by index")
        key = [str(t), _f64(frame.simTime), str(frame.step), str(frame.sceneId)]
        for name, device, h in zip(proxy_names, proxy_devices, proxies, strict=True):
            position = h.pose.position if h.pose is not None else None
            self.forces.write(self.FORCES, key + [name, device] + _xyz(h.force) + _xyz(h.torque) + [str(h.contacts)]
                              + _xyz(position), t)
        for name, h in zip(device_names, devices, strict=True):
            self.devices.write(self.DEVICES, key + [name] + _xyz(h.force) + _xyz(h.torque) + [str(h.contacts)], t)

    def add_state(self, t: int, frame: StateFrameT) -> None:
        self.states += 1
        header = (("log_time_ns", "sim_time_s", "step", "scene_id") + tuple(f"{_snake(a)}_J" for a, _ in self.ENERGIES)
                  + ("balance_drift_J",))
        row = [str(t), _f64(frame.simTime), str(frame.step), str(frame.sceneId)]
        if frame.energies is None:
            self.states_without_energies += 1
            row += [""] * (len(self.ENERGIES) + 1)
        else:
            row += [_text(getattr(frame.energies, a), kind) for a, kind in self.ENERGIES]
            row.append(_f64(sum(sign * getattr(frame.energies, _camel(name)) for name, sign in _BALANCE.items())))
        self.energies.write(header, row, t)

    def add_telemetry(self, t: int, telemetry: TelemetryT) -> None:
        header = (("log_time_ns",) + tuple(_UNITS.get(_snake(a), _snake(a)) for a, _ in self.TELEMETRY)
                  + ("fault_count", "faults"))
        row = [str(t)] + [_text(getattr(telemetry, a), kind) for a, kind in self.TELEMETRY]
        # The count is a number in every row (0 without a fault), where an empty `faults` reads as missing.
        row += [str(len(telemetry.faults or [])), "; ".join(telemetry.faults or [])]
        self.telemetry.write(header, row, t)
        for c in telemetry.effectCosts or []:
            self.effect_costs.write(("log_time_ns", "sim_time_s", "effect", "ns_per_step"),
                                    [str(t), _f64(telemetry.simTime), c.name or "", _f32(c.nsPerStep)], t)

    def add_input(self, t: int, device_input: Any) -> None:
        header = ("log_time_ns", "device", "sequence", "device_time_ns", "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz",
                  "buttons")
        p, q = device_input.position, device_input.orientation
        row = [str(t), device_input.device or "", str(device_input.sequence), str(device_input.deviceTimeNs)]
        row += ["", "", ""] if p is None else [_f64(p.x), _f64(p.y), _f64(p.z)]
        row += ["", "", "", ""] if q is None else [_f64(q.w), _f64(q.x), _f64(q.y), _f64(q.z)]
        row.append(str(device_input.buttons))
        self.inputs.write(header, row, t)

    def close(self) -> None:
        for table in (self.forces, self.devices, self.energies, self.telemetry, self.effect_costs, self.inputs):
            table.close()
        if self.states_without_energies:
            self.result.notes.append(f"energies: {self.states_without_energies} of {self.states} state frames carry "
                                     "no energies (a server before protocol 1.4): their energy columns are empty")


class _Surface:
    """The VTU series: one per scene_id, a .vtu per StateFrame and a .pvd per series."""

    def __init__(self, out_dir: pathlib.Path, result: Export, every: int) -> None:
        try:
            self.meshio = importlib.import_module("meshio")
        except ImportError as e:
            raise RuntimeError("VTU export needs meshio (pip install meshio==5.3.5, as tests/requirements.txt "
                               "pins it)") from e
        self.out_dir, self.result, self.every = out_dir, result, every
        self.seen: dict[int, int] = {}  # scene_id -> state frames of its series, written or not
        self.series: dict[int, list[tuple[float, str]]] = {}  # scene_id -> (sim_time [s], .vtu path) per frame
        self.cells: dict[int, list[tuple[str, np.ndarray]]] = {}  # scene_id -> meshio cells
        # scene_id -> the embedded surface's (rest vertices, triangles, carriers, weights), or None
        self.fine: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None] = {}
        self.fine_series: dict[int, list[tuple[float, str]]] = {}
        self.skipped: dict[str, int] = {}  # why -> frames

    def add(self, t: int, frame: StateFrameT, scene: SceneDescriptionT | None) -> None:
        x = np.asarray(frame.positions if frame.positions is not None else [], np.float32).reshape(-1, 3)
        X = np.asarray(scene.restPositions if scene is not None and scene.restPositions is not None else [],
                       np.float32).reshape(-1, 3)
        if scene is None:
            why = "no scene read before them"
        elif len(x) != len(X):
            why = f"their vertex counts differ from their scene's ({len(X)} rest positions)"
        else:
            why = ""
        if why:
            self.skipped[why] = self.skipped.get(why, 0) + 1
            return
        assert scene is not None
        scene_id = scene.sceneId
        if scene_id not in self.series:
            self.series[scene_id] = []
            (self.out_dir / f"surface-{scene_id}").mkdir(exist_ok=True)
            triangles = np.asarray(scene.triangles if scene.triangles is not None else [], np.int64).reshape(-1, 3)
            # meshio reads no file back that has points and no cells: a scene without triangles gets vertices
            self.cells[scene_id] = ([("triangle", triangles)] if len(triangles)
                                    else [("vertex", np.arange(len(X), dtype=np.int64).reshape(-1, 1))])
            self.fine[scene_id] = self._binding(scene, len(X))
            if len(self.series) > 1:
                self.result.notes.append(f"surface: the scene changed at log time {t} ns (scene_id {scene_id}): its "
                                         f"states are in surface-{scene_id}.pvd")
        self.seen[scene_id] = self.seen.get(scene_id, 0) + 1
        if (self.seen[scene_id] - 1) % self.every != 0:
            return
        point_data = {"displacement": x - X}  # [m] (n_vertices x 3)
        scalar_name = scene.scalarName or "scalar"
        if scalar_name == "displacement":
            scalar_name = "displacement_scalar"
        if frame.scalar is not None and len(frame.scalar) == len(x):
            point_data[scalar_name] = np.asarray(frame.scalar, np.float32)
        fields = {}
        for f in frame.fields or []:
            values = np.asarray(f.values if f.values is not None else [], np.float32)
            field_name = f.name.decode() if isinstance(f.name, bytes) else f.name
            if field_name and len(values) == len(x) and field_name not in point_data:
                fields[field_name] = values
        point_data.update(fields)
        frames = self.series[scene_id]
        name = f"surface-{scene_id}/{len(frames):06d}.vtu"
        self.meshio.write(self.out_dir / name, self.meshio.Mesh(X, self.cells[scene_id], point_data=point_data),
                          file_format="vtu")
        frames.append((float(frame.simTime), name))
        fine = self.fine[scene_id]
        if fine is not None:
            rest, triangles, carriers, weights = fine

            def place(v: np.ndarray) -> np.ndarray:  # per fine vertex: sum_k w_k v[carrier_k]
                return np.einsum("pk,pk...->p...", weights, v[carriers])
            fine_data = {"displacement": (place(x.astype(np.float64)) - rest).astype(np.float32)}
            fine_data.update({k: place(v.astype(np.float64)).astype(np.float32) for k, v in fields.items()})
            series = self.fine_series.setdefault(scene_id, [])
            if not series:
                (self.out_dir / f"fine-{scene_id}").mkdir(exist_ok=True)
            fine_name = f"fine-{scene_id}/{len(series):06d}.vtu"
            self.meshio.write(self.out_dir / fine_name,
                              self.meshio.Mesh(rest.astype(np.float32), [("triangle", triangles)],
                                               point_data=fine_data), file_format="vtu")
            series.append((float(frame.simTime), fine_name))

    def _binding(self, scene: SceneDescriptionT, n_vertices: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """The scene's embedded surface, checked against its frame vertices; None without one (or, with a
        note, with one that does not fit them)."""
        e = scene.embedded
        if e is None or e.restPositions is None or e.triangles is None:
            return None
        rest = np.asarray(e.restPositions, np.float64).reshape(-1, 3)
        triangles = np.asarray(e.triangles, np.int64).reshape(-1, 3)
        carriers = np.asarray(e.carriers if e.carriers is not None else [], np.int64).reshape(-1, 4)
        weights = np.asarray(e.weights if e.weights is not None else [], np.float64).reshape(-1, 4)
        why = ("its carriers and weights are not 4 per fine vertex" if len(carriers) != len(rest) or
               len(weights) != len(rest) else
               f"a carrier is not one of the {n_vertices} frame vertices" if carriers.size and
               (carriers.min() < 0 or carriers.max() >= n_vertices) else
               "a triangle names no fine vertex" if triangles.size and
               (triangles.min() < 0 or triangles.max() >= len(rest)) else "")
        if why:
            self.result.notes.append(f"surface: scene_id {scene.sceneId}'s embedded surface is not written: {why}")
            return None
        return rest, triangles, carriers, weights

    def close(self) -> None:
        for prefix, all_series in (("surface", self.series), ("fine", self.fine_series)):
            for scene_id, frames in all_series.items():
                root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
                collection = ET.SubElement(root, "Collection")
                for sim_time, name in frames:
                    ET.SubElement(collection, "DataSet", timestep=_f64(sim_time), group="", part="0", file=name)
                ET.indent(root)
                pvd = f"{prefix}-{scene_id}.pvd"
                ET.ElementTree(root).write(self.out_dir / pvd, encoding="utf-8", xml_declaration=True)
                self.result.files[pvd] = len(frames)
        for why, n in self.skipped.items():
            self.result.notes.append(f"surface: {n} state frames written as no VTU: {why}")


def export(recording: Recording, out_dir: str | pathlib.Path, tables: bool = True, surface: bool = True,
           surface_every: int = 1, progress: Callable[[int, int | None], None] | None = None) -> Export:
    """Writes the CSV tables and/or the VTU series of the surface of `recording` into out_dir (made if
    missing), in one pass; the series hold every `surface_every`th state. What could not be read is in
    recording.problems afterwards; notes about the files are in the result. `progress(done, total)` is called
    every 4096 messages read and at the end (total: what the summary counts on the topics read, None without
    a summary). Raises RuntimeError when `surface` is asked for and meshio is not installed."""
    if surface_every < 1:
        raise ValueError(f"surface_every is {surface_every}: it counts state frames, from 1")
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = Export()
    csvs = _Tables(out, result) if tables else None
    vtus = _Surface(out, result, surface_every) if surface else None
    topics = ["/scene", "/state"] + (["/haptic", "/telemetry", "/input"] if tables else [])
    scenes: dict[int, SceneDescriptionT] = {}  # scene_id -> its latest SceneDescription
    latest: SceneDescriptionT | None = None
    counts = recording.summary_counts
    total = sum(counts.get(topic, 0) for topic in topics) if counts is not None else None
    done = 0
    try:
        for topic, t, envelope in recording.decoded(topics):
            done += 1
            if progress is not None and done % 4096 == 0:
                progress(done, total)
            message = envelope.message
            if topic == "/scene":
                scenes[message.sceneId] = latest = message
            elif topic == "/state":
                if csvs is not None:
                    csvs.add_state(t, message)
                if vtus is not None:
                    vtus.add(t, message, scenes.get(message.sceneId, latest))
            elif csvs is None:
                continue
            elif topic == "/haptic":
                csvs.add_haptic(t, message, scenes.get(message.sceneId, latest))
            elif topic == "/telemetry":
                csvs.add_telemetry(t, message)
            elif topic == "/input":
                csvs.add_input(t, message)
    finally:
        if csvs is not None:
            csvs.close()
        if vtus is not None:
            vtus.close()
    if progress is not None:
        progress(done, total)
    return result


__all__ = ["Export", "export"]
