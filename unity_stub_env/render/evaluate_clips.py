"""``unity-stub-env --task dodge|mimic --evaluate POLICY --video DIR``: one named clip per scripted
case of the evaluation, for each policy named with ``--evaluate`` (not the baselines shown beside it):

  dodge  ``dodge-<policy>-NN-<side>-<body region>.mp4``: the 17 scripted throws (start side and the
         mark aimed at), one episode each (until the sphere passes or hits);
  mimic  ``mimic-<policy>-<motion>.mp4`` per reference motion and ``mimic-<policy>-stand-push-<N s>.mp4``
         per impulse of the push ladder, the evaluation's EVAL_SECONDS or until the ragdoll falls.

The cases are set up as the evaluation sets them (``tasks.dodge.scripted_throws``; mimic's
``motion``, ``rsi`` 0, ``push_impulse``/``push_interval`` and ``residual``)."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Callable

import numpy as np

from unity_stub_env.render import RenderError
from unity_stub_env.render.play import Player, film
from unity_stub_env.render.video import VideoWriter

FPS = 30.0
WIDTH, HEIGHT = 640, 480


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9.]+", "_", text).strip("_")


def _as_player_policy(actor: Callable, task) -> Callable:
    """An evaluation actor (float32 obs [n, o] -> continuous [n, c]) as a Player's act."""
    empty = np.zeros((task.num_agents, 0), np.int32)
    return lambda obs, mask: (np.asarray(actor(obs[0]), np.float32), empty)


def _clip(task, actor, path: Path, label: str, seconds: float | None, size: tuple[int, int], samples: int) -> str:
    player = Player(task, _as_player_policy(actor, task), 0, *size, label, samples)
    writer = VideoWriter(str(path), FPS)
    try:
        film(player, writer, FPS, seconds=seconds, episodes=1)
    finally:
        writer.close()
        player.close()
    return str(path)


def dodge_clips(actors: dict, seed: int, folder: Path, options: dict, size: tuple[int, int], samples: int) -> list[str]:
    from unity_stub_env.tasks.dodge import SCRIPTED_THROWS, DodgeTask, Throws, scripted_throws

    throws, written = scripted_throws(), []
    for name, actor in actors.items():
        for i, (side, mark) in enumerate(SCRIPTED_THROWS):
            task = DodgeTask(1, seed)
            rows = np.full(task.num_agents, i)
            task.launch(np.arange(task.num_agents), Throws(throws.start[rows], throws.target[rows], throws.speed[rows]))
            path = folder / f"dodge-{_slug(name)}-{i + 1:02d}-{side}-{_slug(mark)}.mp4"
            written.append(_clip(task, actor, path, f"dodge / {name}: throw {i + 1} {side} at {mark}", None, size, samples))
    return written


def mimic_clips(actors: dict, seed: int, folder: Path, options: dict, size: tuple[int, int], samples: int) -> list[str]:
    from unity_stub_env.tasks.base import EnvironmentParameters
    from unity_stub_env.tasks.mimic import EVAL_SECONDS, MOTIONS, PUSH_EVAL_INTERVAL, PUSH_LADDER, MimicTask

    cases = [(motion, {"motion": m}) for m, motion in enumerate(MOTIONS)]
    cases += [(f"stand-push-{impulse:g}Ns", {"motion": 0, "push_impulse": impulse,
                                             "push_interval": PUSH_EVAL_INTERVAL}) for impulse in PUSH_LADDER]
    written = []
    for name, actor in actors.items():
        for case, values in cases:
            params = EnvironmentParameters()
            rate = {key: options[key] for key in ("decision_hz", "effort_weight") if key in options}  # as evaluated
            for key, value in {"rsi": 0, "residual": options.get("residual", 0.0), **rate, **values}.items():
                params.set(key, lambda value=value: float(value))
            task = MimicTask(1, seed, params)
            path = folder / f"mimic-{_slug(name)}-{case}.mp4"
            written.append(_clip(task, actor, path, f"mimic / {name}: {case}", EVAL_SECONDS, size, samples))
    return written


CLIPS = {"dodge": dodge_clips, "mimic": mimic_clips}


def write(task_name: str, actors: dict, seed: int, folder: str, options: dict,
          size: tuple[int, int] = (WIDTH, HEIGHT), samples: int = 4) -> list[str]:
    """The clips of every actor (policy name -> actor) into ``folder`` (made if missing); samples:
    the renderer's antialiasing (``scene.MujocoView``)."""
    if task_name not in CLIPS:
        raise RenderError(f"--evaluate --video: task {task_name!r} has no scripted cases to film")
    path = Path(folder)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise RenderError(f"--video {folder!r}: cannot make that folder ({error.strerror})") from None
    return CLIPS[task_name](actors, seed, path, options, size, samples)
