"""Files and disks (docs/reliability.md): a results folder that cannot be written (at start, on
--resume, mid-run), a full disk during a checkpoint write (a file size limit), env_args longer than
the OS allows, a config far larger than any real one, a --run-id that is not a plain folder name,
and the user's umask on everything written. Each bad case: one message, exit 2, no traceback, and
the checkpoints written before still load."""
from __future__ import annotations

import os
import resource
import shutil
import stat
import subprocess
import sys
import textwrap

import pytest

from tests.integration.conftest import free_port_block, learn
from trainer.artifacts.checkpoints import checkpoint_step, load_checkpoint

TINY = """
behaviors:
  Basic:
    trainer_type: ppo
    hyperparameters: {{batch_size: 32, buffer_size: 128, learning_rate: 3.0e-4, beta: 5.0e-3,
                      epsilon: 0.2, lambd: 0.95, num_epoch: 1}}
    network_settings: {{normalize: false, hidden_units: 8, num_layers: 1}}
    reward_signals: {{extrinsic: {{gamma: 0.9, strength: 1.0}}}}
    keep_checkpoints: 3
    checkpoint_interval: 100
    max_steps: {max_steps}
    time_horizon: 3
    summary_freq: 400
{extra}"""


def tiny(tmp_path, max_steps=300, extra=""):
    path = tmp_path / "tiny.yaml"
    path.write_text(textwrap.dedent(TINY.format(max_steps=max_steps, extra=extra)))
    return path


def without_root_override(cmd: list[str]) -> list[str]:
    """As root, permission bits do not stop writes (CAP_DAC_OVERRIDE): drop that capability from
    the trainer (and its simulator) so an unwritable folder is unwritable for it too."""
    if os.geteuid() != 0:
        return cmd
    if shutil.which("setpriv") is None:
        pytest.skip("running as root without setpriv: cannot make a folder unwritable")
    return ["setpriv", "--bounding-set", "-dac_override,-dac_read_search", "--", *cmd]


def learn_cmd(args):
    return without_root_override([sys.executable, "-m", "trainer.cli", *args])


def one_clear_message(r, *parts):
    assert r.returncode == 2, r.stdout[-2000:] + r.stderr[-2000:]
    assert "Traceback" not in r.stdout + r.stderr
    errors = [line for line in r.stderr.splitlines() if line.startswith("mlagents-like-learn: error:")]
    assert len(errors) == 1, r.stderr
    for part in parts:
        assert part in errors[0], errors[0]
    return errors[0]


def base_args(tmp_path, run_id="w"):
    return ["--env", "stub:basic", "--run-id", run_id, "--results-dir", str(tmp_path / "results"),
            "--base-port", str(free_port_block()), "--seed", "5", "--timeout-wait", "20"]


@pytest.mark.parametrize("run_id", ["../x", "../../x", "a/b", "..", ".", "/abs"])
def test_run_id_must_be_a_plain_folder_name(tmp_path, env_no_proxy, run_id):
    (tmp_path / "inner").mkdir()
    r = learn([str(tiny(tmp_path)), *base_args(tmp_path / "inner", run_id)], cwd=tmp_path / "inner", env=env_no_proxy)
    one_clear_message(r, "--run-id", repr(run_id), "plain folder name")
    assert sorted(os.listdir(tmp_path)) == ["inner", "tiny.yaml"] and os.listdir(tmp_path / "inner") == []


def test_a_config_over_1_mib_is_refused_before_parsing(tmp_path, env_no_proxy):
    big = tmp_path / "big.yaml"
    big.write_text(textwrap.dedent(TINY.format(max_steps=300, extra="")) + "# padding\n" * 120_000)  # 1.2 MB
    assert big.stat().st_size > 1 << 20
    r = learn([str(big), *base_args(tmp_path)], cwd=tmp_path, env=env_no_proxy)
    one_clear_message(r, str(big), "MiB", "at most 1 MiB")
    assert not (tmp_path / "results").exists()


def test_env_args_longer_than_the_os_allows(tmp_path, env_no_proxy):
    # one argument over Linux's MAX_ARG_STRLEN (128 KiB); in the YAML, since the trainer's own
    # command line could not carry it either
    config = tiny(tmp_path, extra=f"env_settings:\n  env_args: ['--x', '{'y' * 200_000}']\n")
    r = learn([str(config), *base_args(tmp_path)], cwd=tmp_path, env=env_no_proxy)
    one_clear_message(r, "command line is too long", "--env-args")
    # nothing trained, so the same run id can be used again right away
    assert not list((tmp_path / "results").rglob("*.pt"))


def test_unwritable_results_folder_at_start(tmp_path, env_no_proxy):
    results = tmp_path / "results"
    results.mkdir(mode=0o500)
    try:
        r = subprocess.run(learn_cmd([str(tiny(tmp_path)), *base_args(tmp_path)]), cwd=tmp_path,
                           capture_output=True, text=True, env=env_no_proxy, timeout=120)
    finally:
        results.chmod(0o700)
    one_clear_message(r, "cannot write", str(results), "Permission denied", "writable")
    assert os.listdir(results) == []


def _trained_run(tmp_path, env_no_proxy):
    r = learn([str(tiny(tmp_path)), *base_args(tmp_path)], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    run = tmp_path / "results" / "w"
    return run, (run / "Basic" / "checkpoint.pt").read_bytes()


def test_unwritable_run_folder_on_resume_keeps_the_checkpoint(tmp_path, env_no_proxy):
    run, latest = _trained_run(tmp_path, env_no_proxy)
    (run / "Basic").chmod(0o500)
    try:
        r = subprocess.run(learn_cmd([str(tiny(tmp_path, max_steps=600)), *base_args(tmp_path), "--resume"]),
                           cwd=tmp_path, capture_output=True, text=True, env=env_no_proxy, timeout=120)
    finally:
        (run / "Basic").chmod(0o700)
    one_clear_message(r, "cannot write", str(run / "Basic"), "Permission denied", "--resume")
    assert (run / "Basic" / "checkpoint.pt").read_bytes() == latest


def test_unwritable_mid_run_stops_with_one_message_and_keeps_the_checkpoints(tmp_path, env_no_proxy):
    run = tmp_path / "results" / "w"
    proc = subprocess.Popen(learn_cmd([str(tiny(tmp_path, max_steps=3000)), *base_args(tmp_path)]), cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env_no_proxy)
    try:
        for line in proc.stdout:
            if "Exported" in line:  # the first checkpoint is complete: now the folder turns read-only
                (run / "Basic").chmod(0o500)
                break
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
        (run / "Basic").chmod(0o700)
    r = subprocess.CompletedProcess(proc.args, proc.returncode, line + out, err)
    one_clear_message(r, "cannot write", str(run / "Basic"), "Permission denied")
    state = load_checkpoint(run / "Basic" / "checkpoint.pt")
    assert 0 < checkpoint_step(state) < 3000


def test_full_disk_during_a_checkpoint_write_keeps_the_previous_one(tmp_path, env_no_proxy):
    """A file size limit stands in for a full disk: the resumed run's first checkpoint cannot be
    written (EFBIG; the trainer ignores SIGXFSZ so the write fails instead of killing it)."""
    run, latest = _trained_run(tmp_path, env_no_proxy)
    limit = len(latest) // 2

    def limit_file_size():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    r = subprocess.run([sys.executable, "-m", "trainer.cli", str(tiny(tmp_path, max_steps=900)),
                        *base_args(tmp_path), "--resume"], cwd=tmp_path, capture_output=True, text=True,
                       env=env_no_proxy, timeout=120, preexec_fn=limit_file_size)
    one_clear_message(r, "cannot write", "File too large", "ulimit -f", "--resume")
    assert (run / "Basic" / "checkpoint.pt").read_bytes() == latest
    assert checkpoint_step(load_checkpoint(run / "Basic" / "checkpoint.pt")) > 300
    assert not list(run.rglob("*.tmp"))


def test_results_are_created_with_the_users_umask(tmp_path, env_no_proxy):
    r = subprocess.run([sys.executable, "-m", "trainer.cli", str(tiny(tmp_path)), *base_args(tmp_path)],
                       cwd=tmp_path, capture_output=True, text=True, env=env_no_proxy, timeout=120,
                       preexec_fn=lambda: os.umask(0o027))
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    paths = [tmp_path / "results"] + list((tmp_path / "results").rglob("*"))
    assert len(paths) > 10
    for path in paths:
        mode = stat.S_IMODE(path.stat().st_mode)
        assert mode & 0o027 == 0, (path, oct(mode))  # nothing beyond what the umask allows
    # and the umask is applied, not a private 0o600 of mkstemp: the group may read checkpoints
    for name in ("Basic/checkpoint.pt", "Basic.onnx", "run_logs/training_status.json", "configuration.yaml"):
        assert stat.S_IMODE((tmp_path / "results" / "w" / name).stat().st_mode) == 0o640, name
