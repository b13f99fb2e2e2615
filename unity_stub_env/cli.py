"""``unity-stub-env``: run a stub task as if it were a Unity player built with ML-Agents.

    unity-stub-env --task NAME --mlagents-port P [-nographics] [-batchmode] [-logFile F]
                   [--num-areas N] [--agents-per-area N] [--seed S] [--decision-period K]
                   [--connect-timeout T] [--spin-wait-ms MS] [--transport {http2,grpcio}]
    unity-stub-env --task mirror --spec behaviors.json --mlagents-port P    (or --task mirror=FILE)
    unity-stub-env --list
    unity-stub-env --task dodge|mimic --evaluate MODEL.onnx|zero|random|scripted [--episodes N] [--seed S] [--json F]
                   [--evaluate-option KEY=VALUE] [--video DIR]  (one clip per scripted case)
    unity-stub-env --task T --play MODEL.onnx|zero|random|scripted --video FILE.mp4|FILE.gif [--seconds S |
                   --episodes N] [--width W --height H --fps F --seed S --env-param K=V --agent K --stochastic]
    unity-stub-env --task basic|ball3d|... --record-demo OUT.demo --policy MODEL.onnx|scripted
                   [--demo-steps N] [--seed S] [--num-areas N] [--env-param KEY=NUMBER] [--demo-noise S]  (see unity_stub_env.record_demo)
    unity-stub-env hmm train CORPUS -o MODEL [--states N --restarts R --method fast|baum-welch --seed S]
    unity-stub-env hmm sample MODEL -n N --length L [--seed S]      (see unity_stub_env.hmm)
    unity-stub-env creature --kind quadruped|biped|lsystem --seed S [--mjcf OUT.xml]

Unity flags the stub does not know are ignored, as a player ignores them. Exit codes:
0 the trainer (status 400 / QUIT / gone) or a signal ended the run; 1 no trainer within
--connect-timeout, an incompatible trainer or a protocol error; 2 bad command line.

The stub reads no environment variable of its own (mlagents-like-learn passes its choices as flags);
MuJoCo's renderer reads MUJOCO_GL (unity_stub_env.render.gl).
"""
from __future__ import annotations

import argparse
import logging
import os
import resource
import signal
import sys

from protos.spec_file import SpecFile, SpecFileError
from unity_stub_env.academy import Academy, ActionCountError
from unity_stub_env.agents import EpisodeIdCounter, build_brain_parameters
from unity_stub_env.communicator import TRANSPORTS, RpcCommunicator, SessionEnd, SideChannelState, encode_stats
from unity_stub_env.launcher import spin_wait_args, transport_args, write_player_launcher
from unity_stub_env.task_names import MIRROR_TASK
from unity_stub_env.tasks import TASKS, EnvironmentParameters, make_task

logger = logging.getLogger("unity_stub_env")
_UNITY_FLAGS = {"-logfile": "-logFile", "-nographics": "-nographics", "-batchmode": "-batchmode"}
COMMAND_RESET = 1
COMMAND_QUIT = 2


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="unity-stub-env", allow_abbrev=False,
        description="A headless simulator that trains against any ML-Agents (comm API 1.5.0) trainer.")
    parser.add_argument("--task", action="append",
                        help=f"task to simulate: {', '.join(sorted(TASKS))}; repeat it (or separate "
                             "names with commas) for a scene with several behaviors")
    parser.add_argument("--spec", metavar="FILE", default=None,
                        help="--task mirror: the behaviors.json to replay (a run's run_logs/behaviors.json "
                             "or mlagents-like-learn --capture-spec FILE; docs/mirror.md)")
    parser.add_argument("--mlagents-port", type=int, default=None,
                        help="port of the trainer's gRPC server (a Unity player does not train without it)")
    parser.add_argument("--num-areas", type=int, default=None, help="override the trainer's num_areas")
    parser.add_argument("--agents-per-area", type=int, default=None, metavar="N",
                        help="agents in one area, for tasks whose agents are independent copies (ball3d, "
                             "dodge, ...): 1 makes a one-agent scene, as single-agent wrappers such as "
                             "UnityToGymWrapper need (default: the task's)")
    parser.add_argument("--seed", type=int, default=None, help="override the trainer's seed")
    parser.add_argument("--decision-period", type=int, default=None,
                        help="control steps between decisions (default: the task's)")
    parser.add_argument("--connect-timeout", type=float, default=60.0,
                        help="seconds to keep retrying the connection to the trainer (default 60)")
    parser.add_argument("--spin-wait-ms", type=float, default=0.0, metavar="MS",
                        help="poll for the trainer's answer up to MS ms past when it is due instead of "
                             "sleeping through it (saves the wake-up on a machine with a CPU to spare; "
                             "mlagents-like-learn passes it when it does; default 0 = always sleep)")
    parser.add_argument("--transport", choices=TRANSPORTS, default="http2",
                        help="the gRPC client: http2 (the stub's own, single-threaded; default) or grpcio "
                             "(mlagents-like-learn passes the transport its server uses)")
    parser.add_argument("--list", action="store_true", help="list the tasks with their specs and exit")
    parser.add_argument("--evaluate", action="append", metavar="POLICY", default=None,
                        help="run --task's scripted evaluation (no trainer) with POLICY: a trained .onnx, "
                             "'zero', 'random' (these two are always shown beside it) or 'scripted' (mimic's balance "
                             "expert); repeatable")
    parser.add_argument("--episodes", type=int, default=None,
                        help="--evaluate: dodge: random throws after the scripted ones (default 500); "
                             "mimic: trials per motion and push (default 32); --play: film until the "
                             "followed agent has finished N episodes")
    parser.add_argument("--json", dest="json_path", default=None, metavar="FILE",
                        help="--evaluate: also write the results as JSON to FILE")
    parser.add_argument("--evaluate-option", dest="evaluate_options", action="append", default=[],
                        metavar="KEY=VALUE", help="--evaluate: a task option for every policy, e.g. mimic's "
                                                  "residual=0.25 for a policy trained with that residual; repeatable")
    parser.add_argument("--play", metavar="POLICY", default=None,
                        help="play --task in-process (no trainer) with POLICY: a trained .onnx (deterministic "
                             "actions unless --stochastic), 'zero', 'random' or 'scripted' (basic, ball3d, mimic), "
                             "and film it to --video FILE (unity_stub_env.render.play)")
    parser.add_argument("--video", metavar="FILE|DIR", default=None,
                        help="--play: the clip to write, .mp4 (H.264) or .gif by its extension; "
                             "--evaluate: a folder for one clip per scripted case")
    parser.add_argument("--seconds", type=float, default=None,
                        help="--play: simulated seconds to film (default 10, or until --episodes)")
    parser.add_argument("--width", type=int, default=640, help="--play: frame width in pixels (default 640)")
    parser.add_argument("--height", type=int, default=480, help="--play: frame height in pixels (default 480)")
    parser.add_argument("--fps", type=float, default=30.0, help="--play: frames per simulated second (default 30)")
    parser.add_argument("--agent", type=int, default=0, metavar="K",
                        help="--play: the agent of the area the camera follows (default 0)")
    parser.add_argument("--stochastic", action="store_true",
                        help="--play MODEL.onnx: sample the actions instead of taking the deterministic ones")
    parser.add_argument("--antialias", type=int, default=4, metavar="SAMPLES",
                        help="--play: multisampling of MuJoCo's renderer (default 4; 0 draws ~3x faster on a CPU)")
    parser.add_argument("--tensorboard", metavar="DIR", default=None,
                        help="--play: also write the clip to DIR as a TensorBoard animated image (GIF) summary")
    parser.add_argument("--tensorboard-tag", default="clip", help="--tensorboard: the image's tag (default clip)")
    parser.add_argument("--tensorboard-step", type=int, default=0, help="--tensorboard: the summary's step")
    parser.add_argument("--record-demo", metavar="OUT.demo", default=None,
                        help="record a demonstration of --task in Unity's .demo format (no trainer) with "
                             "--policy, for behavioral_cloning and GAIL")
    parser.add_argument("--policy", default=None, metavar="MODEL.onnx|scripted",
                        help="--record-demo: a trained .onnx (deterministic actions) or 'scripted' (the "
                             "task's hand-written expert: basic, ball3d, mimic)")
    parser.add_argument("--env-param", dest="env_params", action="append", default=[], metavar="KEY=NUMBER",
                        help="--record-demo, --play: an environment parameter the task reads, e.g. mimic's "
                             "motion=2; repeatable")
    parser.add_argument("--demo-noise", type=float, default=0.0, metavar="SIGMA",
                        help="--record-demo: act with Gaussian noise of std SIGMA on the continuous actions "
                             "while recording the policy's own (DART; default 0)")
    parser.add_argument("--demo-steps", type=int, default=None, metavar="N",
                        help="--record-demo: record whole episodes until the file holds N steps (default 1000)")
    parser.add_argument("--write-launcher", metavar="DIR", default=None,
                        help="write DIR/Stub<Task>.x86_64, a Unity-build-like launcher of --task that "
                             "mlagents-learn --env DIR/Stub<Task> (or UnityEnvironment) can start, and exit")
    parser.add_argument("--crash-after", type=int, default=None, metavar="N",
                        help="fault injection for tests: exit with code 3 after N exchanges, "
                             "without closing the connection (like a crashed player)")
    parser.add_argument("-logFile", dest="log_file", default=None, help="write the log here ('-' = stdout)")
    parser.add_argument("-nographics", action="store_true", help="accepted; the stub never renders")
    parser.add_argument("-batchmode", action="store_true", help="accepted; the stub is always headless")
    return parser


def _normalise_unity_flags(argv: list[str]) -> list[str]:
    """Unity reads its own flags case-insensitively (``-logfile`` works too)."""
    return [_UNITY_FLAGS.get(arg.lower(), arg) if arg.startswith("-") and not arg.startswith("--") else arg
            for arg in argv]


def _configure_logging(log_file: str | None) -> None:
    if log_file in (None, "-"):
        handler: logging.Handler = logging.StreamHandler(sys.stdout if log_file == "-" else sys.stderr)
    else:
        handler = logging.FileHandler(log_file, mode="a")
    handler.setFormatter(logging.Formatter("%(asctime)s [%(levelname)s] %(message)s"))
    logger.handlers[:] = [handler]
    logger.setLevel(logging.INFO)
    logger.propagate = False


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "hmm":  # the HMM tools: unity-stub-env hmm train|sample ...
        from unity_stub_env.hmm import main as hmm_main

        return hmm_main(argv[1:])
    if argv and argv[0] == "creature":  # a generated creature's MJCF (unity_stub_env.creatures)
        from unity_stub_env.creatures import main as creature_main

        return creature_main(argv[1:])
    args, unknown = build_parser().parse_known_args(_normalise_unity_flags(argv))
    if args.list:
        for task_class in TASKS.values():
            print(task_class.describe())
        print(f"{MIRROR_TASK}: replays the behaviors of a behaviors.json given with --spec FILE (or "
              f"--task {MIRROR_TASK}=FILE) with learnable synthetic dynamics; see docs/mirror.md.")
        return 0
    args.tasks = [name for value in (args.task or []) for name in value.split(",") if name]
    for index, name in enumerate(args.tasks):  # --task mirror=FILE is --task mirror --spec FILE
        if name.startswith(MIRROR_TASK + "="):
            args.tasks[index], args.spec = MIRROR_TASK, name[len(MIRROR_TASK) + 1:]
    args.mirror = None
    if MIRROR_TASK in args.tasks:
        if args.spec is None:
            print("unity-stub-env: --task mirror needs --spec FILE (a behaviors.json, docs/mirror.md).",
                  file=sys.stderr)
            return 2
        try:
            args.mirror = SpecFile.load(args.spec)
        except SpecFileError as error:
            print(f"unity-stub-env: {error}", file=sys.stderr)
            return 2
    unknown_tasks = [name for name in args.tasks if name not in TASKS and name != MIRROR_TASK]
    if not args.tasks or unknown_tasks:
        print(f"unity-stub-env: unknown or missing --task {', '.join(unknown_tasks) or repr(None)}; "
              f"known tasks: {', '.join(sorted(TASKS))}, {MIRROR_TASK} (with --spec; see --list).", file=sys.stderr)
        return 2
    if len(set(args.tasks)) != len(args.tasks):
        print(f"unity-stub-env: each --task may appear once (got {', '.join(args.tasks)}): two copies "
              "would share one behavior name; use --num-areas for more agents.", file=sys.stderr)
        return 2
    if args.agents_per_area is not None:
        fixed = [name for name in args.tasks if name == MIRROR_TASK or TASKS[name].agents_interact]
        if fixed or args.agents_per_area < 1:
            print(f"unity-stub-env: --agents-per-area must be 1 or more and applies to tasks whose agents are "
                  f"independent; {', '.join(fixed) or args.agents_per_area} cannot take it (use --num-areas).",
                  file=sys.stderr)
            return 2
    if not args.spin_wait_ms >= 0:
        print(f"unity-stub-env: --spin-wait-ms must be 0 or more, got {args.spin_wait_ms:g}.", file=sys.stderr)
        return 2
    if args.play is not None:
        if len(args.tasks) != 1 or args.mirror is not None or args.video is None:
            print("unity-stub-env: --play takes exactly one --task and --video FILE.mp4|FILE.gif.", file=sys.stderr)
            return 2
        from unity_stub_env.render.play import run as run_play

        return run_play(args)
    if args.evaluate:
        if len(args.tasks) != 1 or args.mirror is not None:
            print("unity-stub-env: --evaluate takes exactly one --task.", file=sys.stderr)
            return 2
        from unity_stub_env.evaluate import run as run_evaluation

        return run_evaluation(args.tasks[0], args.evaluate, args.seed or 0, args.episodes, args.json_path,
                              args.evaluate_options, args.video)
    if args.record_demo is not None:
        if len(args.tasks) != 1 or args.mirror is not None or args.policy is None:
            print("unity-stub-env: --record-demo takes exactly one --task and --policy MODEL.onnx|scripted.",
                  file=sys.stderr)
            return 2
        from unity_stub_env.record_demo import run as run_recording

        return run_recording(args.tasks[0], args.record_demo, args.policy, args.demo_steps, args.seed or 0,
                             args.num_areas, args.env_params, args.demo_noise)
    if args.write_launcher is not None:
        spec = ["--spec", os.path.abspath(args.spec)] if args.mirror is not None else []
        agents = ["--agents-per-area", str(args.agents_per_area)] if args.agents_per_area is not None else []
        path = write_player_launcher(args.write_launcher, args.tasks, extra_args=spin_wait_args(
            args.spin_wait_ms / 1e3) + transport_args(args.transport) + spec + agents)
        print(f"{path}  (use --env {path.with_suffix('')})")
        return 0
    if args.mlagents_port is None:
        print("unity-stub-env: no --mlagents-port given. A Unity player started without it does not "
              "train; pass the trainer's port, e.g. --mlagents-port 5005.", file=sys.stderr)
        return 2
    _configure_logging(args.log_file)
    if unknown:
        logger.info("Ignoring unknown flags: %s", " ".join(unknown))
    logger.info("Trainer port %d, %s client, polling up to %g ms for its answers", args.mlagents_port,
                args.transport, args.spin_wait_ms)
    communicator = RpcCommunicator(args.mlagents_port, args.connect_timeout, args.spin_wait_ms / 1e3,
                                   args.transport)
    signal.signal(signal.SIGTERM, communicator.request_stop)
    signal.signal(signal.SIGINT, communicator.request_stop)
    try:
        run_session(communicator, args)
    except SessionEnd as end:
        (logger.info if end.exit_code == 0 else logger.error)("%s", end)
        if end.exit_code and args.log_file is not None:
            print(f"unity-stub-env: {end}", file=sys.stderr)
        return end.exit_code
    except ActionCountError as error:
        logger.error("%s", error)
        if args.log_file is not None:
            print(f"unity-stub-env: {error}", file=sys.stderr)
        communicator.close(send_closing=True)
        return 1
    finally:
        _log_cpu_time()
        logging.shutdown()
    return 0


def _log_cpu_time() -> None:
    """The process's own CPU time, last in the log: bench/train.py subtracts it from a whole
    training run's CPU to compare what each trainer itself costs."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    logger.info("CPU time %.2f s (user %.2f s, system %.2f s)",
                usage.ru_utime + usage.ru_stime, usage.ru_utime, usage.ru_stime)


def run_session(communicator: RpcCommunicator, args: argparse.Namespace) -> None:
    """Handshake, build the task from the trainer's seed/num_areas, then step until told to stop."""
    communicator.connect()
    init_input, first_input = communicator.initialize()
    seed = args.seed if args.seed is not None else init_input.seed
    num_areas = args.num_areas if args.num_areas is not None else max(init_input.num_areas, 1)
    env_params = EnvironmentParameters()
    side_channels = SideChannelState(env_params)
    side_channels.apply(first_input.side_channel)
    if first_input.command == COMMAND_QUIT:
        communicator.close(send_closing=False)
        raise SessionEnd("The trainer sent QUIT.", 0)
    counter = EpisodeIdCounter()  # process-wide, like Unity's
    academies = []
    tasks = []
    for index, name in enumerate(args.tasks):  # one behavior per task, like a scene with several
        if name == MIRROR_TASK:  # one task per behavior of the spec file
            from unity_stub_env.tasks.mirror import mirror_tasks

            tasks += mirror_tasks(args.mirror, num_areas, seed + index, env_params)
        else:
            tasks.append(make_task(name, num_areas=num_areas, seed=seed + index, env_params=env_params,
                                   agents_per_area=args.agents_per_area))
    for task in tasks:
        academy = Academy(task, args.decision_period, counter)  # construction is the first RESET
        brains = {key: build_brain_parameters(key, task.action_spec) for key, _ in academy.behaviors}
        academies.append((academy, brains))
        logger.info("Task %s: %s %s, %d agents (%d areas), seed %d, decision period %d",
                    task.name, "behavior" if len(brains) == 1 else "behaviors", ", ".join(brains), task.num_agents, num_areas, task.seed,
                    academy.decision_period)
    exchanges = 0
    while True:
        if args.crash_after is not None and exchanges >= args.crash_after:
            logger.error("Crashing on purpose after %d exchanges (--crash-after).", exchanges)
            logging.shutdown()
            os._exit(3)
        exchanges += 1
        batches = [(key, infos, brains[key]) for academy, brains in academies
                   for key, infos in academy.collect_batches()]
        stats = [stat for academy, _ in academies for stat in academy.take_stats()]
        rl_input = communicator.exchange_many(batches, encode_stats(stats))
        side_channels.apply(rl_input.side_channel)
        if rl_input.command == COMMAND_QUIT:
            communicator.close(send_closing=False)
            raise SessionEnd("The trainer sent QUIT.", 0)
        if rl_input.command == COMMAND_RESET:
            logger.info("Environment reset by the trainer")
            for academy, _ in academies:
                academy.environment_reset()
            continue
        for academy, _ in academies:
            for index, (key, _) in enumerate(academy.behaviors):
                academy.apply_action_list(rl_input.agent_actions.get(key), index)
            academy.advance()


def entry() -> None:
    """The executable: ``main``, then an immediate exit, like a Unity player quitting. The log
    is flushed and closed and the connection answered by then; skipping the interpreter's
    teardown of numpy and MuJoCo (~50 ms, measured) lets the trainer finish that much sooner."""
    code = main()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


if __name__ == "__main__":
    entry()
