"""mlagents_envs' exception classes, with its hierarchy: every one is a ``UnityException``."""
from __future__ import annotations


class UnityException(Exception):
    """Any error of the environment API."""


class UnityEnvironmentException(UnityException):
    """Starting, running or closing the environment failed (no executable, the process exited,
    incompatible versions, no environment loaded)."""


class UnityCommunicationException(UnityException):
    """The environment sent something the protocol does not allow."""


class UnityCommunicatorStoppedException(UnityException):
    """The environment closed the connection."""


class UnityObservationException(UnityException):
    """An observation could not be read."""


class UnityActionException(UnityException):
    """Actions for an unknown behavior, of the wrong shape, or for an agent that did not ask."""


class UnityTimeOutException(UnityException):
    """The environment did not connect or answer within ``timeout_wait`` seconds."""


class UnitySideChannelException(UnityException):
    """A side channel was used wrongly (e.g. a screen width without a height)."""


class UnityWorkerInUseException(UnityException):
    """The port of this worker id is taken."""

    def __init__(self, worker_id: int, detail: str = "") -> None:
        self.worker_id = worker_id
        message = (f"Couldn't start socket communication because worker number {worker_id} is still in use. "
                   "Close the environment that holds it, or use another worker_id or base_port.")
        super().__init__(f"{message} {detail}".strip())


class UnityPolicyException(UnityException):
    """A policy could not be used (kept for scripts that catch it)."""
