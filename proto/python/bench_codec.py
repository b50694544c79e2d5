"""Codec benchmark, Python: the size of the protocol's frames and what encoding and decoding one costs
(proto/tactile.fbs). The same cases as server/bench/codec_bench.cpp and proto/js/bench/codec.bench.js, so
that the three tables compare. Prints figures, passes and fails nothing.

    .venv/bin/python proto/python/bench_codec.py            all cases (a few seconds)
    .venv/bin/python proto/python/bench_codec.py --quick    fewer repeats, for CI

Cases: StateFrames of 5 k, 20 k and 50 k surface vertices (positions, a scalar per vertex, 1 proxy) and
HapticFrames of 1 proxy / 1 device and of 5 proxies / 1 device. Columns:
  encode  the generated builder API, float arrays written by `Builder.CreateNumpyVector` (one copy each);
  decode  `tactile_proto.decode` (its checks, then the object API, float arrays as numpy views into the
          bytes), and every value read once (sums): what a peer of this codec pays;
  read    the generated accessors alone (`GetRootAs`, `...AsNumpy`), no checks, every value read once.
Python's flatbuffers runtime has no verifier, so there is no verify step to time (codec.py says what
decode checks instead). Times are medians over repeated batches of calls, per frame.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import flatbuffers
import numpy as np

import tactile_proto
from tactile_proto.generated import Envelope as env
from tactile_proto.generated import HapticFrame as hf
from tactile_proto.generated import StateFrame as sf
from tactile_proto.generated.DeviceHaptics import CreateDeviceHaptics
from tactile_proto.generated.Mat3f import Mat3f
from tactile_proto.generated.Message import Message
from tactile_proto.generated.ProxyHaptics import CreateProxyHaptics
from tactile_proto.generated.ProxyPose import CreateProxyPose, ProxyPose
from tactile_proto.generated.Quatf import Quatf
from tactile_proto.generated.Vec3f import CreateVec3f, Vec3f

# The surface vertex counts of the C++ benchmark's slabs, so that sizes match across languages.
STATE_VERTICES = (5000, 20000, 49928)
HAPTIC_PROXIES = (1, 5)
FILE_IDENTIFIER = tactile_proto.FILE_IDENTIFIER


def time_per_call(f: Callable[[], object], repeats: int) -> float:
    """Seconds per call of f: the median over `repeats` batches, each long enough (>= 5 ms) that the
    clock's resolution and the loop's own cost do not show."""
    calls = 1
    while True:  # find the batch size (this also warms up)
        t0 = time.perf_counter()
        for _ in range(calls):
            f()
        if time.perf_counter() - t0 >= 5e-3:
            break
        calls *= 2
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(calls):
            f()
        samples.append((time.perf_counter() - t0) / calls)
    return statistics.median(samples)


def seal(b: flatbuffers.Builder, message_type: int, body: int) -> bytes:
    """The Envelope around `body`, as bytes (as tactile_proto.encode returns them)."""
    env.EnvelopeStart(b)
    env.EnvelopeAddMessageType(b, message_type)
    env.EnvelopeAddMessage(b, body)
    b.Finish(env.EnvelopeEnd(b), FILE_IDENTIFIER)
    return bytes(b.Output())


def _sum_fields(struct: Any) -> float:
    """The sum of a decoded struct's fields (a Vec3fT, QuatfT or Mat3fT of the object API)."""
    return float(sum(vars(struct).values()))


# ---- state frames --------------------------------------------------------------------------------------


class StateData:
    """What a StateFrame carries, as the sender holds it."""

    def __init__(self, n_vertices: int, rng: np.random.Generator) -> None:
        self.positions = rng.uniform(-0.1, 0.1, (n_vertices, 3)).astype(np.float32)  # [m] (n_vertices x 3)
        self.scalar = rng.uniform(0, 1e-3, n_vertices).astype(np.float32)  # [m] (n_vertices)
        self.pose = rng.uniform(-1, 1, 7).tolist()  # position [m] x y z, orientation w x y z (1 proxy)
        self.force = rng.uniform(-1, 1, 3).tolist()  # [N] (1 proxy)


def encode_state(d: StateData) -> bytes:
    # Sized for the whole frame, so that the builder never grows (it cannot be cleared and reused in 2.0.7).
    b = flatbuffers.Builder(4 * (d.positions.size + d.scalar.size) + 256)
    positions = b.CreateNumpyVector(d.positions.reshape(-1))
    scalar = b.CreateNumpyVector(d.scalar)
    sf.StateFrameStartProxiesVector(b, 1)
    CreateProxyPose(b, *d.pose)
    proxies = b.EndVector()
    sf.StateFrameStartContactForcesVector(b, 1)
    CreateVec3f(b, *d.force)
    forces = b.EndVector()
    sf.StateFrameStart(b)
    sf.StateFrameAddSceneId(b, 1)
    sf.StateFrameAddStep(b, 1000)
    sf.StateFrameAddSimTime(b, 0.2)
    sf.StateFrameAddServerTimeNs(b, 123456789)
    sf.StateFrameAddPositions(b, positions)
    sf.StateFrameAddScalar(b, scalar)
    sf.StateFrameAddProxies(b, proxies)
    sf.StateFrameAddContactForces(b, forces)
    return seal(b, Message.StateFrame, sf.StateFrameEnd(b))


def decode_state(data: bytes) -> float:
    frame: Any = tactile_proto.decode(data).message  # a StateFrameT
    s = frame.simTime + frame.step + frame.serverTimeNs + frame.sceneId
    s += float(frame.positions.sum()) + float(frame.scalar.sum())
    for p in frame.proxies:
        s += _sum_fields(p.position) + _sum_fields(p.orientation)
    for f in frame.contactForces:
        s += _sum_fields(f)
    return s


def _read_vec(v: Any) -> float:
    return float(v.X() + v.Y() + v.Z())


def _read_quat(q: Any) -> float:
    return float(q.W() + q.X() + q.Y() + q.Z())


def _read_mat(m: Any) -> float:
    return float(m.M00() + m.M01() + m.M02() + m.M10() + m.M11() + m.M12() + m.M20() + m.M21() + m.M22())


def read_state(data: bytes) -> float:
    table = env.Envelope.GetRootAs(data, 0).Message()
    frame = sf.StateFrame()
    frame.Init(table.Bytes, table.Pos)
    s = frame.SimTime() + frame.Step() + frame.ServerTimeNs() + frame.SceneId()
    s += float(frame.PositionsAsNumpy().sum()) + float(frame.ScalarAsNumpy().sum())
    x, q = Vec3f(), Quatf()  # nested structs are read through objects the caller gives
    for i in range(frame.ProxiesLength()):
        p = frame.Proxies(i)
        s += _read_vec(p.Position(x)) + _read_quat(p.Orientation(q))
    for i in range(frame.ContactForcesLength()):
        s += _read_vec(frame.ContactForces(i))
    return s


# ---- haptic frames -------------------------------------------------------------------------------------


class HapticData:
    """What a HapticFrame carries: 23 numbers per proxy (force, torque, pose, stiffness, contacts) and 24
    per device (force, torque, stiffness, contacts; pose; newest input sequence)."""

    def __init__(self, n_proxies: int, rng: np.random.Generator) -> None:
        self.proxies = [rng.uniform(-1, 1, 22).tolist() + [3] for _ in range(n_proxies)]
        self.devices = [rng.uniform(-1, 1, 15).tolist() + [3 * n_proxies]]
        self.device_poses = [rng.uniform(-1, 1, 7).tolist()]
        self.sequences = np.full(1, 42, dtype=np.uint64)


def encode_haptic(d: HapticData) -> bytes:
    b = flatbuffers.Builder(128 + 92 * len(d.proxies) + 100 * len(d.devices))
    # A vector of structs is written back to front.
    hf.HapticFrameStartProxiesVector(b, len(d.proxies))
    for p in reversed(d.proxies):
        CreateProxyHaptics(b, *p)
    proxies = b.EndVector()
    hf.HapticFrameStartDevicesVector(b, len(d.devices))
    for dev in reversed(d.devices):
        CreateDeviceHaptics(b, *dev)
    devices = b.EndVector()
    hf.HapticFrameStartDevicePosesVector(b, len(d.device_poses))
    for pose in reversed(d.device_poses):
        CreateProxyPose(b, *pose)
    device_poses = b.EndVector()
    sequences = b.CreateNumpyVector(d.sequences)
    hf.HapticFrameStart(b)
    hf.HapticFrameAddSceneId(b, 1)
    hf.HapticFrameAddStep(b, 1000)
    hf.HapticFrameAddSimTime(b, 0.2)
    hf.HapticFrameAddServerTimeNs(b, 123456789)
    hf.HapticFrameAddLastInputSequence(b, 42)
    hf.HapticFrameAddProxies(b, proxies)
    hf.HapticFrameAddDevices(b, devices)
    hf.HapticFrameAddDevicePoses(b, device_poses)
    hf.HapticFrameAddDeviceInputSequences(b, sequences)
    return seal(b, Message.HapticFrame, hf.HapticFrameEnd(b))


def decode_haptic(data: bytes) -> float:
    frame: Any = tactile_proto.decode(data).message  # a HapticFrameT
    s = frame.simTime + frame.step + frame.serverTimeNs + frame.lastInputSequence + frame.sceneId
    for p in frame.proxies:
        s += _sum_fields(p.force) + _sum_fields(p.torque) + _sum_fields(p.pose.position)
        s += _sum_fields(p.pose.orientation) + _sum_fields(p.stiffness) + p.contacts
    for dev in frame.devices:
        s += _sum_fields(dev.force) + _sum_fields(dev.torque) + _sum_fields(dev.stiffness) + dev.contacts
    for pose in frame.devicePoses:
        s += _sum_fields(pose.position) + _sum_fields(pose.orientation)
    s += float(frame.deviceInputSequences.sum())
    return s


def read_haptic(data: bytes) -> float:
    table = env.Envelope.GetRootAs(data, 0).Message()
    frame = hf.HapticFrame()
    frame.Init(table.Bytes, table.Pos)
    s = frame.SimTime() + frame.Step() + frame.ServerTimeNs() + frame.LastInputSequence() + frame.SceneId()
    x, q, pose, m = Vec3f(), Quatf(), ProxyPose(), Mat3f()
    for i in range(frame.ProxiesLength()):
        p = frame.Proxies(i)
        s += _read_vec(p.Force(x)) + _read_vec(p.Torque(x)) + _read_vec(p.Pose(pose).Position(x))
        s += _read_quat(pose.Orientation(q)) + _read_mat(p.Stiffness(m)) + p.Contacts()
    for i in range(frame.DevicesLength()):
        dev = frame.Devices(i)
        s += _read_vec(dev.Force(x)) + _read_vec(dev.Torque(x)) + _read_mat(dev.Stiffness(m)) + dev.Contacts()
    for i in range(frame.DevicePosesLength()):
        p = frame.DevicePoses(i)
        s += _read_vec(p.Position(x)) + _read_quat(p.Orientation(q))
    s += float(frame.DeviceInputSequencesAsNumpy().sum())
    return s


# ---- the table -----------------------------------------------------------------------------------------


def measure(name: str, vertices: int, data: bytes, encode: Callable[[], object], decode: Callable[[], object],
            read: Callable[[], object], repeats: int) -> tuple[str, int, int, float, float, float]:
    """One row: (frame, vertices or 0, bytes, encode, decode, read [s per frame])."""
    return (name, vertices, len(data), time_per_call(encode, repeats), time_per_call(decode, repeats),
            time_per_call(read, repeats))


def main() -> None:
    parser = argparse.ArgumentParser(description="Prints the size and the encode/decode cost of tactile frames.")
    parser.add_argument("--quick", action="store_true", help="fewer repeats, for CI")
    repeats = 5 if parser.parse_args().quick else 21
    rng = np.random.default_rng(1)

    rows = []
    for n in STATE_VERTICES:
        state = StateData(n, rng)
        data = encode_state(state)
        # The decoded views must be the values written: a wrong benchmark times nothing useful.
        if not np.array_equal(tactile_proto.decode(data).message.positions, state.positions.reshape(-1)):
            raise SystemExit("the decoded positions differ from those encoded")
        rows.append(measure(f"state {round(n / 1000)}k", n, data, partial(encode_state, state),
                            partial(decode_state, data), partial(read_state, data), repeats))
    for n in HAPTIC_PROXIES:
        haptic = HapticData(n, rng)
        data = encode_haptic(haptic)
        if len(tactile_proto.decode(data).message.proxies) != n:
            raise SystemExit("the decoded frame lost proxies")
        rows.append(measure(f"haptic {n}p/1d", 0, data, partial(encode_haptic, haptic), partial(decode_haptic, data),
                            partial(read_haptic, data), repeats))

    print(f"Python codec cost per frame (flatbuffers {flatbuffers.__version__}, numpy {np.__version__}, medians)\n")
    print(f"{'frame':<18} {'vertices':>9} {'bytes':>8} {'B/vert':>8} {'encode us':>10} {'decode us':>10} "
          f"{'read us':>9}")
    for name, n, size, encode, decode, read in rows:
        vertices, per_vertex = (str(n), f"{size / n:.2f}") if n else ("-", "-")
        print(f"{name:<18} {vertices:>9} {size:>8} {per_vertex:>8} {1e6 * encode:>10.2f} {1e6 * decode:>10.2f} "
              f"{1e6 * read:>9.2f}")
    print("\nencode: generated builder, numpy vectors; decode: tactile_proto.decode + read every value;\n"
          "read: generated accessors + read every value (no checks).")


if __name__ == "__main__":
    main()
