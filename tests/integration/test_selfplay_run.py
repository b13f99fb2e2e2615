"""Self-play end to end on the soccer stub (two behaviors Soccer?team=0/1 over real gRPC):
only the learning team trains, Self-play/ELO in TensorBoard, --resume keeps the ELO and the
snapshot window, and the same layer works with SAC and POCA."""
from __future__ import annotations

import json
import textwrap

import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from tests.integration.conftest import free_port_block, learn
from trainer.artifacts.checkpoints import load_checkpoint

PPO_SELFPLAY = """
behaviors:
  Soccer:
    trainer_type: ppo
    hyperparameters: {{batch_size: 64, buffer_size: 512, learning_rate: 1.0e-3, num_epoch: 2}}
    network_settings: {{hidden_units: 32, num_layers: 1}}
    checkpoint_interval: 1000000
    max_steps: {max_steps}
    time_horizon: 32
    summary_freq: 1000
    self_play: {{save_steps: 500, swap_steps: 200, team_change: 2000, window: 20,
                play_against_latest_model_ratio: 0.5, initial_elo: {initial_elo}}}
"""


def config(tmp_path, name: str, max_steps: int, initial_elo: float = 1200.0, text: str = PPO_SELFPLAY) -> str:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text.format(max_steps=max_steps, initial_elo=initial_elo)))
    return str(path)


def elo_scalars(folder) -> list[tuple[int, float]]:
    acc = EventAccumulator(str(folder), size_guidance={"scalars": 0})
    acc.Reload()
    return [(e.step, e.value) for e in acc.Scalars("Self-play/ELO")] if "Self-play/ELO" in acc.Tags()["scalars"] else []


def test_resume_keeps_the_elo_and_the_window_and_only_one_team_trains(tmp_path, env_no_proxy):
    res = tmp_path / "results"
    common = ["--env", "stub:soccer", "--num-areas", "8", "--seed", "3", "--results-dir", str(res),
              "--run-id", "sp", "--base-port", str(free_port_block())]
    r = learn([config(tmp_path, "a.yaml", 3000), *common], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    first = load_checkpoint(res / "sp/Soccer/checkpoint.pt")
    sp1 = first["SelfPlay"]
    step1 = int(first["global_step"]["step"])
    # the other team's experience was counted, not trained on: about as many steps as the learner's
    ghost1 = int(sp1["counters"][2])
    assert 0.8 * step1 <= ghost1 <= 1.2 * step1, (ghost1, step1)
    n1 = len(sp1["snapshots"])
    assert n1 == 1 + step1 // 500 or n1 == step1 // 500, n1  # the first, then one per > 500 steps
    status = json.loads((res / "sp/run_logs/training_status.json").read_text())
    assert status["Soccer"]["elo"] == float(sp1["elos"][-1])
    elo1 = elo_scalars(res / "sp/Soccer")
    assert elo1 and all(1100 < v < 1300 for _, v in elo1), elo1

    # resumed with another initial_elo: the saved rating continues, initial_elo is not used
    r = learn([config(tmp_path, "b.yaml", 6000, initial_elo=1500.0), *common, "--resume"],
              cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    sp2 = load_checkpoint(res / "sp/Soccer/checkpoint.pt")["SelfPlay"]
    assert len(sp2["snapshots"]) > n1
    for old, new in zip(sp1["snapshots"], sp2["snapshots"][:n1]):  # the window went on, not restarted
        assert old.keys() == new.keys() and all(torch.equal(old[k], new[k]) for k in old)
    assert int(sp2["counters"][2]) > ghost1
    elo2 = elo_scalars(res / "sp/Soccer")
    after = [v for s, v in elo2 if s > step1]
    assert after and all(abs(v - float(sp1["elos"][-1])) < 100 for v in after), (sp1["elos"][-1], after)
    assert all(v < 1400 for v in after)  # 1500 would mean the rating restarted from initial_elo


SAC_SELFPLAY = """
behaviors:
  Soccer:
    trainer_type: sac
    hyperparameters: {{batch_size: 64, buffer_size: 20000, learning_rate: 3.0e-4, buffer_init_steps: 0,
                      steps_per_update: 10.0, init_entcoef: 0.05}}
    network_settings: {{hidden_units: 32, num_layers: 1}}
    checkpoint_interval: 1000000
    max_steps: {max_steps}
    time_horizon: 16
    summary_freq: 1000
    self_play: {{save_steps: 500, swap_steps: 200, team_change: 1500, window: 5, initial_elo: {initial_elo}}}
"""


def test_selfplay_with_sac(tmp_path, env_no_proxy):
    res = tmp_path / "results"
    r = learn([config(tmp_path, "s.yaml", 3000, text=SAC_SELFPLAY), "--env", "stub:soccer", "--num-areas", "8",
               "--seed", "4", "--results-dir", str(res), "--run-id", "sac", "--base-port", str(free_port_block())],
              cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "team 1 learns now" in r.stdout + r.stderr  # team_change 1500 < 3000 steps
    state = load_checkpoint(res / "sac/Soccer/checkpoint.pt")
    step = int(state["global_step"]["step"])
    assert len(state["SelfPlay"]["snapshots"]) >= 5  # the window of 5 filled (one per > 500 steps)
    assert 0.8 * step <= int(state["SelfPlay"]["counters"][2]) <= 1.2 * step
    assert (res / "sac/Soccer.onnx").is_file()


POCA_SELFPLAY = PPO_SELFPLAY.replace("trainer_type: ppo", "trainer_type: poca")


def test_selfplay_with_poca_swaps_writes_elo_and_resume_keeps_the_window(tmp_path, env_no_proxy):
    """trainer_type poca under self_play on soccer (each player is a group of one, as an agent without
    a group is in the reference): the other team plays snapshots, Self-play/ELO is written, the
    team changes, --resume continues the window and the rating."""
    assert "trainer_type: poca" in POCA_SELFPLAY
    res = tmp_path / "results"
    common = ["--env", "stub:soccer", "--num-areas", "8", "--seed", "5", "--results-dir", str(res),
              "--run-id", "poca", "--base-port", str(free_port_block())]
    r = learn([config(tmp_path, "p.yaml", 3000, text=POCA_SELFPLAY), *common], cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    assert "team 1 learns now" in r.stdout + r.stderr  # team_change 2000 < 3000 steps
    first = load_checkpoint(res / "poca/Soccer/checkpoint.pt")
    assert any(key.startswith("attention.") for key in first["Optimizer:critic"])  # POCA's critic trained
    sp1 = first["SelfPlay"]
    step1 = int(first["global_step"]["step"])
    assert 0.8 * step1 <= int(sp1["counters"][2]) <= 1.2 * step1  # the ghost team's steps, counted only
    n1 = len(sp1["snapshots"])
    assert n1 >= step1 // 500 >= 5, (n1, step1)
    elo1 = elo_scalars(res / "poca/Soccer")
    assert elo1 and all(1100 < v < 1300 for _, v in elo1), elo1
    assert len({round(v, 3) for _, v in elo1}) > 1, elo1  # games were rated: the rating moved

    r = learn([config(tmp_path, "q.yaml", 5000, initial_elo=1500.0, text=POCA_SELFPLAY), *common, "--resume"],
              cwd=tmp_path, env=env_no_proxy)
    assert r.returncode == 0, r.stderr[-3000:]
    sp2 = load_checkpoint(res / "poca/Soccer/checkpoint.pt")["SelfPlay"]
    assert len(sp2["snapshots"]) > n1
    for old, new in zip(sp1["snapshots"], sp2["snapshots"][:n1]):
        assert old.keys() == new.keys() and all(torch.equal(old[k], new[k]) for k in old)
    after = [v for s, v in elo_scalars(res / "poca/Soccer") if s > step1]
    assert after and all(abs(v - float(sp1["elos"][-1])) < 100 for v in after), (sp1["elos"][-1], after)
    assert (res / "poca/Soccer.onnx").is_file()
