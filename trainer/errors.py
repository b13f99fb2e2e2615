"""Errors a user can act on. Each carries one message that names the thing and what to do.

The CLI turns any ``UserError`` into that one message on stderr and exit code 2 (no traceback
unless ``--debug``), and so does ``protos.errors.ProtocolError`` (a message from the simulator
we cannot make sense of), which the wire package shares with the simulator. Everything else is a
bug and keeps its traceback.
"""
from __future__ import annotations


class UserError(Exception):
    """Bad input or a broken environment the user can fix. Exit code 2."""

    exit_code = 2


class ConfigError(UserError):
    """A YAML file or CLI flag that is malformed, unknown or out of range."""


class EnvironmentNotFoundError(UserError):
    """--env names no executable we can find."""


class PortInUseError(UserError):
    """The port we need to listen on is taken."""


class UnityTimeOutError(UserError):
    """The simulator did not connect, or stopped answering, within --timeout-wait."""


class SimulatorExitedError(UserError):
    """The simulator process died."""


class UnityVersionError(UserError):
    """The simulator speaks an incompatible communication API version."""


class ResultsWriteError(UserError):
    """A file of the results folder could not be written: permissions, a read-only or full disk,
    a file size limit. Earlier checkpoints are intact (every write is atomic)."""


class UnityCommunicatorStoppedError(Exception):
    """The simulator closed the connection (status != 200). Not an error: training stops cleanly."""

