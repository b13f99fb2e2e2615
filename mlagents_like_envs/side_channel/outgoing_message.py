"""One message to send on a side channel, written value by value (little-endian)."""
from __future__ import annotations

import logging
import struct

from protos.side_channels import PayloadWriter

logger = logging.getLogger(__name__)


class OutgoingMessage:
    """``buffer`` holds the bytes written so far; values are read back in the same order by the
    environment's side channel (C# ``IncomingMessage``)."""

    def __init__(self) -> None:
        self.buffer = bytearray()

    def write_bool(self, b: bool) -> None:
        self.buffer += struct.pack("<?", b)

    def write_int32(self, i: int) -> None:
        self.buffer += PayloadWriter().write_int32(i).getvalue()

    def write_float32(self, f: float) -> None:
        """Rounded to 32-bit precision."""
        self.buffer += PayloadWriter().write_float32(f).getvalue()

    def write_float32_list(self, float_list: list[float]) -> None:
        """The count (int32), then each value as float32."""
        self.buffer += PayloadWriter().write_float_list(float_list).getvalue()

    def write_string(self, s: str) -> None:
        """The ASCII byte length (int32), then the bytes; a non-ASCII string is a ValueError."""
        self.buffer += PayloadWriter().write_string(s).getvalue()

    def set_raw_bytes(self, buffer: bytes | bytearray) -> None:
        """Replace the whole buffer (what was written before is lost, with a warning)."""
        if self.buffer:
            logger.warning("set_raw_bytes replaces %d bytes already written to this message.", len(self.buffer))
        self.buffer = bytearray(buffer)
