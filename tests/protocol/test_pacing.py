"""PacedWait (protos/pacing.py): when a waiter blocks and when it polls, by hand."""
from __future__ import annotations

import pytest

from protos import pacing
from protos.pacing import LEAD_S, PacedWait, wait_paced


@pytest.fixture
def clock(monkeypatch):
    """A settable perf_counter for pacing.py."""
    now = [0.0]
    monkeypatch.setattr(pacing.time, "perf_counter", lambda: now[0])
    return now


def exchange(pace: PacedWait, clock, sent_at: float, took: float) -> None:
    clock[0] = sent_at
    pace.sent()
    clock[0] = sent_at + took
    pace.arrived()


def test_no_window_without_spin_history_or_a_message_out(clock):
    assert LEAD_S == 0.5e-3
    off = PacedWait(0.0)
    exchange(off, clock, 1.0, 0.002)
    off.sent()
    assert off.window() is None  # spin 0: plain blocking
    on = PacedWait(0.001)
    on.sent()
    assert on.window() is None  # nothing learnt yet
    on.arrived()
    assert on.window() is None  # nothing out


def test_window_brackets_the_earliest_recent_answer(clock):
    pace = PacedWait(0.001)
    exchange(pace, clock, 10.0, 0.0020)
    exchange(pace, clock, 20.0, 0.0015)
    exchange(pace, clock, 30.0, 0.0030)
    clock[0] = 40.0
    pace.sent()
    block_until, poll_until = pace.window()
    # due = 40 + 1.5 ms; block until 0.5 ms before, poll until 1 ms after
    assert block_until == pytest.approx(40.0010)
    assert poll_until == pytest.approx(40.0025)
    assert (pace.arrivals, pace.caught_polling) == (3, 0)


def test_history_keeps_the_last_16_answers(clock):
    pace = PacedWait(0.002)
    exchange(pace, clock, 1.0, 0.0001)  # one fast answer long ago
    for i in range(16):
        exchange(pace, clock, 2.0 + i, 0.004)
    clock[0] = 100.0
    pace.sent()
    assert pace.window() == pytest.approx((100.0035, 100.006))


def test_an_answer_there_before_we_looked_teaches_nothing(clock):
    pace = PacedWait(0.001)
    exchange(pace, clock, 1.0, 0.002)
    clock[0] = 2.0
    pace.sent()
    pace.forget()  # it was already waiting: its arrival time is unknown
    assert pace.window() is None
    clock[0] = 9.0
    pace.arrived(polling=True)  # without a message out: ignored
    assert (pace.arrivals, pace.caught_polling) == (1, 0)
    exchange(pace, clock, 10.0, 0.003)
    clock[0] = 20.0
    pace.sent()
    assert pace.window() == pytest.approx((20.0015, 20.003))  # min(2 ms, 3 ms)


def test_polling_arrivals_are_counted(clock):
    pace = PacedWait(0.001)
    for i, polled in enumerate([False, True, True, False, True]):
        clock[0] = float(i)
        pace.sent()
        clock[0] += 0.001
        pace.arrived(polling=polled)
    assert (pace.arrivals, pace.caught_polling) == (5, 3)


def test_negative_spin_is_off():
    assert PacedWait(-1.0).spin_s == 0.0


# --- wait_paced: the waiting itself, on a real socket pair ----------------------------------

def primed(spin_s: float, took: float) -> PacedWait:
    """A PacedWait that has seen one answer take ``took`` s and has just sent again."""
    pace = PacedWait(spin_s)
    pace._recent.append(took)
    pace.sent()
    return pace


def test_wait_paced_without_a_window_does_not_wait_or_look():
    calls = []
    assert wait_paced(PacedWait(0.0), [], lambda: calls.append(1) or True) is False
    assert calls == []


def test_wait_paced_polls_until_ready_inside_the_window():
    pace = primed(spin_s=10.0, took=0.0)  # due now: no block, poll for up to 10 s
    answers = iter([False, False, True])
    calls = []
    assert wait_paced(pace, [], lambda: calls.append(1) or next(answers)) is True
    assert len(calls) == 3


def test_wait_paced_gives_up_when_the_window_closes():
    pace = primed(spin_s=0.002, took=0.0)
    calls = []
    assert wait_paced(pace, [], lambda: calls.append(1) or False) is False
    assert len(calls) >= 1


def test_wait_paced_returns_from_the_block_when_the_answer_is_already_readable():
    import socket

    a, b = socket.socketpair()
    with a, b:
        a.sendall(b"x")
        pace = primed(spin_s=0.001, took=60.0)  # due in a minute: it would block until then
        assert wait_paced(pace, [b], lambda: True) is False  # found by the block, not by polling
