"""What the network side and the tick share: fixed slots in one block of memory, never a lock.

The block is a `multiprocessing.shared_memory` segment when the tick runs in a process of its own, or a
plain bytearray when it runs in a thread; the layout and the code are the same. Each slot has one writer.
A slot that holds more than one word is guarded by a sequence counter (a seqlock): the writer makes it odd,
writes, makes it even; a reader that sees it odd or changed across its read tries again. x86 keeps stores
in order, and CPython's reads and writes of one memoryview element are single machine accesses.

Layout (int64 words `q`, then float64 words `d`, then event text bytes):
  header     written by the network: link state, scene generation, server fault, delay; by the tick: stop
             acknowledgement and its loop statistics (tick count, missed deadlines, lateness histogram)
  per device states ring (network -> tick), pose slot (tick -> network), status (tick -> status line)
  events     ring of safety events (tick -> network), with their text
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from multiprocessing import shared_memory
from typing import Any

# ---- sizes ----------------------------------------------------------------------------------------------
RING = 64                  # states kept per device
EVENT_RING = 256
EVENT_TEXT = 200           # bytes of UTF-8 per event message
HIST_US = 10000            # lateness histogram: 1 us bins up to 10 ms, then one overflow bin

# ---- header ints ----------------------------------------------------------------------------------------
H_STOP = 0                 # set by the owner: the tick should stop
H_TICK_ALIVE = 1           # the tick's latest monotonic time [ns]
H_LINK = 2                 # 1 while connected to the server with a scene
H_SCENE_GEN = 3            # bumped for every new scene (reset, load): the tick forgets old states
H_FAULT = 4                # 1 while the server reports a fault
H_DELAY_NS = 5             # display delay of the 'delay' mode [ns]
H_DT_NS = 6                # interval between states: the simulation step, or longer if the server skips [ns]
H_TICKS = 7                # ticks done
H_MISSED = 8               # ticks that started more than one period late
H_REANCHORS = 9            # stalls the tick gave up catching up on
H_LATE_MAX = 10            # latest tick lateness maximum [ns]
H_EVENTS = 11              # events written (ring index = count % EVENT_RING)
H_READY = 12               # the tick has opened its devices and started (1), or failed (-1)
H_ALLOW_NS = 13            # network lateness allowance in the delay [ns]
H_POSE_SEQ = 14            # bumped by the tick after it wrote this tick's poses
H_INTS = 16
# the lateness histogram follows the header ints: HIST_US + 1 words

# ---- per device ints, doubles ---------------------------------------------------------------------------
# states ring: ints [seq, t_ns, arrival_ns, step, contacts, coupled], doubles [force 3, stiffness 9, position 3,
# coupling's max force, local model 17 (wire.MODEL_FLOATS)]
S_INTS, S_DBLS = 6, 33
# pose slot: ints [seq, time_ns, sequence, buttons, connected], doubles [position 3, orientation 4]
P_INTS, P_DBLS = 5, 7
# status: ints [safety mode, engaged ticks, passivity ticks, states used], doubles [command 3, out 3,
# position 3 (scene), passivity alpha, passivity energy, window mean force]
T_INTS, T_DBLS = 4, 12
D_INTS = 1 + RING * S_INTS + P_INTS + T_INTS   # [0] = states written
D_DBLS = RING * S_DBLS + P_DBLS + T_DBLS
# events: ints [seq, time_ns, kind, device, text length], doubles [force]
E_INTS, E_DBLS = 5, 1


def size_of(n_devices: int) -> tuple[int, int, int]:
    """Words of ints, words of doubles, bytes of text for n devices."""
    ints = H_INTS + HIST_US + 1 + n_devices * D_INTS + EVENT_RING * E_INTS
    dbls = n_devices * D_DBLS + EVENT_RING * E_DBLS
    return ints, dbls, EVENT_RING * EVENT_TEXT


class Exchange:
    def __init__(self, n_devices: int, *, shared: bool = False, name: str | None = None) -> None:
        """A new block (`shared`: a shared-memory segment), or the segment `name` another process made."""
        self.n_devices = n_devices
        ints, dbls, text = size_of(n_devices)
        nbytes = 8 * (ints + dbls) + text
        self.shm: shared_memory.SharedMemory | None = None
        if name is not None:
            self.shm = shared_memory.SharedMemory(name=name)
            buf: Any = self.shm.buf
        elif shared:
            self.shm = shared_memory.SharedMemory(create=True, size=nbytes)
            buf = self.shm.buf
            buf[:nbytes] = bytes(nbytes)
        else:
            buf = bytearray(nbytes)
        self.name = self.shm.name if self.shm else None
        mv = memoryview(buf)
        self.i = mv[: 8 * ints].cast("q")
        self.d = mv[8 * ints: 8 * (ints + dbls)].cast("d")
        self.text = mv[8 * (ints + dbls): nbytes]
        self.hist_base = H_INTS
        self._dev_i = [H_INTS + HIST_US + 1 + k * D_INTS for k in range(n_devices)]
        self._dev_d = [k * D_DBLS for k in range(n_devices)]
        self._ev_i = H_INTS + HIST_US + 1 + n_devices * D_INTS
        self._ev_d = n_devices * D_DBLS

    def close(self, unlink: bool = False) -> None:
        # Views first: a segment with views still alive cannot be closed.
        self.i.release()
        self.d.release()
        self.text.release()
        if self.shm is not None:
            self.shm.close()
            if unlink:
                self.shm.unlink()

    # ---- states (network -> tick) -----------------------------------------------------------------------

    def states_written(self, dev: int) -> int:
        return self.i[self._dev_i[dev]]

    def write_state(self, dev: int, t_ns: int, arrival_ns: int, step: int, contacts: int,
                    force: Sequence[float], stiffness: Sequence[float], position: Sequence[float],
                    coupled: bool = False, max_force: float = 0.0, model: Sequence[float] | None = None) -> None:
        i, d = self.i, self.d
        count = i[self._dev_i[dev]]
        slot = count % RING
        bi = self._dev_i[dev] + 1 + slot * S_INTS
        bd = self._dev_d[dev] + slot * S_DBLS
        i[bi] = 2 * count + 1
        i[bi + 1], i[bi + 2], i[bi + 3], i[bi + 4], i[bi + 5] = t_ns, arrival_ns, step, contacts, int(coupled)
        d[bd], d[bd + 1], d[bd + 2] = force[0], force[1], force[2]
        for k in range(9):
            d[bd + 3 + k] = stiffness[k]
        d[bd + 12], d[bd + 13], d[bd + 14] = position[0], position[1], position[2]
        d[bd + 15] = max_force
        if model is None:
            d[bd + 32] = 0.0  # no model: radius 0
        else:
            for k in range(17):
                d[bd + 16 + k] = model[k]
        i[bi] = 2 * count + 2
        i[self._dev_i[dev]] = count + 1

    def read_state(self, dev: int, count: int, history: Any) -> bool:
        """Copies state number `count` of `dev` into `history` (StateHistory.push); False if overwritten."""
        i, d = self.i, self.d
        slot = count % RING
        bi = self._dev_i[dev] + 1 + slot * S_INTS
        bd = self._dev_d[dev] + slot * S_DBLS
        for _ in range(4):
            seq = i[bi]
            if seq != 2 * count + 2:
                return False  # overwritten by a newer state (the tick fell RING states behind), or being written
            history.push(i[bi + 1], i[bi + 2], i[bi + 3], d[bd: bd + 3], d[bd + 3: bd + 12], d[bd + 12: bd + 15],
                         i[bi + 4], bool(i[bi + 5]), d[bd + 15], d[bd + 16: bd + 33])
            if i[bi] == seq:
                return True
        return False

    # ---- poses (tick -> network) ------------------------------------------------------------------------

    def write_pose(self, dev: int, time_ns: int, sequence: int, buttons: int, connected: bool,
                   position: Sequence[float], orientation: Sequence[float]) -> None:
        i, d = self.i, self.d
        bi = self._dev_i[dev] + 1 + RING * S_INTS
        bd = self._dev_d[dev] + RING * S_DBLS
        seq = i[bi]
        i[bi] = seq + 1
        i[bi + 1], i[bi + 2], i[bi + 3], i[bi + 4] = time_ns, sequence, buttons, 1 if connected else 0
        d[bd], d[bd + 1], d[bd + 2] = position[0], position[1], position[2]
        d[bd + 3], d[bd + 4], d[bd + 5], d[bd + 6] = orientation[0], orientation[1], orientation[2], orientation[3]
        i[bi] = seq + 2

    def read_pose(self, dev: int) -> tuple[int, int, int, bool, tuple[float, ...], tuple[float, ...]] | None:
        """(time_ns, sequence, buttons, connected, position, orientation), or None while being written."""
        i, d = self.i, self.d
        bi = self._dev_i[dev] + 1 + RING * S_INTS
        bd = self._dev_d[dev] + RING * S_DBLS
        for _ in range(8):
            seq = i[bi]
            if seq & 1:
                continue
            out = (i[bi + 1], i[bi + 2], i[bi + 3], bool(i[bi + 4]), tuple(d[bd: bd + 3]), tuple(d[bd + 3: bd + 7]))
            if i[bi] == seq:
                return out
        return None

    # ---- status (tick -> status line, single words: no seqlock needed) ----------------------------------

    def status_base(self, dev: int) -> tuple[int, int]:
        return (self._dev_i[dev] + 1 + RING * S_INTS + P_INTS, self._dev_d[dev] + RING * S_DBLS + P_DBLS)

    # ---- events (tick -> network) -----------------------------------------------------------------------

    def write_event(self, time_ns: int, kind: int, device: int, force_N: float, message: str) -> None:
        i = self.i
        count = i[H_EVENTS]
        slot = count % EVENT_RING
        bi = self._ev_i + slot * E_INTS
        raw = message.encode("utf-8")[:EVENT_TEXT]
        i[bi] = 2 * count + 1
        i[bi + 1], i[bi + 2], i[bi + 3], i[bi + 4] = time_ns, kind, device, len(raw)
        # the force at the event: a magnitude, finite and >= 0 as the protocol wants (a non-finite force
        # is the event's cause, named in its message)
        self.d[self._ev_d + slot] = abs(force_N) if math.isfinite(force_N) else 0.0
        self.text[slot * EVENT_TEXT: slot * EVENT_TEXT + len(raw)] = raw
        i[bi] = 2 * count + 2
        i[H_EVENTS] = count + 1

    def read_event(self, count: int) -> tuple[int, int, int, float, str] | None:
        """Event number `count`: (time_ns, kind, device, force_N, message), or None if overwritten."""
        i = self.i
        slot = count % EVENT_RING
        bi = self._ev_i + slot * E_INTS
        seq = i[bi]
        if seq != 2 * count + 2:
            return None
        n = i[bi + 4]
        out = (i[bi + 1], i[bi + 2], i[bi + 3], self.d[self._ev_d + slot],
               bytes(self.text[slot * EVENT_TEXT: slot * EVENT_TEXT + n]).decode("utf-8", "replace"))
        return out if i[bi] == seq else None

    # ---- lateness histogram (tick) ----------------------------------------------------------------------

    def histogram(self) -> list[int]:
        return list(self.i[self.hist_base: self.hist_base + HIST_US + 1])


def percentile_us(hist: Sequence[int], q: float) -> float:
    """The q-quantile (0..1) of a 1 us lateness histogram [us] (the overflow bin reads as HIST_US)."""
    total = sum(hist)
    if total == 0:
        return math.nan
    rank = q * (total - 1)
    seen = 0
    for us, n in enumerate(hist):
        seen += n
        if seen > rank:
            return float(us)
    return float(len(hist) - 1)
