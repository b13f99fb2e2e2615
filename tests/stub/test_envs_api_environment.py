"""mlagents_like_envs.environment.UnityEnvironment over real gRPC with the stub in its own process:
the reset/step cycle, actions, side channels, and the mlagents_envs exception for each failure."""
from __future__ import annotations

import os
import socket
import time
import uuid

import numpy as np
import pytest

from mlagents_like_envs.base_env import ActionTuple, DecisionSteps, TerminalSteps
from mlagents_like_envs.environment import UnityEnvironment
from mlagents_like_envs.exception import (
    UnityActionException,
    UnityEnvironmentException,
    UnityTimeOutException,
    UnityWorkerInUseException,
)
from mlagents_like_envs.side_channel import IncomingMessage, SideChannel
from mlagents_like_envs.side_channel.environment_parameters_channel import EnvironmentParametersChannel
from tests.stub.conftest import start_stub
from unity_stub_env import write_player_launcher

BALL = "3DBall?team=0"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    with open(f"/proc/{pid}/stat") as f:
        return f.read().split(")")[-1].split()[0] == "Z"


class StatsRecorder(SideChannel):
    """A user-defined side channel on the stats channel's id, read field by field."""

    def __init__(self) -> None:
        super().__init__(uuid.UUID("a1d8f7b7-cec8-50f9-b78b-d3e165a78520"))
        self.seen: list[tuple[str, float, int]] = []

    def on_message_received(self, msg: IncomingMessage) -> None:
        self.seen.append((msg.read_string(), msg.read_float32(), msg.read_int32()))


def test_a_session_with_the_stub():
    recorder = StatsRecorder()
    env = UnityEnvironment("stub:ball3d", base_port=free_port(), seed=5, side_channels=[recorder], timeout_wait=30)
    pid = env._process.pid
    try:
        assert dict(env.behavior_specs) == {}  # specs arrive with the first reset
        with pytest.raises(UnityActionException, match="call reset"):
            env.get_steps(BALL)
        env.reset()
        spec = env.behavior_specs[BALL]
        assert [o.shape for o in spec.observation_specs] == [(8,)]
        assert spec.action_spec.continuous_size == 2 and spec.action_spec.discrete_branches == ()
        decision, terminal = env.get_steps(BALL)
        assert isinstance(decision, DecisionSteps) and isinstance(terminal, TerminalSteps)
        assert len(decision) == 12 and len(terminal) == 0 and decision.obs[0].shape == (12, 8)
        first = decision.agent_id[0]
        assert np.array_equal(decision[first].obs[0], decision.obs[0][0])

        env.step()  # no actions set: zeros for everyone
        np.random.seed(0)
        ended = 0
        for _ in range(150):
            decision, terminal = env.get_steps(BALL)
            ended += len(terminal)
            assert all(agent in terminal for agent in terminal.agent_id)
            env.set_actions(BALL, spec.action_spec.random_action(len(decision)))
            env.set_action_for_agent(BALL, decision.agent_id[0], ActionTuple(continuous=np.ones((1, 2))))
            env.step()
        assert ended >= 12  # random tilts drop the balls
        assert recorder.seen and {key for key, _, _ in recorder.seen} >= {"3DBall/Ball Fell"}
    finally:
        env.close()
    assert gone(pid) or (time.sleep(2) is None and gone(pid))
    with pytest.raises(UnityEnvironmentException, match="No Unity environment is loaded"):
        env.step()
    with pytest.raises(UnityEnvironmentException, match="No Unity environment is loaded"):
        env.close()


def test_wrong_actions_are_action_exceptions():
    with UnityEnvironment("stub:basic", base_port=free_port(), timeout_wait=30) as env:
        env.reset()
        name = "Basic?team=0"
        n = len(env.get_steps(name)[0])
        with pytest.raises(UnityActionException, match=r"discrete input of dimension \(1, 1\).*\(1, 2\)"):
            env.set_actions(name, ActionTuple(discrete=np.zeros((n, 2), np.int32)))
        with pytest.raises(UnityActionException, match="must be an ActionTuple"):
            env.set_actions(name, np.zeros((n, 1)))  # type: ignore[arg-type]
        with pytest.raises(UnityActionException, match="does not correspond to an existing agent group"):
            env.set_actions("Other?team=0", ActionTuple(discrete=np.zeros((n, 1), np.int32)))
        with pytest.raises(IndexError, match="did not request a decision"):
            env.set_action_for_agent(name, 12345, ActionTuple(discrete=np.zeros((1, 1), np.int32)))
        with pytest.raises(UnityActionException, match=r"dimension \(1, 0\).*received input of dimension \(2, 0\)"):
            env.set_action_for_agent(name, env.get_steps(name)[0].agent_id[0], ActionTuple(discrete=np.zeros((2, 1))))
        env.set_actions(name, ActionTuple(discrete=np.full((n, 1), 2)))
        env.step()


def test_environment_parameters_reach_the_scene():
    """Gravity 0 sent with the first reset: no ball drops (obs 4 is its height above the plate)."""
    heights = {}
    for gravity in (0.0, None):
        channel = EnvironmentParametersChannel()
        if gravity is not None:
            channel.set_float_parameter("gravity", gravity)
        with UnityEnvironment("stub:ball3d", base_port=free_port(), seed=1, side_channels=[channel],
                              timeout_wait=30) as env:
            env.reset()
            start = env.get_steps(BALL)[0].obs[0][:, 4]
            for _ in range(5):
                env.step()
            heights[gravity] = start, env.get_steps(BALL)[0].obs[0][:, 4]
    start, after = heights[0.0]
    assert np.allclose(start, after, atol=1e-5) and start.min() > 3.0  # dropped from 4 above the plate
    start, after = heights[None]
    assert (after < start - 1.0).all()  # 9.81 m/s^2: it falls


def test_the_editor_is_whatever_connects_to_the_port():
    port = free_port()
    with pytest.raises(UnityEnvironmentException, match="worker 0"):
        UnityEnvironment(file_name=None, worker_id=1, base_port=port)
    stub = start_stub(port, "basic")  # plays the Editor: it connects to base_port
    try:
        with UnityEnvironment(file_name=None, base_port=port, timeout_wait=30) as env:
            env.reset()
            assert list(env.behavior_specs) == ["Basic?team=0"]
            env.step()
        assert stub.wait(timeout=20) == 0
    finally:
        if stub.poll() is None:
            stub.kill()
        stub.communicate(timeout=10)


def test_failures_raise_mlagents_exceptions(tmp_path):
    with pytest.raises(UnityEnvironmentException, match="Could not find"):
        UnityEnvironment(str(tmp_path / "NoSuchGame"), base_port=free_port())

    silent = tmp_path / "Silent.x86_64"  # a "build" that never connects
    silent.write_text("#!/bin/sh\nexec sleep 60\n")
    silent.chmod(0o755)
    started = time.monotonic()
    with pytest.raises(UnityTimeOutException, match="within 2.0 s"):
        UnityEnvironment(str(silent), base_port=free_port(), timeout_wait=2)
    assert time.monotonic() - started < 30

    crashing = tmp_path / "Crash.x86_64"
    crashing.write_text("#!/bin/sh\nexit 3\n")
    crashing.chmod(0o755)
    with pytest.raises(UnityEnvironmentException, match="exited with code 3"):
        UnityEnvironment(str(crashing), base_port=free_port(), timeout_wait=30)

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(UnityWorkerInUseException, match="worker number 2"):
            UnityEnvironment(str(crashing), worker_id=2, base_port=port - 2)


def test_a_dead_environment_is_an_environment_exception(tmp_path):
    build = write_player_launcher(tmp_path, ["basic"])
    env = UnityEnvironment(str(build), base_port=free_port(), timeout_wait=30)
    env.reset()
    env._process._process.kill()
    with pytest.raises(UnityEnvironmentException, match="exited"):
        for _ in range(50):
            env.step()
    env.close()
