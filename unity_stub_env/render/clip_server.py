"""``python -m unity_stub_env.render.clip_server``: one long-lived process that films a training
run's checkpoints (mlagents-like-learn ``--record-video``), one clip per request.

The trainer starts it once per run (at nice 19) and writes one JSON request per line to its stdin;
it films each with ``play`` and answers one JSON line on stdout. MuJoCo, onnxruntime, the encoder
and TensorBoard's writer are imported once, not once per clip (docs/video.md, "Clips while
training"). A request::

    {"task": "ball3d", "policy": "MODEL.onnx", "video": "OUT.mp4", "seconds": 10, "fps": 20,
     "width": 320, "height": 240, "samples": 0, "seed": 1, "tensorboard": ["DIR", "TAG", STEP],
     "side_channel": "HEX", "stub_args": ["--decision-period", "5"]}

``side_channel``: the environment-parameter messages the trainer sends its simulators (hex), so the
clip plays the run's parameters and lessons; ``stub_args``: the run's ``--env-args`` for the stub,
of which the options that shape the task (``--agents-per-area``, ``--decision-period``) apply
(``stub_options``: one agent of a task whose agents are independent, unless the run chose).
The answer: ``{"ok": bool, "message": str, "clip_cpu": s, "cpu": s}``: the clip's own CPU seconds
and this process's total so far (its start-up included), each counting the encoder processes it
waited for; the trainer's CPU budget reads them. End of input: the process exits.
"""
from __future__ import annotations

import json
import resource
import sys

CPU_FIELDS = (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)


def cpu_seconds() -> float:
    """This process's CPU time, user and system, with that of the children it has waited for (the
    ffmpeg encoder of each clip)."""
    return sum(u.ru_utime + u.ru_stime for u in map(resource.getrusage, CPU_FIELDS))


def stub_options(task: str, stub_args: list[str]) -> tuple[int | None, int | None]:
    """(agents_per_area, decision_period) of a clip: the stub arguments of the training run, read by
    the stub's own parser (its other options do not change what a clip shows). A task whose agents
    are independent copies (ball3d's 12 plates, dodge's 14 figures) is filmed with the one agent the
    camera follows unless the run chose a number: the same picture of that agent at about half the
    CPU (dodge, mimic)."""
    from unity_stub_env.cli import build_parser
    from unity_stub_env.tasks import TASKS

    from unity_stub_env.render import RenderError

    try:
        known, _ = build_parser().parse_known_args(stub_args)
    except SystemExit:  # argparse's message is in the log already
        raise RenderError(f"the run's stub arguments {' '.join(stub_args)!r} do not parse") from None
    agents = known.agents_per_area
    if agents is None and task in TASKS and not TASKS[task].agents_interact:
        agents = 1
    return agents, known.decision_period


def film_request(request: dict) -> str:
    """Film one request; the line ``play`` reports. RenderError for anything unusable."""
    from unity_stub_env.render.play import play

    agents_per_area, decision_period = stub_options(request["task"], list(request.get("stub_args") or []))
    tensorboard = request.get("tensorboard")
    side_channel = bytes.fromhex(request.get("side_channel") or "")
    result = play(request["task"], request["policy"], request["video"], seconds=float(request["seconds"]),
                  width=int(request["width"]), height=int(request["height"]), fps=float(request["fps"]),
                  seed=int(request["seed"]), tensorboard=None if tensorboard is None else tuple(tensorboard),
                  samples=int(request["samples"]), side_channel=side_channel, agents_per_area=agents_per_area,
                  decision_period=decision_period)
    returns = ", ".join(f"{r:+.2f}" for r in result.episode_returns) or "none finished"
    return (f"Wrote {request['video']}: {result.frames} frames, {result.steps} control steps; episode returns: "
            f"{returns}; environment parameters: {describe_parameters(side_channel)}")


def describe_parameters(side_channel: bytes) -> str:
    """``key=value`` (a constant) or ``key~sampler(values)`` per environment parameter, for the log."""
    from protos import side_channels as sc

    parameters = [sc.decode_env_parameter(payload) for channel, payload in sc.unpack_messages(side_channel)
                  if channel == sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID]
    return ", ".join(f"{key}={p.values[0]:g}" if p.kind == "float" else f"{key}~{p.kind}{p.values}"
                     for key, p in parameters) or "the task's defaults"


def serve(requests, answers, log) -> None:
    """Answer each request line of ``requests`` on ``answers``; a failed clip is logged and answered
    with ok false, and the next request is served."""
    from unity_stub_env.render import RenderError

    import unity_stub_env.render.play  # noqa: F401  (the imports, before the first request's clock)

    for line in requests:
        if not line.strip():
            continue
        before = cpu_seconds()
        try:
            ok, message = True, film_request(json.loads(line))
        except RenderError as error:
            ok, message = False, str(error)
        except Exception as error:  # a broken clip must not end the run's clips: logged, answered
            import traceback

            traceback.print_exc(file=log)
            ok, message = False, f"{type(error).__name__}: {error}"
        print(message, file=log, flush=True)
        after = cpu_seconds()
        answers.write(json.dumps({"ok": ok, "message": message, "clip_cpu": after - before, "cpu": after}) + "\n")
        answers.flush()


def main() -> int:
    import os

    # the answers get the original stdout; anything else written there (a library's print, a C
    # warning) goes to stderr, the trainer's clips.log, and cannot garble an answer
    answers = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    serve(sys.stdin, answers, sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
