"""Run-level features end to end: several envs, curriculum, simulator stats, restarts, inference."""
from __future__ import annotations

import json
import signal
import sys
import textwrap

import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.integration.conftest import BASIC_YAML, free_port_block, learn, run_with_signals


def tb_scalars(folder) -> dict[str, list[tuple[int, float]]]:
    acc = EventAccumulator(str(folder), size_guidance={"scalars": 0})
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def test_two_envs_curriculum_and_simulator_stats(tmp_path, env_no_proxy):
    cfg = tmp_path / "c.yaml"
    cfg.write_text(textwrap.dedent(BASIC_YAML.format(max_steps=1200, interval=100000, summary=400, keep=5)) + textwrap.dedent("""
        environment_parameters:
          difficulty:
            curriculum:
              - name: Easy
                value: 0.0
                completion_criteria: {behavior: Basic, measure: progress, threshold: 0.5, require_reset: true}
              - name: Hard
                value: {sampler_type: uniform, sampler_parameters: {min_value: 1.0, max_value: 2.0}}
        """))
    port = free_port_block(2)
    r = learn([str(cfg), "--env", "stub:basic", "--num-envs", "2", "--run-id", "c", "--seed", "5",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(port)], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    run = tmp_path / "results" / "c"
    # one simulator per env, each with its own Player log on base_port + i
    assert (run / "run_logs/Player-0.log").is_file() and (run / "run_logs/Player-1.log").is_file()
    assert "Parameter 'difficulty' is in lesson 'Easy' and has value 'Float: value=0.0'" in r.stdout
    assert "Parameter 'difficulty' is in lesson 'Hard' and has value 'Uniform sampler: min=1.0, max=2.0'" in r.stdout
    status = json.loads((run / "run_logs/training_status.json").read_text())
    assert status["difficulty"] == {"lesson_num": 1}
    tags = tb_scalars(run / "Basic")
    lessons = tags["Environment/Lesson Number/difficulty"]
    assert lessons[0][1] == 0.0 and lessons[-1][1] == 1.0  # progress 0.5 of 1200 steps: lesson 0 at the 400 summary, 1 from 800
    # a stat the simulator sends on the stats side channel lands under its own name
    assert "Basic/Large Goal Reached" in tags
    assert all(0.0 <= v <= 1.0 for _, v in tags["Basic/Large Goal Reached"])
    # the RESET required by the lesson change reached the simulators
    logs = (run / "run_logs/Player-0.log").read_text() + (run / "run_logs/Player-1.log").read_text()
    assert "Environment reset by the trainer" in logs


def _flaky_game(tmp_path, crash_after: int, first_port: int | None = None, first_port_crash_after: int = 0) -> str:
    """A 'Unity build' whose first launch on each port crashes after ``crash_after`` exchanges
    (``first_port_crash_after`` on ``first_port``); later launches are fine. Each crash leaves
    a ``crashed-<port>`` mark in ``tmp_path``."""
    game = tmp_path / "Flaky.x86_64"
    game.write_text(textwrap.dedent(f"""\
        #!/bin/sh
        port=""; prev=""
        for a; do [ "$prev" = --mlagents-port ] && port="$a"; prev="$a"; done
        mark="{tmp_path}/crashed-$port"
        if [ ! -f "$mark" ]; then
          touch "$mark"
          [ "$port" = "{first_port}" ] && after={first_port_crash_after} || after={crash_after}
          exec "{sys.executable}" -m unity_stub_env.cli --task basic --crash-after $after "$@"
        fi
        exec "{sys.executable}" -m unity_stub_env.cli --task basic "$@"
        """))
    game.chmod(0o755)
    return str(tmp_path / "Flaky")


def test_crashed_simulator_is_restarted_and_training_finishes(tmp_path, basic_config, env_no_proxy):
    game = _flaky_game(tmp_path, crash_after=300)
    r = learn([str(basic_config(max_steps=900)), "--env", game, "--run-id", "f", "--timeout-wait", "10",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert "restarting it and resetting all environments" in r.stdout
    status = json.loads((tmp_path / "results/f/run_logs/training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] > 900


@pytest.mark.parametrize("worker0_crash_after", [0, 150])
def test_each_simulator_has_its_own_restart_quota_and_a_crash_during_reset_is_restarted(
        tmp_path, basic_config, worker0_crash_after, env_no_proxy):
    """Two simulators, default limits (1 restart per 60 s, as ML-Agents counts them: per worker).
    The first launch of worker 0 dies during the initial RESET (0) or after 150 steps, worker 1's
    after 200 steps; both are restarted once and training finishes."""
    port = free_port_block(2)
    game = _flaky_game(tmp_path, crash_after=200, first_port=port, first_port_crash_after=worker0_crash_after)
    r = learn([str(basic_config(max_steps=900)), "--env", game, "--num-envs", "2",
               "--run-id", "q", "--timeout-wait", "10", "--results-dir", str(tmp_path / "results"),
               "--base-port", str(port)], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert sorted(p.name for p in tmp_path.glob("crashed-*")) == [f"crashed-{port}", f"crashed-{port + 1}"]
    restarts = [line for line in r.stdout.splitlines() if "restarting it and resetting all environments" in line]
    assert [line.split("Worker ")[1][0] for line in restarts] == ["0", "1"]
    status = json.loads((tmp_path / "results/q/run_logs/training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] > 900


def test_crash_without_restarts_left_is_a_clear_error(tmp_path, basic_config, env_no_proxy):
    game = _flaky_game(tmp_path, crash_after=50)
    r = learn([str(basic_config(max_steps=900)), "--env", game, "--run-id", "g", "--timeout-wait", "10",
               "--max-lifetime-restarts", "0", "--results-dir", str(tmp_path / "results"),
               "--base-port", str(free_port_block())], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 2
    assert "exited" in r.stderr and "Player-" in r.stderr and "Traceback" not in r.stderr


def test_inference_runs_the_saved_policy_without_training(tmp_path, basic_config, env_no_proxy):
    port = free_port_block()
    res = str(tmp_path / "results")
    r = learn([str(basic_config(max_steps=600, interval=300)), "--env", "stub:basic", "--run-id", "i",
               "--results-dir", res, "--base-port", str(port)], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-2000:]
    status_file = tmp_path / "results/i/run_logs/training_status.json"
    before = json.loads(status_file.read_text())["Basic"]
    cmd = [sys.executable, "-m", "trainer.cli", str(basic_config(max_steps=600)), "--env", "stub:basic",
           "--run-id", "i", "--results-dir", res, "--base-port", str(port), "--inference"]
    # SIGTERM: what Slurm or a user's kill sends
    code, text = run_with_signals(cmd, tmp_path, env_no_proxy, [(("Loaded", "checkpoint.pt"), signal.SIGTERM)])
    assert code == 0, text
    after = json.loads(status_file.read_text())["Basic"]
    assert after["checkpoints"] == before["checkpoints"]  # inference writes no new checkpoint
    assert f"at step {before['final_checkpoint']['steps']}" in text


def test_two_behaviors_in_one_run_each_train_and_stop_at_their_own_max_steps(tmp_path, env_no_proxy):
    """One simulator with two behaviors (stub:basic,ball3d, like a Unity scene with two Behavior
    Parameters): each gets its own trainer, folder, TensorBoard run, checkpoints and ONNX, and one
    that reaches max_steps stops learning while the other goes on."""
    cfg = tmp_path / "two.yaml"
    cfg.write_text(textwrap.dedent("""
        behaviors:
          Basic:
            trainer_type: ppo
            hyperparameters: {batch_size: 32, buffer_size: 256}
            network_settings: {hidden_units: 20, num_layers: 1}
            max_steps: 600
            time_horizon: 3
            summary_freq: 300
            checkpoint_interval: 300
          3DBall:
            trainer_type: ppo
            hyperparameters: {batch_size: 64, buffer_size: 1200}
            network_settings: {normalize: true, hidden_units: 32}
            max_steps: 2400
            time_horizon: 100
            summary_freq: 1200
            checkpoint_interval: 1200
        """))
    r = learn([str(cfg), "--env", "stub:basic,ball3d", "--run-id", "two", "--seed", "2",
               "--results-dir", str(tmp_path / "results"), "--base-port", str(free_port_block())],
              cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    run = tmp_path / "results" / "two"
    assert "Connected new brain: Basic?team=0" in r.stdout and "Connected new brain: 3DBall?team=0" in r.stdout
    status = json.loads((run / "run_logs/training_status.json").read_text())
    for brain, max_steps in (("Basic", 600), ("3DBall", 2400)):
        assert (run / f"{brain}.onnx").is_file() and (run / brain / "checkpoint.pt").is_file()
        final = status[brain]["final_checkpoint"]["steps"]
        # stops within one decision batch of max_steps (24 ball3d agents per decision at most)
        assert max_steps < final <= max_steps + 24, (brain, final)
        tags = tb_scalars(run / brain)
        assert "Losses/Policy Loss" in tags and "Environment/Cumulative Reward" in tags
    # 3DBall finished first but was not updated or checkpointed again while Basic trained on
    assert sorted(c["steps"] for c in status["3DBall"]["checkpoints"])[-1] == status["3DBall"]["final_checkpoint"]["steps"]
    assert len(status["3DBall"]["checkpoints"]) == 3


def test_curiosity_and_rnd_train_report_and_resume(tmp_path, env_no_proxy):
    text = textwrap.dedent(BASIC_YAML.format(max_steps="{max_steps}", interval=100000, summary=300, keep=5))
    text = text.replace("reward_signals: {extrinsic: {gamma: 0.9, strength: 1.0}}", textwrap.dedent("""\
        reward_signals:
              extrinsic: {gamma: 0.9, strength: 1.0}
              curiosity: {gamma: 0.99, strength: 0.02, network_settings: {hidden_units: 16}}
              rnd: {gamma: 0.99, strength: 0.01, network_settings: {hidden_units: 8, num_layers: 1}}"""))
    cfg, cfg2 = tmp_path / "c.yaml", tmp_path / "c2.yaml"
    cfg.write_text(text.replace("{max_steps}", "900"))
    cfg2.write_text(text.replace("{max_steps}", "1500"))
    port = free_port_block()
    common = ["--env", "stub:basic", "--run-id", "cur", "--seed", "2", "--results-dir", str(tmp_path / "results"),
              "--base-port", str(port)]
    r = learn([str(cfg), *common], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    tags = tb_scalars(tmp_path / "results/cur/Basic")
    for tag in ("Losses/Curiosity Forward Loss", "Losses/Curiosity Inverse Loss", "Losses/RND Loss",
                "Policy/Curiosity Reward", "Policy/Curiosity Value Estimate", "Policy/Rnd Reward",
                "Policy/Rnd Value Estimate", "Policy/Extrinsic Value Estimate"):
        assert tag in tags, tag
    # rnd rewards are positive prediction errors; curiosity's stay <= 1 (capped at 1/strength, times strength)
    assert all(v > 0 for _, v in tags["Policy/Rnd Reward"])
    assert all(0 <= v for _, v in tags["Policy/Curiosity Reward"])
    r2 = learn([str(cfg2), *common, "--resume"], cwd=tmp_path, env=env_no_proxy)
    assert r2.returncode == 0, r2.stderr[-3000:]
    assert "starts untrained" not in r2.stdout + r2.stderr  # the providers came back from checkpoint.pt
    steps = [s for s, _ in tb_scalars(tmp_path / "results/cur/Basic")["Losses/RND Loss"]]
    assert max(steps) >= 1500 - 300


def test_memory_trains_exports_recurrent_onnx_and_resumes(tmp_path, env_no_proxy):
    import onnx

    text = textwrap.dedent(BASIC_YAML.format(max_steps="{max_steps}", interval=100000, summary=300, keep=5))
    text = text.replace("network_settings: {normalize: false, hidden_units: 20, num_layers: 1}",
                        "network_settings: {normalize: true, hidden_units: 20, num_layers: 1,\n"
                        "                       memory: {memory_size: 8, sequence_length: 4}}")
    assert "memory_size: 8" in text
    cfg, cfg2 = tmp_path / "m.yaml", tmp_path / "m2.yaml"
    cfg.write_text(text.replace("{max_steps}", "600"))
    cfg2.write_text(text.replace("{max_steps}", "900"))
    common = ["--env", "stub:basic", "--run-id", "mem", "--seed", "4", "--results-dir", str(tmp_path / "results"),
              "--base-port", str(free_port_block())]
    r = learn([str(cfg), *common], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    model = onnx.load(str(tmp_path / "results/mem/Basic.onnx"))
    assert [i.name for i in model.graph.input][-1] == "recurrent_in"
    assert [o.name for o in model.graph.output][-1] == "recurrent_out"
    assert "Losses/Value Loss" in tb_scalars(tmp_path / "results/mem/Basic")
    r2 = learn([str(cfg2), *common, "--resume"], cwd=tmp_path, env=env_no_proxy)
    assert r2.returncode == 0, r2.stderr[-3000:]
    status = json.loads((tmp_path / "results/mem/run_logs/training_status.json").read_text())
    assert status["Basic"]["final_checkpoint"]["steps"] >= 900
