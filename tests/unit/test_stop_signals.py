"""trainer.stop: a stop signal is recorded, and acted on only where the trainer checks."""
from __future__ import annotations

import os
import signal

import pytest

from trainer.stop import GracefulStop, StopRequests


@pytest.fixture
def requests():
    stop = StopRequests()
    saved = {name: signal.getsignal(getattr(signal, name)) for name in ("SIGTERM", "SIGUSR1", "SIGINT", "SIGQUIT")}
    stop.install()
    yield stop
    for name, handler in saved.items():
        signal.signal(getattr(signal, name), handler)


def test_a_signal_is_only_recorded_until_the_next_safe_point(requests):
    os.kill(os.getpid(), signal.SIGTERM)  # handled before kill() returns, in this thread
    assert requests.requested == "SIGTERM" and requests.received == 1  # nothing was raised here
    with pytest.raises(GracefulStop, match="SIGTERM"):
        requests.check()
    requests.check()  # raised once: the shutdown code after it runs undisturbed


def test_a_second_signal_is_reported_a_third_stops_at_once(requests, capfd):
    os.kill(os.getpid(), signal.SIGUSR1)
    with pytest.raises(GracefulStop):
        requests.check()
    os.kill(os.getpid(), signal.SIGTERM)  # e.g. while the final checkpoint is written
    assert "already stopping" in capfd.readouterr().err
    with pytest.raises(GracefulStop, match="SIGTERM"):
        os.kill(os.getpid(), signal.SIGTERM)
    assert requests.requested == "SIGUSR1" and requests.received == 3


def test_check_without_a_signal_does_nothing():
    stop = StopRequests()
    stop.check()
    assert stop.requested is None
