"""The tactile wire protocol for Python: the codec flatc generates from proto/tactile.fbs
(tactile_proto.generated) and a thin layer over it (codec.py): decode, encode, Hello and version checks."""

from .codec import (
    FILE_IDENTIFIER,
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    ProtocolError,
    check_version,
    decode,
    encode,
    make_hello,
    members,
)

__all__ = ["FILE_IDENTIFIER", "PROTOCOL_MAJOR", "PROTOCOL_MINOR", "ProtocolError", "check_version", "decode",
           "encode", "make_hello", "members"]
