"""A raw scripted trainer (gRPC server) and a launcher for the stub as a separate process."""
from __future__ import annotations

import json
import os
import queue
import socket
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import grpc
import pytest

from protos.communicator_objects import (
    agent_action_pb2,
    header_pb2,
    unity_message_pb2,
    unity_to_external_pb2_grpc,
)
from tests import interop_venv

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
INTEROP_PYTHON = str(interop_venv.INTEROP_PYTHON)  # the real ML-Agents 1.1.0
STEP, RESET, QUIT = 0, 1, 2
Message = unity_message_pb2.UnityMessageProto


class ScriptedTrainer(unity_to_external_pb2_grpc.UnityToExternalProtoServicer):
    """Every Exchange call is queued; the test reads it with ``receive`` and answers it."""

    def __init__(self) -> None:
        self.requests: queue.Queue = queue.Queue()
        self.user_agents: list[str] = []  # of each call: which gRPC client the stub used
        self.responses: queue.Queue = queue.Queue()
        self.server = grpc.server(ThreadPoolExecutor(max_workers=4))
        unity_to_external_pb2_grpc.add_UnityToExternalProtoServicer_to_server(self, self.server)
        self.port = self.server.add_insecure_port("localhost:0")
        self.server.start()

    def Exchange(self, request, context):  # noqa: N802
        self.user_agents.append(dict(context.invocation_metadata()).get("user-agent", ""))
        self.requests.put(request)
        return self.responses.get(timeout=30)

    def receive(self, timeout: float = 10.0) -> Message:
        return self.requests.get(timeout=timeout)

    def respond(self, message: Message) -> None:
        self.responses.put(message)

    def exchange(self, message: Message, timeout: float = 10.0) -> Message:
        """Answer the pending call and return the next request."""
        self.respond(message)
        return self.receive(timeout)

    def stop(self) -> None:
        self.server.stop(None)


def init_answer(seed: int = 0, num_areas: int = 1, version: str = "1.5.0") -> Message:
    message = Message(header=header_pb2.HeaderProto(status=200))
    init = message.unity_input.rl_initialization_input
    init.seed, init.num_areas = seed, num_areas
    init.communication_version, init.package_version = version, "1.1.0"
    init.capabilities.baseRLCapabilities = True
    return message


def command_answer(command: int, side_channel: bytes = b"", status: int = 200) -> Message:
    message = Message(header=header_pb2.HeaderProto(status=status))
    if status == 200:
        message.unity_input.rl_input.command = command
        message.unity_input.rl_input.side_channel = side_channel
    return message


def step_answer(behavior: str, continuous=None, discrete=None, side_channel: bytes = b"") -> Message:
    """STEP with one AgentActionProto per row of ``continuous`` / ``discrete``."""
    message = command_answer(STEP, side_channel)
    rows = continuous if continuous is not None else discrete
    actions = message.unity_input.rl_input.agent_actions[behavior].value
    for i in range(len(rows)):
        action = agent_action_pb2.AgentActionProto()
        if continuous is not None:
            action.continuous_actions.extend(continuous[i])
        if discrete is not None:
            action.discrete_actions.extend(discrete[i])
        actions.append(action)
    return message


def start_stub(port: int, task: str, *extra: str) -> subprocess.Popen:
    command = [sys.executable, "-m", "unity_stub_env.cli", "--task", task, "--mlagents-port", str(port),
               "--connect-timeout", "20", *extra]
    return subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.fixture
def trainer():
    scripted = ScriptedTrainer()
    yield scripted
    scripted.stop()


@pytest.fixture
def launch():
    """launch(port, task, *flags) -> Popen; every process is killed at teardown."""
    processes = []

    def _launch(port: int, task: str, *extra: str) -> subprocess.Popen:
        process = start_stub(port, task, *extra)
        processes.append(process)
        return process

    yield _launch
    for process in processes:
        if process.poll() is None:
            process.kill()
        process.communicate(timeout=10)


def handshake(trainer: ScriptedTrainer, seed: int = 0, num_areas: int = 1, side_channel: bytes = b""):
    """Answer M1 and M2 (with RESET); returns (M1, M2, M3)."""
    first = trainer.receive(timeout=20)
    second = trainer.exchange(init_answer(seed, num_areas))
    third = trainer.exchange(command_answer(RESET, side_channel))
    return first, second, third


def run_interop_script(script: str, timeout: float = 120) -> dict:
    """Run ``script`` in the interop venv with argv (free port, this Python, the repo) and return
    the JSON of its last ``RESULT {...}`` line (ML-Agents and our protos never share a process)."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    done = subprocess.run([INTEROP_PYTHON, "-c", script, str(port), sys.executable, REPO],
                          cwd="/tmp", capture_output=True, text=True, timeout=timeout)
    lines = [line for line in done.stdout.splitlines() if line.startswith("RESULT ")]
    assert lines, done.stdout + done.stderr
    return json.loads(lines[-1][len("RESULT "):])


_SESSION_HEAD = r"""
import json, subprocess, sys
import numpy as np
from mlagents_envs.environment import UnityEnvironment
from mlagents_envs.base_env import ActionTuple

port, stub_python, repo = int(sys.argv[1]), sys.argv[2], sys.argv[3]
stub = subprocess.Popen([stub_python, "-m", "unity_stub_env.cli", STUB_ARGS, "--mlagents-port", str(port)], cwd=repo)
env = UnityEnvironment(file_name=None, base_port=port, timeout_wait=30)
env.reset()
"""
_SESSION_TAIL = r"""
env.close()
out["exit"] = stub.wait(timeout=20)
print("RESULT " + json.dumps(out))
"""


def run_stub_session(stub_args: list[str], body: str, timeout: float = 120) -> dict:
    """``run_interop_script`` of one session of the real ``UnityEnvironment`` with the stub: the
    script starts ``unity_stub_env.cli STUB_ARGS`` on the free port, connects and resets, runs
    ``body`` (Python at top level with ``env``, ``np`` and ``ActionTuple``; it fills the dict
    ``out``), then closes the environment and adds the stub's exit status as ``out["exit"]``."""
    head = _SESSION_HEAD.replace("STUB_ARGS", ", ".join(f'"{arg}"' for arg in stub_args))
    return run_interop_script(head + body + _SESSION_TAIL, timeout)
