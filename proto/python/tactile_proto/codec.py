"""The tactile wire codec: bytes in, messages out, no I/O (proto/README.md).

`decode(bytes) -> EnvelopeT` and `encode(message) -> bytes`, over the object API that flatc generates from
proto/tactile.fbs (tactile_proto.generated). Decoded messages are the generated `...T` objects, with:
  - scalar arrays (`[float]`, `[uint]`) as numpy views into the message's bytes (no copy; read-only when
    the input is `bytes`, and aliasing it when it is a `bytearray`);
  - strings as `str`;
  - an absent string or vector as None, which the schema defines to read as "" or empty.

Python's flatbuffers runtime has no verifier. decode checks what it can before reading (size, file
identifier, root offset), turns every read that falls outside the message into a ProtocolError (strings
included, which the runtime would cut short), and checks what the object API does not: union types it
knows, a message in the Envelope, UTF-8 strings. A damaged message whose offsets still land inside it can
decode to wrong values: the peer that must not trust its input (the C++ server) runs the verifier.
"""

from __future__ import annotations

import importlib
import pkgutil
import struct
from collections.abc import Iterator, Sequence
from typing import Any

import flatbuffers
import numpy as np
from flatbuffers import number_types

from . import generated
from .generated.Envelope import Envelope, EnvelopeT
from .generated.ErrorCode import ErrorCode
from .generated.Hello import HelloT
from .generated.Message import Message
from .generated.ProtocolMajor import ProtocolMajor
from .generated.ProtocolMinor import ProtocolMinor
from .generated.ViewFields import ViewFieldsT
from .generated.Welcome import WelcomeT

PROTOCOL_MAJOR: int = ProtocolMajor.Current
PROTOCOL_MINOR: int = ProtocolMinor.Current
FILE_IDENTIFIER = b"TCTL"  # the schema's file_identifier (tests check it against the generated code)


class ProtocolError(ValueError):
    """A message this codec refuses; `code` is the ErrorCode to answer it with."""

    def __init__(self, message: str, code: int = ErrorCode.Malformed) -> None:
        super().__init__(message)
        self.code = code


def members(enum: type) -> dict[str, int]:
    """The members of a generated enum (or union type enum): name -> value."""
    return {k: v for k, v in vars(enum).items() if not k.startswith("_")}


def _tables_of(union: type) -> dict[type, int]:
    """Object API class -> type value, for each table of a generated union type enum."""
    out = {}
    for name, value in members(union).items():
        if value != 0:  # NONE
            module = importlib.import_module(f"{generated.__name__}.{name}")
            out[getattr(module, f"{name}T")] = value
    return out


def _unions() -> list[type]:
    """Every union of the schema (flatc writes a `<Union>Creator` next to a union's type enum only)."""
    found = []
    for info in pkgutil.iter_modules(generated.__path__):
        module = importlib.import_module(f"{generated.__name__}.{info.name}")
        if hasattr(module, f"{info.name}Creator"):
            found.append(getattr(module, info.name))
    return found


_MESSAGE_TYPE = _tables_of(Message)  # what an Envelope holds
# Every union's tables (a table in two unions would need its type looked up per union; none is).
_UNION_TYPE = {cls: value for union in _unions() for cls, value in _tables_of(union).items()}
_GENERATED = generated.__name__ + "."
# What a read past the end of a damaged message raises inside the flatbuffers runtime and numpy.
_READ_ERRORS = (struct.error, IndexError, ValueError, TypeError, OverflowError)


def _is_object(x: Any) -> bool:
    """Whether x is a generated object API instance (a table or struct)."""
    return type(x).__module__.startswith(_GENERATED)


def _tree(obj: Any, path: str) -> Iterator[tuple[Any, str]]:
    """Every object API instance under obj (obj first), with its path for messages."""
    yield obj, path
    for name, value in vars(obj).items():
        if _is_object(value):
            yield from _tree(value, f"{path}.{name}")
        elif isinstance(value, list):
            for i, item in enumerate(value):
                if _is_object(item):
                    yield from _tree(item, f"{path}.{name}[{i}]")


def _union_value(obj: Any, name: str) -> tuple[bool, Any]:
    """For `<field>Type` attributes, the union's value (flatc names a union's type `<field>Type`)."""
    if not name.endswith("Type") or not hasattr(obj, name[:-4]):
        return False, None
    return True, getattr(obj, name[:-4])


class _Bounded(np.ndarray):
    """The message as uint8 (a view, not a copy) for the runtime to read. The runtime slices it only to
    read a string (Table.String: its bytes, then a 0 in the buffer), and a plain slice would stop at the
    end without a word; here a string that runs past the end or lacks its 0 raises IndexError."""

    def __getitem__(self, key: Any) -> Any:
        if isinstance(key, slice):
            start, stop = key.start or 0, key.stop if key.stop is not None else len(self)
            if start < 0 or stop >= len(self) or super().__getitem__(stop) != 0:
                raise IndexError(f"string at {start}:{stop} runs past the {len(self)}-byte message or lacks its 0")
        return super().__getitem__(key)


def _text(raw: bytes, path: str) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ProtocolError(f"{path}: string is not UTF-8 ({e.reason} at byte {e.start})") from e


def decode(data: bytes | bytearray | memoryview) -> EnvelopeT:
    """The Envelope in `data`; raises ProtocolError naming what is wrong with a message it cannot read."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise TypeError(f"decode takes bytes, not {type(data).__name__}")
    n = memoryview(data).nbytes
    if n < 8:
        raise ProtocolError(f"message too short: {n} bytes (the root offset and file identifier take 8)")
    if bytes(data[4:8]) != FILE_IDENTIFIER:
        raise ProtocolError(f"wrong file identifier {bytes(data[4:8])!r}: not a {FILE_IDENTIFIER.decode()} Envelope")
    root = struct.unpack_from("<I", data, 0)[0]
    if root % 4 != 0 or root + 4 > n:
        raise ProtocolError(f"root table offset {root} is not an aligned offset inside the {n}-byte message")
    try:
        envelope = EnvelopeT.InitFromObj(Envelope.GetRootAs(np.frombuffer(data, np.uint8).view(_Bounded), 0))
        for obj, path in _tree(envelope, "Envelope"):
            for name, value in list(vars(obj).items()):
                if isinstance(value, bytes):
                    setattr(obj, name, _text(value, f"{path}.{name}"))
                elif isinstance(value, list) and value and isinstance(value[0], bytes):
                    setattr(obj, name, [_text(s, f"{path}.{name}[{i}]") for i, s in enumerate(value)])
                else:
                    is_union, table = _union_value(obj, name)
                    if is_union and value != 0 and table is None:
                        raise ProtocolError(f"{path}.{name[:-4]}: union type {value} is unknown or has no table")
    except ProtocolError:
        raise
    except _READ_ERRORS as e:
        raise ProtocolError(f"malformed message ({n} bytes): {type(e).__name__}: {e}") from e
    if envelope.message is None:
        raise ProtocolError("empty Envelope: it holds no message")
    return envelope


_WIRE_DTYPES: dict[type, dict[str, np.dtype]] = {}


def _wire_dtypes(cls: type) -> dict[str, np.dtype]:
    """Attribute -> element dtype of each scalar vector of an object API class, read from the generated
    `<Field>AsNumpy` accessor of its table class (which names the number_types flags of its elements)."""
    if cls in _WIRE_DTYPES:
        return _WIRE_DTYPES[cls]
    table = getattr(importlib.import_module(cls.__module__), cls.__name__[:-1])
    out: dict[str, np.dtype] = {}
    for name in vars(cls()):
        accessor = getattr(table, f"{name[0].upper()}{name[1:]}AsNumpy", None)
        if accessor is None:
            continue
        flags = [f for f in accessor.__code__.co_names if f.endswith("Flags") and f != "UOffsetTFlags"]
        if len(flags) == 1:
            out[name] = number_types.to_numpy_type(getattr(number_types, flags[0]))
    _WIRE_DTYPES[cls] = out
    return out


def _check_encodable(envelope: EnvelopeT) -> None:
    """Refuses what the generated Pack would write as garbage without a word: union types that do not
    match their tables, and numpy arrays of another element type or shape than the wire's."""
    for obj, path in _tree(envelope, "Envelope"):
        dtypes = _wire_dtypes(type(obj))
        for name, value in vars(obj).items():
            if isinstance(value, np.ndarray) and name in dtypes:
                wire = dtypes[name]
                if value.ndim != 1 or value.dtype.kind != wire.kind or value.dtype.itemsize != wire.itemsize:
                    raise ValueError(f"{path}.{name}: a {value.ndim}-d {value.dtype} array; the wire holds a flat "
                                     f"{wire} vector (pass np.ravel(a).astype(np.{wire}))")
            is_union, table = _union_value(obj, name)
            if is_union and (table is not None or value != 0):
                expected = _UNION_TYPE.get(type(table))
                if value != expected:
                    raise ValueError(f"{path}.{name} is {value}, but {path}.{name[:-4]} is "
                                     f"{type(table).__name__ if table is not None else 'None'} (type {expected})")


def encode(message: Any) -> bytes:
    """The bytes of one Envelope: `message` is an EnvelopeT, or a message (HelloT, StateFrameT...) to wrap."""
    if isinstance(message, EnvelopeT):
        envelope = message
    elif type(message) in _MESSAGE_TYPE:
        envelope = EnvelopeT()
        envelope.messageType = _MESSAGE_TYPE[type(message)]
        envelope.message = message
    else:
        raise TypeError(f"encode takes an EnvelopeT or a message table (HelloT, ...), not {type(message).__name__}")
    if envelope.message is None:
        raise ValueError("empty Envelope: it holds no message")
    _check_encodable(envelope)
    builder = flatbuffers.Builder(1024)
    builder.Finish(envelope.Pack(builder), FILE_IDENTIFIER)
    return bytes(builder.Output())


def make_hello(
    role: int, token: str = "", client_name: str = "", devices: Sequence[str] = (), fields: Sequence[str] = (),
    max_rate_hz: float = 0.0,
) -> HelloT:
    """A Hello in this codec's protocol version; `role` is a generated Role value (Role.Device...); `fields`
    the per-vertex fields asked for in state frames (1.8); `max_rate_hz` the frames per second the client
    takes at most, haptic frames for a Device and state frames otherwise (1.10; 0: the server's rate)."""
    hello = HelloT()
    hello.protocolMajor = PROTOCOL_MAJOR
    hello.protocolMinor = PROTOCOL_MINOR
    hello.role = role
    hello.token = token
    hello.clientName = client_name
    hello.devices = list(devices)
    hello.fields = list(fields)
    hello.maxRateHz = max_rate_hz
    return hello


def make_view_fields(fields: Sequence[str]) -> ViewFieldsT:
    """A ViewFields (1.8): the per-vertex fields a client now asks for in its state frames."""
    v = ViewFieldsT()
    v.fields = list(fields)
    return v


def check_version(message: Any) -> None:
    """Raises ProtocolError (code VersionMismatch) when a Hello or Welcome (or an Envelope holding one)
    speaks another major version than this codec; minor versions only add fields, so any minor goes."""
    if isinstance(message, EnvelopeT):
        message = message.message
    if not isinstance(message, (HelloT, WelcomeT)):
        raise TypeError(f"check_version takes a Hello or a Welcome, not {type(message).__name__}")
    if message.protocolMajor != PROTOCOL_MAJOR:
        raise ProtocolError(f"version mismatch: peer speaks {message.protocolMajor}.{message.protocolMinor}, "
                            f"we speak {PROTOCOL_MAJOR}.{PROTOCOL_MINOR}", ErrorCode.VersionMismatch)


__all__ = ["FILE_IDENTIFIER", "PROTOCOL_MAJOR", "PROTOCOL_MINOR", "ProtocolError", "check_version",
           "decode", "encode", "make_hello", "members"]
