"""docker/slurm/train.sbatch on a real Slurm: a warning signal mid-run makes the trainer save
and the job requeue itself; the requeued job resumes from that checkpoint without --resume in
the command, ends COMPLETED at max_steps, and TensorBoard (read with its own loader) has every
summary step once. A job killed without warning resumes from its last periodic checkpoint."""
from __future__ import annotations

import json
import os
import re
import signal
import time
from pathlib import Path

import pytest
import yaml
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
from tensorboard.backend.event_processing.event_file_loader import LegacyEventFileLoader

from tests.slurm.cluster import ROOT

pytestmark = pytest.mark.slurm

TEMPLATE = "docker/slurm/train.sbatch"
MAX_STEPS, SUMMARY, INTERVAL = 6000, 500, 1000
BASIC_MAX_STEP = 100  # unity_stub_env/tasks/basic.py: an episode ends after at most 100 steps
CONFIG = f"""
behaviors:
  Basic:
    trainer_type: ppo
    hyperparameters: {{batch_size: 32, buffer_size: 256, learning_rate: 3.0e-4, beta: 5.0e-3,
                      epsilon: 0.2, lambd: 0.95, num_epoch: 3}}
    network_settings: {{normalize: false, hidden_units: 20, num_layers: 1}}
    reward_signals: {{extrinsic: {{gamma: 0.9, strength: 1.0}}}}
    keep_checkpoints: 20
    checkpoint_interval: {INTERVAL}
    max_steps: {MAX_STEPS}
    time_horizon: 3
    summary_freq: {SUMMARY}
"""


def submit(cluster, tmp_path: Path, *learn_args: str, sbatch_args: tuple[str, ...] = ()) -> tuple[str, Path]:
    cfg = tmp_path / "basic.yaml"
    cfg.write_text(CONFIG)
    job = cluster.sbatch(*sbatch_args, "--mem=1G", "--cpus-per-task=1", f"--output={tmp_path}/slurm-%j.out", TEMPLATE, str(cfg),
                         "--env", "stub:basic", "--seed", "1", "--results-dir", str(tmp_path / "results"),
                         *learn_args)
    return job, tmp_path / f"slurm-{job}.out"


def wait_for_line(log: Path, pattern: str, timeout: float = 180) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        text = log.read_text(errors="replace") if log.exists() else ""
        if re.search(pattern, text):
            return text
        time.sleep(0.2)
    raise TimeoutError(f"no {pattern!r} in {log} after {timeout} s:\n" + (log.read_text()[-3000:] if log.exists() else ""))


def raw_summary_steps(folder: Path) -> list[list[int]]:
    """Per event file (oldest first): the steps of its scalar summaries, as written."""
    files = sorted(f for f in os.listdir(folder) if f.startswith("events.out.tfevents"))
    steps = []
    for name in files:
        events = LegacyEventFileLoader(str(folder / name)).Load()  # as written (no conversion)
        steps.append([e.step for e in events if e.HasField("summary") and any(v.HasField("simple_value")
                                                                               for v in e.summary.value)])
    return steps


def tensorboard_steps(folder: Path, tag: str) -> list[int]:
    acc = EventAccumulator(str(folder), size_guidance={"scalars": 0})
    acc.Reload()
    return [e.step for e in acc.Scalars(tag)]


def episode_steps(folder: Path) -> float:
    """Sum over TensorBoard's summaries of episodes x mean episode length: the agent steps of the
    completed episodes it shows."""
    acc = EventAccumulator(str(folder), size_guidance={"scalars": 0, "histograms": 0})
    acc.Reload()
    counts = {e.step: e.histogram_value.num for e in acc.Histograms("Environment/Cumulative Reward_hist")}
    lengths = {e.step: e.value for e in acc.Scalars("Environment/Episode Length")}
    assert counts.keys() == lengths.keys()
    return sum(counts[s] * lengths[s] for s in counts)


def assert_episode_steps_add_up(folder: Path, final: int) -> None:
    """The completed episodes' steps in TensorBoard add up to the trainer's final step, less the two
    episodes never completed (the one under way at the stop or kill, as the resumed simulator
    starts afresh, and the one at the end: each at most Basic's max_step = 100 steps), plus, after
    a kill, the few steps between the checkpoint and the summary after it, counted again after the
    resume (docs/cluster.md, TensorBoard continuity). A summary period counted twice would be ~500
    over, one lost 500-700 under. (CI once saw 102 under with the old bound of +-100.)"""
    counted = episode_steps(folder)
    assert -SUMMARY / 5 < final - counted <= 2 * BASIC_MAX_STEP, (counted, final)


def test_warning_signal_requeues_and_the_job_resumes_to_completion(cluster, tmp_path):
    job, log = submit(cluster, tmp_path)
    wait_for_line(log, r"Basic\. Step: 1000\.")  # after the first summaries
    cluster.run("scancel", "--batch", "--signal=USR1", job)
    info = cluster.wait_for_state(job, ("COMPLETED", "FAILED", "CANCELLED", "TIMEOUT"), timeout=300)
    text = log.read_text()
    assert info["JobState"] == "COMPLETED" and info["ExitCode"] == "0:0", (info, text[-4000:])
    assert int(info["Restarts"]) == 1, info
    run = tmp_path / "results" / f"basic-{job}"

    first, second = text.split("(restart 1)")
    assert "SIGUSR1 received" in first and "exit 75); requeueing" in first, first[-3000:]
    saved = int(re.findall(r"Basic-(\d+)\.onnx to ", first)[-1])  # the final save of the first start
    assert 1000 <= saved < MAX_STEPS
    assert "--resume" in second.splitlines()[1]  # the template added it
    resumed = int(re.search(r"Loaded \S+checkpoint\.pt for behavior Basic at step (\d+)", second).group(1))
    assert resumed == saved
    assert "trainer exited with status 0" in second

    status = json.loads((run / "run_logs" / "training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] >= MAX_STEPS
    assert (run / "Basic.onnx").is_file()
    # TensorBoard: the first start wrote the summaries up to the period it stopped in (that one
    # early, at its label), the second the rest; no step twice, none skipped
    labels = list(range(SUMMARY, MAX_STEPS + 1, SUMMARY))
    partial = -(-saved // SUMMARY) * SUMMARY
    per_file = raw_summary_steps(run / "Basic")
    assert len(per_file) == 2, per_file
    assert per_file[0] == [s for s in labels if s < partial] + [partial] * (per_file[0][-1:] == [partial])
    assert per_file[1] == [s for s in labels if s > partial]
    # (a summary with no completed episode and no update has nothing to write: the stop may land
    # a few steps into a period; then its label is absent, and no other)
    assert_episode_steps_add_up(run / "Basic", status["Basic"]["final_checkpoint"]["steps"])


# buffer_size 256: the 18th update comes at ~4,610 steps, after the checkpoint of 4000 and the
# summary of 4500, before the checkpoint of 5000; a run resumed from 4000 makes ~8 updates to 6000
FREEZE_AT_UPDATE = 18


def frozen_pids(cluster, job: str, log: Path, timeout: float = 240) -> list[int]:
    """The job's processes once one of them (the trainer) has stopped itself with SIGSTOP."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and cluster.job(job).get("JobState") in ("PENDING", "RUNNING"):
        out = cluster.run("scontrol", "listpids", job, check=False).stdout
        pids = [int(line.split()[0]) for line in out.splitlines()[1:] if line.split()[:1] != ["-1"]]
        for pid in pids:
            try:
                state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
            except (OSError, IndexError):
                continue
            if state == "T":
                return pids
        time.sleep(0.2)
    raise TimeoutError(f"no process of job {job} stopped ({cluster.job(job)}):\n" + log.read_text()[-3000:])


def test_a_job_killed_without_warning_resumes_from_its_last_periodic_checkpoint(cluster, tmp_path):
    """The trainer freezes itself (MLAGENTS_LIKE_CRASH_AT=update:18:SIGSTOP, trainer/crash_points.py)
    at the same step however loaded the machine is; then every process of the job is killed at
    once, as in a node failure. The requeued job resumes from the newest checkpoint on disk."""
    freeze = f"--export=ALL,MLAGENTS_LIKE_CRASH_AT=update:{FREEZE_AT_UPDATE}:SIGSTOP"
    job, log = submit(cluster, tmp_path, sbatch_args=(freeze,))
    pids = frozen_pids(cluster, job, log)
    assert len(pids) >= 3  # batch shell, trainer, simulator
    run = tmp_path / "results" / f"basic-{job}" / "Basic"
    on_disk = sorted(int(m.group(1)) for f in run.iterdir() if (m := re.fullmatch(r"Basic-(\d+)\.pt", f.name)))
    for pid in pids:  # as a node failure: everything at once, no signal to handle
        os.kill(pid, signal.SIGKILL)
    killed = cluster.wait_for_state(job, ("FAILED", "CANCELLED", "COMPLETED"), timeout=60)
    assert killed["JobState"] == "FAILED", killed
    first = log.read_text()
    checkpoints = [int(s) for s in re.findall(r"Exported \S+Basic-(\d+)\.onnx", first)]
    summaries = [int(s) for s in re.findall(r"Basic\. Step: (\d+)\.", first)]
    # frozen after the 4th periodic checkpoint and a summary past it, before the 5th checkpoint
    assert on_disk == checkpoints and len(on_disk) == 4, (on_disk, checkpoints)
    assert on_disk[-1] < summaries[-1] < on_disk[-1] + INTERVAL, (on_disk, summaries)
    cluster.run("scontrol", "requeue", job)  # what Slurm does for a --requeue job after a node failure
    info = cluster.wait_for_state(job, ("COMPLETED", "FAILED", "CANCELLED"), timeout=300)
    text = log.read_text()
    assert info["JobState"] == "COMPLETED" and int(info["Restarts"]) == 1, (info, text[-4000:])
    second = text.split("(restart 1)")[1]
    resumed = int(re.search(r"Loaded \S+checkpoint\.pt for behavior Basic at step (\d+)", second).group(1))
    assert resumed == on_disk[-1]  # the newest periodic checkpoint on disk when the job died

    per_file = raw_summary_steps(run)
    assert len(per_file) == 2 and set(per_file[0]) & set(per_file[1]), per_file  # steps written twice...
    labels = list(range(SUMMARY, MAX_STEPS + 1, SUMMARY))
    period = (resumed // SUMMARY + 1) * SUMMARY  # the killed start wrote this summary after the checkpoint
    assert period in per_file[0] and per_file[1][0] == period + SUMMARY, per_file
    for tag in ("Policy/Entropy", "Environment/Cumulative Reward"):  # ...shown once
        assert tensorboard_steps(run, tag) == labels, tag
    # the killed start's summaries after that period are not counted: the steps add up
    final = json.loads((run.parent / "run_logs" / "training_status.json").read_text())["Basic"]["final_checkpoint"]["steps"]
    assert_episode_steps_add_up(run, final)


def test_a_sweep_runs_one_array_element_per_seed_and_summarises_them(cluster, tmp_path):
    cfg = tmp_path / "basic.yaml"
    cfg.write_text(CONFIG.replace(f"max_steps: {MAX_STEPS}", "max_steps: 1000"))
    results = tmp_path / "results"
    sweep = [str(ROOT / "docker" / "slurm" / "sweep.sh"), str(cfg), "--seeds", "4-5",
             "--set", "behaviors.Basic.hyperparameters.lambd=0.9", "--name", "sw", "--results-dir", str(results),
             "--sbatch", f"--mem=1G --cpus-per-task=1 --output={tmp_path}/slurm-%A_%a.out", "--", "--env", "stub:basic"]
    out = cluster.run(*sweep, cwd=ROOT).stdout
    assert "2 elements (2 seeds x 1 settings)" in out, out
    array = (results / "sweeps" / "sw" / "job_id").read_text().strip()
    for task in (0, 1):
        info = cluster.wait_for_state(f"{array}_{task}", ("COMPLETED", "FAILED", "CANCELLED"), timeout=240)
        assert info["JobState"] == "COMPLETED", (info, (tmp_path / f"slurm-{array}_{task}.out").read_text()[-3000:])
    for task, seed in ((0, 4), (1, 5)):  # one results folder per element, with its seed and override
        written = yaml.safe_load((results / f"sw_{task}" / "configuration.yaml").read_text())
        assert written["env_settings"]["seed"] == seed
        assert written["behaviors"]["Basic"]["hyperparameters"]["lambd"] == 0.9
    table = cluster.run(str(ROOT / "docker" / "slurm" / "sweep.sh"), "summary", str(results / "sweeps" / "sw"),
                        cwd=ROOT).stdout.splitlines()
    assert table[0].split() == ["element", "run_id", "seed", "behaviors.Basic.hyperparameters.lambd",
                                "behavior", "step", "final", "reward"]
    blank = table.index("")  # the per-element table, then the mean over seeds (mlagents-like-plot's aggregation)
    rows = [line.split() for line in table[1:blank]]
    assert [r[:6] for r in rows] == [["0", "sw_0", "4", "0.9", "Basic", "1000"], ["1", "sw_1", "5", "0.9", "Basic", "1000"]]
    for r in rows:
        assert -1.0 <= float(r[6]) <= 1.0  # Basic's rewards: a mean return, not a placeholder
    assert table[blank + 2].split()[:4] == ["setting/behavior", "seeds", "step", "mean"]
    grouped = table[blank + 3].split()
    assert grouped[-6:-4] == ["2", "1000"], table[blank:]  # seeds, the last step both reached
    # the mean of the two finals, each printed to 4 decimals: equal within their rounding
    assert abs(float(grouped[-4]) - (float(rows[0][6]) + float(rows[1][6])) / 2) <= 1e-4, table[blank:]


def test_scancel_saves_and_ends_the_job_without_requeue(cluster, tmp_path):
    """scancel sends TERM to every process of the job, the simulator included: the trainer still
    counts it as a stop (exit 75, final checkpoint), but a cancelled job stays cancelled."""
    job, log = submit(cluster, tmp_path)
    wait_for_line(log, r"Basic\. Step: 1000\.")
    cluster.run("scancel", job)
    text = wait_for_line(log, r"train\.sbatch: (the trainer stopped|trainer exited)", timeout=60)
    assert "exit 75) while Slurm ends the job (JobState=COMPLETING: cancelled or preempted): not requeued" in text, \
        text[-3000:]
    info = cluster.wait_for_state(job, ("CANCELLED", "COMPLETED", "FAILED"), timeout=60)
    assert info["JobState"] == "CANCELLED" and info["Restarts"] == "0", info
    time.sleep(2)  # a requeue would show within the credential lifetime (5 s here)
    assert cluster.job(job)["JobState"] == "CANCELLED"
    saved = int(re.findall(r"Basic-(\d+)\.onnx to ", text)[-1])
    status = json.loads((tmp_path / "results" / f"basic-{job}" / "run_logs" / "training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] == saved >= 1000


def test_two_nodes_in_network_namespaces_a_requeued_job_resumes_on_the_other_node(cluster2, tmp_path):
    """Nodes na and nb are network namespaces of their own (own loopback, own ports) sharing the
    file system: the job starts on one, that node is drained, the warning signal requeues the job,
    and it resumes on the other from the checkpoint the first wrote."""
    job, log = submit(cluster2, tmp_path)
    wait_for_line(log, r"Basic\. Step: 1000\.")
    first = cluster2.job(job)["NodeList"]
    other = {"na": "nb", "nb": "na"}[first]
    cluster2.run("scontrol", "update", f"NodeName={first}", "State=DRAIN", "Reason=mlagents-like-test")
    try:
        cluster2.run("scancel", "--batch", "--signal=USR1", job)
        info = cluster2.wait_for_state(job, ("COMPLETED", "FAILED", "CANCELLED"), timeout=300)
    finally:
        cluster2.run("scontrol", "update", f"NodeName={first}", "State=RESUME", check=False)
    text = log.read_text()
    assert info["JobState"] == "COMPLETED" and int(info["Restarts"]) == 1 and info["NodeList"] == other, info
    before, after = text.split("(restart 1)")
    assert f"(restart 0) on {first}:" in before and after.startswith(f" on {other}:"), text[:600]
    saved = int(re.findall(r"Basic-(\d+)\.onnx to ", before)[-1])
    resumed = int(re.search(r"Loaded \S+checkpoint\.pt for behavior Basic at step (\d+)", after).group(1))
    assert resumed == saved
    steps = tensorboard_steps(tmp_path / "results" / f"basic-{job}" / "Basic", "Environment/Episode Length")
    assert len(steps) == len(set(steps)) and steps[-1] == MAX_STEPS and steps[0] == SUMMARY
