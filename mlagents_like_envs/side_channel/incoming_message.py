"""One message received on a side channel, read value by value in the order it was written."""
from __future__ import annotations

import struct

from protos.side_channels import PayloadReader


class IncomingMessage:
    """Each ``read_*`` returns its ``default_value`` once the message is used up, as in
    mlagents_envs; a value cut short by the end of the message is a ProtocolError."""

    def __init__(self, buffer: bytes, offset: int = 0) -> None:
        self.buffer = buffer
        self.offset = offset

    def _reader(self, what: str) -> PayloadReader:
        return PayloadReader(bytes(self.buffer[self.offset:]), f"side channel message ({what})")

    def _read(self, what: str, method: str):
        reader = self._reader(what)
        value = getattr(reader, method)()
        self.offset = len(self.buffer) - reader.remaining
        return value

    def read_bool(self, default_value: bool = False) -> bool:
        if self._at_end_of_buffer():
            return default_value
        value = struct.unpack_from("<?", self.buffer, self.offset)[0]
        self.offset += 1
        return value

    def read_int32(self, default_value: int = 0) -> int:
        return default_value if self._at_end_of_buffer() else self._read("int32", "read_int32")

    def read_float32(self, default_value: float = 0.0) -> float:
        return default_value if self._at_end_of_buffer() else self._read("float32", "read_float32")

    def read_float32_list(self, default_value: list[float] | None = None) -> list[float]:
        if self._at_end_of_buffer():
            return [] if default_value is None else default_value
        return self._read("float32 list", "read_float_list")

    def read_string(self, default_value: str = "") -> str:
        return default_value if self._at_end_of_buffer() else self._read("string", "read_string")

    def get_raw_bytes(self) -> bytearray:
        """A copy of the whole message."""
        return bytearray(self.buffer)

    def _at_end_of_buffer(self) -> bool:
        return self.offset >= len(self.buffer)
