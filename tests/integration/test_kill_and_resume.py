"""kill -9 of the trainer at 22 moments across acting, updating and checkpoint writing; every
``--resume`` loads the newest complete checkpoint, cleans what the killed run left, and the last
run finishes (docs/reliability.md). The moments are picked deterministically with the
MLAGENTS_LIKE_CRASH_AT hook (trainer/crash_points.py): the trainer SIGKILLs itself at the Nth time
it reaches a named point, so nothing of its own runs after (no handler, no flush)."""
from __future__ import annotations

import json
import os
import re
import signal
import textwrap

import pytest

from tests.integration.conftest import free_port_block, learn
from trainer.artifacts.checkpoints import CheckpointError, checkpoint_step, load_checkpoint

TINY = """
behaviors:
  Basic:
    trainer_type: ppo
    hyperparameters: {batch_size: 32, buffer_size: 128, learning_rate: 3.0e-4, beta: 5.0e-3,
                      epsilon: 0.2, lambd: 0.95, num_epoch: 1}
    network_settings: {normalize: false, hidden_units: 8, num_layers: 1}
    reward_signals: {extrinsic: {gamma: 0.9, strength: 1.0}}
    keep_checkpoints: 3
    checkpoint_interval: 100
    max_steps: 2400
    time_horizon: 3
    summary_freq: 400
"""

# (point, occurrence within that run); the first run starts fresh, each later one is --resume
MOMENTS = [
    ("checkpoint.status", 2),
    ("act", 1), ("act", 57), ("act", 173),
    ("update", 1), ("update", 2), ("update.done", 1), ("update.done", 3),
    ("checkpoint.pt", 1), ("checkpoint.pt", 2), ("checkpoint.onnx", 1), ("checkpoint.onnx", 2),
    ("checkpoint.latest", 1), ("checkpoint.latest", 2), ("checkpoint.status", 1),
    ("atomic.replace", 1), ("atomic.replace", 2), ("atomic.replace", 3), ("atomic.replace", 5),
    ("atomic.replace", 8), ("atomic.replace", 13),
    ("act", 301),
]
STEP_FILE = re.compile(r"Basic-(\d+)\.(pt|onnx)")


def newest_loadable_step(folder) -> int:
    """What --resume must pick, found independently of the trainer: the highest step among the
    folder's .pt files that load and pass their checksum."""
    steps = []
    for name in os.listdir(folder):
        if name.endswith(".pt"):
            try:
                steps.append(checkpoint_step(load_checkpoint(folder / name)))
            except CheckpointError:
                pass
    return max(steps)


def test_kill_9_at_22_moments_and_resume_each_time(tmp_path, env_no_proxy):
    assert len(MOMENTS) >= 20
    config = tmp_path / "tiny.yaml"
    config.write_text(textwrap.dedent(TINY))
    run = tmp_path / "results" / "k"
    base = [str(config), "--env", "stub:basic", "--run-id", "k", "--results-dir", str(tmp_path / "results"),
            "--base-port", str(free_port_block()), "--seed", "3", "--timeout-wait", "20"]
    resumed_steps, had_temp_files = [], 0
    for i, (point, n) in enumerate(MOMENTS):
        args = base + (["--resume"] if i else [])
        expected = None
        if i:
            expected = newest_loadable_step(run / "Basic")
            temp_files = [p for p in run.rglob(".*.tmp")]
            had_temp_files += bool(temp_files)
        r = learn(args, cwd=tmp_path, env={**env_no_proxy, "MLAGENTS_LIKE_CRASH_AT": f"{point}:{n}"}, timeout=120)
        assert r.returncode == -signal.SIGKILL, (point, n, r.stdout[-2000:] + r.stderr[-2000:])
        if i:
            loaded = re.search(r"Loaded (\S+) for behavior Basic at step (\d+)\.", r.stdout)
            if loaded is None:  # killed while writing configuration.yaml, before the simulator connected
                assert (point, n) == ("atomic.replace", 1), (point, n, r.stdout[-2000:])
            else:
                assert int(loaded.group(2)) == expected, (point, n, r.stdout[-2000:])
                resumed_steps.append(expected)
            if temp_files:
                assert "unfinished temp file(s)" in r.stdout, (point, n, temp_files)
    assert had_temp_files >= 3  # the atomic.replace moments left temp files behind, and they went
    assert resumed_steps == sorted(resumed_steps) and resumed_steps[-1] > resumed_steps[0]  # never went back
    expected = newest_loadable_step(run / "Basic")
    r = learn(base + ["--resume"], cwd=tmp_path, env=env_no_proxy, timeout=120)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert f"for behavior Basic at step {expected}." in r.stdout
    # what is left: no temp file, no orphan half, keep_checkpoints pairs, all tracked in the status
    assert not list(run.rglob("*.tmp"))
    halves: dict[int, set] = {}
    for name in os.listdir(run / "Basic"):
        match = STEP_FILE.fullmatch(name)
        if match:
            halves.setdefault(int(match.group(1)), set()).add(match.group(2))
    assert all(kinds == {"pt", "onnx"} for kinds in halves.values()), halves
    status = json.loads((run / "run_logs" / "training_status.json").read_text())
    tracked = [c["steps"] for c in status["Basic"]["checkpoints"]]
    assert tracked == sorted(halves) and len(tracked) == 3
    assert status["Basic"]["final_checkpoint"]["steps"] > 2400
    for step in tracked:
        assert checkpoint_step(load_checkpoint(run / "Basic" / f"Basic-{step}.pt")) == step


def test_a_damaged_newest_checkpoint_falls_back_to_the_previous_one(tmp_path, env_no_proxy):
    config = tmp_path / "tiny.yaml"
    config.write_text(textwrap.dedent(TINY).replace("max_steps: 2400", "max_steps: 500"))
    run = tmp_path / "results" / "d"
    base = [str(config), "--env", "stub:basic", "--run-id", "d", "--results-dir", str(tmp_path / "results"),
            "--base-port", str(free_port_block()), "--seed", "3"]
    r = learn(base, cwd=tmp_path, env={**env_no_proxy, "MLAGENTS_LIKE_CRASH_AT": "checkpoint.status:4"})
    assert r.returncode == -signal.SIGKILL
    steps = sorted({int(m.group(1)) for m in map(STEP_FILE.fullmatch, os.listdir(run / "Basic")) if m})
    newest, previous = steps[-1], steps[-2]
    # the newest numbered file truncated, checkpoint.pt (the same step) with a flipped weight
    pt = run / "Basic" / f"Basic-{newest}.pt"
    pt.write_bytes(pt.read_bytes()[:-100])
    import torch

    latest = run / "Basic" / "checkpoint.pt"
    state = torch.load(latest, weights_only=True)
    next(iter(state["Policy"].values())).view(-1)[0] += 1.0
    torch.save(state, latest)
    r = learn(base + ["--resume"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert f"checkpoint '{latest}' fails its checksum" in r.stdout
    assert f"checkpoint '{pt}' is corrupt, truncated" in r.stdout
    assert f"Loaded {run / 'Basic' / f'Basic-{previous}.pt'} for behavior Basic at step {previous}." in r.stdout
    assert "Traceback" not in r.stdout + r.stderr


def _simulator_pids(port: int) -> list[int]:
    pids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                argv = open(f"/proc/{entry}/cmdline", "rb").read().split(b"\0")
            except OSError:
                continue
            if b"unity_stub_env.cli" in argv and b"--mlagents-port" in argv \
                    and argv[argv.index(b"--mlagents-port") + 1] == str(port).encode():
                pids.append(int(entry))
    return pids


def test_kill_9_of_a_simulator_mid_run_restarts_it_and_the_run_completes(tmp_path, env_no_proxy):
    import subprocess
    import sys

    config = tmp_path / "tiny.yaml"
    config.write_text(textwrap.dedent(TINY).replace("max_steps: 2400", "max_steps: 900"))
    port = free_port_block(2)
    cmd = [sys.executable, "-m", "trainer.cli", str(config), "--env", "stub:basic", "--num-envs", "2",
           "--run-id", "s", "--results-dir", str(tmp_path / "results"), "--base-port", str(port),
           "--seed", "3", "--timeout-wait", "20"]
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env_no_proxy)
    lines, killed = [], []
    try:
        for line in proc.stdout:
            lines.append(line)
            if "Exported" in line and not killed:  # mid-run: a checkpoint written, far from max_steps
                killed = _simulator_pids(port + 1)
                assert len(killed) == 1
                os.kill(killed[0], signal.SIGKILL)
        proc.wait(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    out = "".join(lines)
    assert proc.returncode == 0, out[-3000:]
    restarts = [line for line in out.splitlines() if "restarting it and resetting all environments" in line]
    assert len(restarts) == 1 and "Worker 1" in restarts[0], out[-3000:]
    assert _simulator_pids(port + 1) == []  # the replacement was stopped at the end too
    status = json.loads((tmp_path / "results" / "s" / "run_logs" / "training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] > 900


@pytest.mark.parametrize("point, n, sig", [
    ("update", 2, "SIGTERM"), ("update", 2, "SIGUSR1"),         # lands at the start of an update
    ("checkpoint.pt", 1, "SIGTERM"),                            # between two files of one checkpoint
    ("atomic.replace", 3, "SIGUSR1"),                           # mid-write: the first checkpoint's .onnx
    ("checkpoint.latest", 2, "SIGTERM"),
])
def test_a_stop_signal_during_an_update_or_a_checkpoint_write_ends_with_a_loadable_checkpoint(
        tmp_path, env_no_proxy, point, n, sig):
    config = tmp_path / "tiny.yaml"
    config.write_text(textwrap.dedent(TINY))
    run = tmp_path / "results" / "t"
    r = learn([str(config), "--env", "stub:basic", "--run-id", "t", "--results-dir", str(tmp_path / "results"),
               "--base-port", str(free_port_block()), "--seed", "3"], cwd=tmp_path,
              env={**env_no_proxy, "MLAGENTS_LIKE_CRASH_AT": f"{point}:{n}:{sig}"})
    assert r.returncode == 75, r.stdout[-3000:] + r.stderr[-3000:]
    state = load_checkpoint(run / "Basic" / "checkpoint.pt")
    step = checkpoint_step(state)
    assert 0 < step < 2400
    assert checkpoint_step(load_checkpoint(run / "Basic" / f"Basic-{step}.pt")) == step
    assert (run / "Basic" / f"Basic-{step}.onnx").read_bytes() == (run / "Basic.onnx").read_bytes()
    status = json.loads((run / "run_logs" / "training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] == step
    assert not list(run.rglob("*.tmp"))


def test_a_simulator_that_dies_before_its_handshake_is_started_again(tmp_path, env_no_proxy):
    """Killed while it boots (the soak found it: a kill right after a --resume launched it)."""
    import sys

    game = tmp_path / "Boot.x86_64"
    game.write_text(textwrap.dedent(f"""\
        #!/bin/sh
        if [ ! -f "{tmp_path}/died" ]; then touch "{tmp_path}/died"; kill -9 $$; fi
        exec "{sys.executable}" -m unity_stub_env.cli --task basic "$@"
        """))
    game.chmod(0o755)
    config = tmp_path / "tiny.yaml"
    config.write_text(textwrap.dedent(TINY).replace("max_steps: 2400", "max_steps: 200"))
    r = learn([str(config), "--env", str(tmp_path / "Boot"), "--run-id", "b", "--results-dir",
               str(tmp_path / "results"), "--base-port", str(free_port_block()), "--timeout-wait", "20"],
              cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert (tmp_path / "died").exists()
    assert "Worker 0 failed before its first message" in r.stdout and "exited with code -9" in r.stdout


def shown_summary_steps(brain_dir) -> list[int]:
    """Steps of 'Environment/Episode Length' TensorBoard shows: files in order, a SessionLog START
    at step s drops what earlier files wrote at steps >= s (its purge of orphaned data)."""
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader
    from tensorboard.compat.proto import event_pb2

    shown: list[int] = []
    for path in sorted(brain_dir.glob("events.out.tfevents.*"), key=lambda p: int(p.name.split(".")[3])):
        for event in EventFileLoader(str(path)).Load():
            if event.HasField("session_log") and event.session_log.status == event_pb2.SessionLog.START:
                shown = [s for s in shown if s < event.step]
            elif event.HasField("summary") and any(v.tag == "Environment/Episode Length" for v in event.summary.value):
                shown.append(event.step)
    return shown


def test_a_kill_between_a_checkpoint_and_a_later_summary_loses_no_summary(tmp_path, env_no_proxy):
    """checkpoint_interval 100 is not a multiple of summary_freq 250: the checkpoint at ~300 comes
    long before the summary at 500. The resumed run must write 500 (it used to skip to 750)."""
    config = tmp_path / "tiny.yaml"
    config.write_text(textwrap.dedent(TINY).replace("max_steps: 2400", "max_steps: 1000")
                      .replace("summary_freq: 400", "summary_freq: 250"))
    run = tmp_path / "results" / "l"
    base = [str(config), "--env", "stub:basic", "--run-id", "l", "--results-dir", str(tmp_path / "results"),
            "--base-port", str(free_port_block()), "--seed", "3"]
    r = learn(base, cwd=tmp_path, env={**env_no_proxy, "MLAGENTS_LIKE_CRASH_AT": "checkpoint.status:3"})
    assert r.returncode == -signal.SIGKILL
    assert shown_summary_steps(run / "Basic") == [250]
    r = learn(base + ["--resume"], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert shown_summary_steps(run / "Basic") == [250, 500, 750, 1000]
