"""The one error of the wire package."""
from __future__ import annotations


class ProtocolError(Exception):
    """The peer sent bytes the ML-Agents protocol does not allow (garbled framing, a NaN reward,
    shapes that do not match). The message names the field and what to do; the trainer's CLI
    reports it like a bad flag (one line, exit code 2)."""

    exit_code = 2
