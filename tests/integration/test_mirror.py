"""The CI recipe of docs/mirror.md, end to end: the commands of docs/ci/github-actions.yml and
docs/ci/gitlab-ci.yml run as they are (plus --base-port, so parallel tests do not collide) on
a spec captured here from the stub's own tasks and on a hand-written spec with a PNG camera, a
recurrent behavior and two teams; the reward read back from the TensorBoard files must rise."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from protos.spec_file import SpecFile
from tests.integration.conftest import ROOT, free_port_block, learn

GITHUB = ROOT / "docs" / "ci" / "github-actions.yml"
GITLAB = ROOT / "docs" / "ci" / "gitlab-ci.yml"


def recipe_commands() -> list[str]:
    """The mlagents-like-learn lines of the GitHub workflow, checked to equal the GitLab job's."""
    github = yaml.safe_load(GITHUB.read_text())
    steps = github["jobs"]["trainer-config"]["steps"]
    from_github = [s["run"].strip() for s in steps if "mlagents-like-learn" in s.get("run", "")]
    from_gitlab = [line for line in yaml.safe_load(GITLAB.read_text())["trainer-config"]["script"]
                   if "mlagents-like-learn" in line]
    assert from_github == from_gitlab and len(from_github) == 2
    assert "--check" in from_github[0] and "stub:mirror=$BEHAVIOR_SPEC" in from_github[1]
    uploaded = [s for s in steps if s.get("uses", "").startswith("actions/upload-artifact")]
    assert uploaded[0]["with"]["path"] == "results/${{ env.MIRROR_RUN_ID }}"
    return from_github


def run_recipe(cwd: Path, config: str, spec: str, max_steps: int) -> list[subprocess.CompletedProcess]:
    env = {**os.environ, "TRAINER_CONFIG": config, "BEHAVIOR_SPEC": spec, "MIRROR_MAX_STEPS": str(max_steps),
           "MIRROR_RUN_ID": "mirror", "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    done = []
    for command in recipe_commands():
        done.append(subprocess.run(["bash", "-c", f"{command} --base-port {free_port_block()}"], cwd=cwd, env=env,
                                   capture_output=True, text=True, timeout=240))
        assert done[-1].returncode == 0, done[-1].stdout[-3000:] + done[-1].stderr[-3000:]
    return done


def rewards(run_dir: Path, brain: str) -> list[float]:
    acc = EventAccumulator(str(run_dir / brain))
    acc.Reload()
    return [e.value for e in acc.Scalars("Environment/Cumulative Reward")]


def assert_rises(values: list[float], by: float) -> None:
    third = max(len(values) // 3, 1)
    first, last = float(np.mean(values[:third])), float(np.mean(values[-third:]))
    print(f"reward {first:.3f} -> {last:.3f} over {len(values)} summaries")
    assert last >= first + by, f"{values}: {first:.3f} -> {last:.3f}"


YAML = """
behaviors:
  {name}:
    trainer_type: ppo
    hyperparameters: {{batch_size: 64, buffer_size: 512, learning_rate: 3.0e-3, num_epoch: 3}}
    network_settings: {{hidden_units: 32, num_layers: 1{extra}}}
    reward_signals: {{extrinsic: {{gamma: 0.9, strength: 1.0}}}}
    max_steps: 500000
    time_horizon: 32
    summary_freq: 50000
"""


def project_yaml(*behaviors: tuple[str, str]) -> str:
    return "".join(YAML.format(name=name, extra=extra).replace("behaviors:\n", "" if i else "behaviors:\n")
                   for i, (name, extra) in enumerate(behaviors))


@pytest.mark.slow
def test_recipe_on_a_spec_captured_from_the_stub_tasks(tmp_path):
    capture = learn(["--capture-spec", "ci/behaviors.json", "--env", "stub:basic,ball3d", "--num-areas", "2",
                     "--seed", "3", "--base-port", str(free_port_block())], tmp_path)
    assert capture.returncode == 0, capture.stdout + capture.stderr
    spec = SpecFile.load(str(tmp_path / "ci" / "behaviors.json"))
    assert [(b.name, b.agents, b.agents_per_area) for b in spec.behaviors] == [
        ("Basic?team=0", 2, 1), ("3DBall?team=0", 24, 12)]
    assert not (tmp_path / "results" / "ppo" / "Basic").exists()  # captured, not trained
    (tmp_path / "trainer.yaml").write_text(project_yaml(("Basic", ""), ("3DBall", "")))
    run_recipe(tmp_path, "trainer.yaml", "ci/behaviors.json", max_steps=4000)
    run_dir = tmp_path / "results" / "mirror"
    # measured with seed 1: Basic 3.83 -> 5.88, 3DBall 1.59 -> 2.14 (the target policy earns 10)
    assert_rises(rewards(run_dir, "Basic"), by=1.0)
    assert_rises(rewards(run_dir, "3DBall"), by=0.3)
    # the run records what it met: the mirror presents the captured behaviors (1 area here, 2 in the capture)
    def seen(spec: SpecFile) -> list:
        return [(b.name, b.spec, b.compressions, b.agents_per_area) for b in spec.behaviors]
    assert seen(SpecFile.load(str(run_dir / "run_logs" / "behaviors.json"))) == seen(spec)


HAND_SPEC = {
    "format_version": 1, "source": "hand-written", "num_areas": 1, "stats": ["Game/Score"],
    "behaviors": [
        {"name": "Seeker?team=0", "observations": [{"name": "CameraSensor", "shape": [3, 20, 20],
                                                     "compression": "png"}],
         "actions": {"continuous": 0, "discrete_branches": [3]}, "agents": 4, "max_step": 50},
        {"name": "Rememberer?team=0", "observations": [{"name": "VectorSensor_size6", "shape": [6]}],
         "actions": {"continuous": 1, "discrete_branches": [2]}, "agents": 4, "max_step": 50},
        {"name": "Striker?team=0", "observations": [{"name": "VectorSensor_size8", "shape": [8]}],
         "actions": {"continuous": 0, "discrete_branches": [3, 2]}, "agents": 2, "groups_per_area": 1,
         "max_step": 50},
        {"name": "Striker?team=1", "observations": [{"name": "VectorSensor_size8", "shape": [8]}],
         "actions": {"continuous": 0, "discrete_branches": [3, 2]}, "agents": 2, "groups_per_area": 1,
         "max_step": 50},
    ],
}


@pytest.mark.slow
def test_recipe_on_a_hand_written_spec_with_a_camera_memory_and_two_teams(tmp_path):
    (tmp_path / "behaviors.json").write_text(json.dumps(HAND_SPEC))
    config = project_yaml(("Seeker", ", vis_encode_type: simple"),
                          ("Rememberer", ", memory: {sequence_length: 8, memory_size: 16}"), ("Striker", ""))
    (tmp_path / "trainer.yaml").write_text(config)
    # the check first catches what a renamed behavior and a too small camera break
    broken = config.replace("Seeker:", "Seekr:").replace("vis_encode_type: simple", "vis_encode_type: nature_cnn")
    (tmp_path / "broken.yaml").write_text(broken)
    check = learn(["broken.yaml", "--check", "--spec", "behaviors.json"], tmp_path)
    assert check.returncode == 2
    assert len(check.stdout.strip().splitlines()) == 2, check.stdout
    assert "behavior 'Seeker' is in the spec but not under 'behaviors'" in check.stdout
    assert "'behaviors.Seekr' in broken.yaml names no behavior of the spec" in check.stdout

    run_recipe(tmp_path, "trainer.yaml", "behaviors.json", max_steps=5000)
    run_dir = tmp_path / "results" / "mirror"
    recorded = SpecFile.load(str(run_dir / "run_logs" / "behaviors.json"))
    def seen(spec: SpecFile) -> dict:  # what the protocol shows (max_step cannot be seen)
        return {b.name: (b.spec, b.compressions, b.agents, b.groups_per_area) for b in spec.behaviors}
    assert seen(recorded) == seen(SpecFile.from_dict(HAND_SPEC))
    assert recorded.stats == ("Game/Score",)
    # measured with seed 1: Seeker 1.80 -> 2.77, Rememberer 1.85 -> 2.08, Striker 2.10 -> 2.67 (max 5)
    for brain, by in (("Seeker", 0.5), ("Rememberer", 0.1), ("Striker", 0.3)):
        assert_rises(rewards(run_dir, brain), by=by)
