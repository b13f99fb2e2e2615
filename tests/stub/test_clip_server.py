"""The renderer of --record-video (unity_stub_env/render/clip_server.py): one process answering clip
requests in turn, the run's environment parameters applied from the trainer's side-channel bytes
(the same frames as --env-param gives), the stub options that shape a clip, a bad request answered
without ending the process, and the CPU seconds it reports."""
from __future__ import annotations

import io
import json

import numpy as np
import pytest
from PIL import Image

from protos import side_channels as sc
from unity_stub_env.render import RenderError
from unity_stub_env.render.clip_server import describe_parameters, serve, stub_options
from unity_stub_env.render.play import play

SIZE = {"seconds": 0.5, "fps": 10, "width": 64, "height": 48, "samples": 0, "seed": 3}


def frames(path) -> list[np.ndarray]:
    gif = Image.open(path)
    out = []
    for index in range(gif.n_frames):
        gif.seek(index)
        out.append(np.asarray(gif.convert("RGB")))
    return out


def test_stub_options_of_a_clip():
    assert stub_options("dodge", []) == (1, None)  # independent figures: the followed one alone
    assert stub_options("ball3d", ["--agents-per-area", "3", "--decision-period", "2", "--spin-wait-ms", "1"]) == (3, 2)
    assert stub_options("soccer", []) == (None, None)  # players that play together stay
    with pytest.raises(RenderError, match="do not parse"):
        stub_options("ball3d", ["--decision-period", "often"])


def test_requests_are_filmed_in_turn_with_the_runs_environment_parameters(tmp_path):
    biped = sc.pack_messages([(sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID, sc.encode_env_float("creature_kind", 1.0))])
    requests = [
        {"task": "creature", "policy": "zero", "video": str(tmp_path / "default.gif"), **SIZE},
        {"task": "creature", "policy": "zero", "video": str(tmp_path / "biped.gif"), "side_channel": biped.hex(), **SIZE},
        {"task": "creature", "policy": "nonsense", "video": str(tmp_path / "bad.gif"), **SIZE},
        {"task": "creature", "policy": "zero", "video": str(tmp_path / "last.gif"), **SIZE},
    ]
    answers, log = io.StringIO(), io.StringIO()
    serve([json.dumps(r) + "\n" for r in requests], answers, log)
    replies = [json.loads(line) for line in answers.getvalue().splitlines()]
    assert [r["ok"] for r in replies] == [True, True, False, True]
    assert "unknown policy" in replies[2]["message"]
    assert "creature_kind=1" in replies[1]["message"] and "the task's defaults" in replies[0]["message"]
    cpu = [r["cpu"] for r in replies]
    assert all(r["clip_cpu"] >= 0 for r in replies) and cpu == sorted(cpu) and cpu[0] > 0
    # the side-channel bytes give the clip --env-param creature_kind=1 gives: a biped, not the quadruped
    play("creature", "zero", str(tmp_path / "cli.gif"), 0.5, None, 64, 48, 10, 3, ["creature_kind=1"], 0,
         samples=0, agents_per_area=1)
    default, biped_frames, cli = (frames(tmp_path / f"{n}.gif") for n in ("default", "biped", "cli"))
    assert biped_frames[0].shape == (48, 64, 3)  # (a GIF merges repeated frames: no count here)
    assert len(biped_frames) == len(cli) and all(np.array_equal(a, b) for a, b in zip(biped_frames, cli))
    assert not np.array_equal(default[-1], biped_frames[-1])


def test_describe_parameters():
    payloads = [(sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID, sc.encode_env_float("motion", 2.0)),
                (sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID, sc.encode_env_sampler("speed", "uniform", 5, (0.5, 1.5)))]
    assert describe_parameters(sc.pack_messages(payloads)) == "motion=2, speed~uniform(0.5, 1.5)"
    assert describe_parameters(b"") == "the task's defaults"
