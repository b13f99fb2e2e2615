"""The simulators launch before the trainer imports numpy, protobuf or torch, and the run then
serves the port the launch bound (docs/performance.md, "Start-up and exit"). Real processes:
mlagents-like-learn and the stub over gRPC; a port held by another process is still one message,
exit 2, with no simulator left running."""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

from tests.integration.conftest import free_port_block

# Runs trainer.cli in this process, noting at the pool's launch which heavy modules are imported
# and whether a simulator process exists yet.
DRIVER = """
import json, sys
from trainer.envs import pool

out = sys.argv[1]
seen = {}
launch = pool.EnvPool.launch

def observed(self, *args, **kwargs):
    seen["at_launch"] = sorted(m for m in ("numpy", "google.protobuf", "torch", "trainer.protocol.server")
                               if m in sys.modules)
    result = launch(self, *args, **kwargs)
    seen["launched"] = [w.process is not None and w.process.pid is not None for w in self.workers]
    return result

pool.EnvPool.launch = observed
from trainer.cli import main
code = main(sys.argv[2:])
with open(out, "w") as f:
    json.dump(seen, f)
sys.exit(code)
"""

CONFIG = """
behaviors:
  Basic:
    trainer_type: ppo
    hyperparameters: {batch_size: 32, buffer_size: 128, num_epoch: 1}
    network_settings: {hidden_units: 16, num_layers: 1}
    max_steps: 300
    time_horizon: 16
    summary_freq: 300
"""


def run_driver(tmp_path, env: dict, port: int) -> tuple[subprocess.CompletedProcess, dict]:
    (tmp_path / "c.yaml").write_text(CONFIG)
    (tmp_path / "driver.py").write_text(DRIVER)
    seen = tmp_path / "seen.json"
    r = subprocess.run([sys.executable, str(tmp_path / "driver.py"), str(seen), str(tmp_path / "c.yaml"),
                        "--env", "stub:basic", "--num-envs", "2", "--seed", "1", "--run-id", "r",
                        "--results-dir", str(tmp_path / "results"), "--base-port", str(port)],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300, env=env)
    return r, json.loads(seen.read_text()) if seen.exists() else {}


def test_simulators_launch_before_numpy_protobuf_and_torch_and_the_run_trains(tmp_path, env_no_proxy):
    r, seen = run_driver(tmp_path, env_no_proxy, free_port_block(2))
    assert r.returncode == 0, r.stderr[-3000:]
    assert seen == {"at_launch": [], "launched": [True, True]}
    assert (tmp_path / "results" / "r" / "Basic.onnx").is_file()
    assert "Basic. Step: 300." in r.stdout


def simulators_on(port: int) -> list[int]:
    """The pids of processes launched with ``--mlagents-port port``."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                args = f.read().split(b"\0")
        except OSError:
            continue
        if any(a == b"--mlagents-port" and b == str(port).encode() for a, b in zip(args, args[1:])):
            found.append(int(pid))
    return found


def test_a_taken_port_is_one_message_and_no_simulator_is_left(tmp_path, env_no_proxy):
    port = free_port_block(2)
    with socket.socket() as holder:
        holder.bind(("127.0.0.1", port + 1))  # the second worker's port
        holder.listen()
        r, seen = run_driver(tmp_path, env_no_proxy, port)
    assert r.returncode == 2
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and f"Port {port + 1} on 127.0.0.1 is already in use" in lines[0], r.stderr
    assert "--base-port" in lines[0] and "Traceback" not in r.stderr
    assert seen == {"at_launch": []}  # the launch raised
    assert simulators_on(port) == []  # the first worker's simulator, started, was stopped
