"""Protocol benchmark (run by hand, not a test): how fast does the trainer side talk to a simulator?

    .venv/bin/python bench/protocol.py [--exchanges 2000] [--warmup 200] [--profile]

Measures, in one run on the same machine:
  (i)   our UnityEndpoint answering every step with a preallocated all-zero ActionTuple, against
        the stub ``basic`` running as a separate process (``--num-areas`` 16 and 64 agents);
  (ii)  the real mlagents_envs 1.1.0 UnityEnvironment (in .venv-interop, its own process) with
        random actions against the same stub and agent counts (bench/envs_api.py runs our
        mlagents_like_envs UnityEnvironment through the very same loop against it);
  (iii) the stub's raw task steps/s without any protocol (make_task + step loop) for basic and
        ball3d, and ball3d through the protocol, to express protocol overhead as a percentage of
        ball3d physics time per decision (decision_period physics steps).
Prints a markdown table and the target checks, and writes JSON to bench/out/protocol-<time>.json.
Targets: (i) >= 5x (ii); protocol overhead <= 15 % of ball3d physics time.
``--profile`` adds cProfile tables of the trainer loop and of the stub process (basic, 64 agents).
"""
from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import platform
import pstats
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from trainer.envs.cpus import spin_budget  # noqa: E402
from trainer.protocol.server import UnityEndpoint  # noqa: E402
from unity_stub_env import make_task  # noqa: E402
from trainer.config.env_vars import EnvVars  # noqa: E402
from unity_stub_env.launcher import spin_wait_args, transport_args, write_player_launcher  # noqa: E402

INTEROP_PYTHON = REPO / ".venv-interop" / "bin" / "python"
PEER = Path(__file__).resolve().parent / "peers" / "mlagents_envs_rollout.py"
OUT = Path(__file__).resolve().parent / "out"
AGENTS_PER_AREA = {"basic": 1, "ball3d": 12}
# as mlagents-like-learn decides for one simulator; the stub gets the same flag under
# mlagents_envs (ii), so both trainers face the same simulator
SPIN_WAIT = spin_budget(2, EnvVars.from_environ().spin_wait_s)
STUB_FLAGS = spin_wait_args(SPIN_WAIT)


def transport() -> str:
    """MLAGENTS_LIKE_TRANSPORT as a run would read it, at each call (bench/transport.py sets it
    between runs): the endpoint's server and, by flag, the stub's client."""
    return EnvVars.from_environ().transport


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def launch_stub(task: str, port: int, num_areas: int, profile_to: Path | None = None,
                physics_to: Path | None = None) -> subprocess.Popen:
    """The stub as its own process, optionally under ``cProfile -o profile_to``, or with its
    physics timed per decision into ``physics_to`` (bench/peers/timed_stub.py)."""
    command = [sys.executable]
    if profile_to is not None:
        command += ["-m", "cProfile", "-o", str(profile_to), "-m", "unity_stub_env.cli"]
    elif physics_to is not None:
        command += [str(Path(__file__).parent / "peers" / "timed_stub.py"), str(physics_to)]
    else:
        command += ["-m", "unity_stub_env.cli"]
    command += ["--task", task, *STUB_FLAGS, *transport_args(transport()), "--mlagents-port", str(port),
                "--num-areas", str(num_areas), "-nographics", "-batchmode", "-logFile", os.devnull]
    return subprocess.Popen(command, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def bench_endpoint(task: str, num_areas: int, warmup: int, exchanges: int,
                   profile: bool = False, stub_profile: Path | None = None) -> dict:
    """(i): UnityEndpoint ⇄ stub process, zero-cost actions. Returns timing and counts."""
    port = free_port()
    endpoint = UnityEndpoint(port=port, timeout_wait=60.0, spin_wait=SPIN_WAIT,
                             transport=transport())
    endpoint.start()
    physics_file = Path(tempfile.mkstemp(prefix="stub_physics_", suffix=".json")[1])
    stub = launch_stub(task, port, num_areas, stub_profile, None if stub_profile else physics_file)
    endpoint.is_alive = lambda: stub.poll() is None
    profiler = cProfile.Profile() if profile else None
    try:
        endpoint.handshake(seed=0, num_areas=num_areas)
        result = endpoint.reset(b"")
        (behavior,) = result.steps
        deciding = len(result.steps[behavior][0])
        actions = {behavior: endpoint.behavior_specs[behavior].action_spec.empty_action(deciding)}
        for _ in range(warmup):
            result = endpoint.step(actions)
        agent_steps = 0
        if profiler:
            profiler.enable()
        started = time.perf_counter()
        for _ in range(exchanges):
            result = endpoint.step(actions)
            agent_steps += len(result.steps[behavior][0])
        seconds = time.perf_counter() - started
        if profiler:
            profiler.disable()
    finally:
        endpoint.close()
        stub.wait(timeout=30)
    out = {"exchanges": exchanges, "seconds": seconds, "agent_steps": agent_steps}
    try:
        durations = json.loads(physics_file.read_text() or "[]")
    except (OSError, ValueError):
        durations = []
    physics_file.unlink(missing_ok=True)
    if len(durations) >= exchanges:  # the stub's physics during the timed exchanges (the last ones)
        out["stub_physics_seconds"] = sum(durations[-exchanges:])
    if profiler:
        out["profile"] = profiler
    return out


def bench_mlagents_envs(task: str, num_areas: int, warmup: int, exchanges: int,
                        package: str = "mlagents_envs") -> dict | None:
    """(ii): the real UnityEnvironment in .venv-interop with random actions (None if that venv is
    missing), or with ``package="mlagents_like_envs"`` ours, in this venv, through the same loop."""
    ours = package != "mlagents_envs"
    if not ours and not INTEROP_PYTHON.exists():
        return None
    with tempfile.TemporaryDirectory() as folder:
        exe = write_player_launcher(folder, [task], extra_args=STUB_FLAGS + transport_args(transport()))
        options = {"file_name": str(exe.with_suffix("")), "base_port": free_port(),
                   "num_areas": num_areas, "warmup": warmup, "exchanges": exchanges, "package": package}
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        if ours:
            env["PYTHONPATH"] = str(REPO)
        python = sys.executable if ours else str(INTEROP_PYTHON)
        completed = subprocess.run([python, str(PEER), json.dumps(options)], cwd=folder,
                                   capture_output=True, text=True, timeout=900, env=env)
    if completed.returncode != 0:
        raise RuntimeError(f"{package} rollout failed:\n{completed.stderr[-3000:]}")
    return json.loads(completed.stdout.strip().splitlines()[-1])


def bench_raw_physics(task_name: str, num_areas: int, decisions: int) -> dict:
    """(iii): the task alone: ``decisions * decision_period`` step() calls with zero actions,
    finished agents reset like the academy does. No protos, no gRPC."""
    task = make_task(task_name, num_areas=num_areas, seed=0)
    task.reset()
    continuous = np.zeros((task.num_agents, task.action_spec.continuous_size), dtype=np.float32)
    discrete = np.zeros((task.num_agents, len(task.action_spec.discrete_branches)), dtype=np.int32)
    steps = decisions * task.decision_period
    started = time.perf_counter()
    for _ in range(steps):
        outcome = task.step(continuous, discrete)
        if outcome.done.any():
            task.reset(outcome.done)
    seconds = time.perf_counter() - started
    return {"steps": steps, "decisions": decisions, "seconds": seconds,
            "agent_steps": steps * task.num_agents, "decision_period": task.decision_period}


def bench_breakdown(task_name: str, num_areas: int, exchanges: int) -> dict:
    """Per-exchange cost of each protocol piece, in one process and without gRPC (ms).

    Replays what both ends do around one exchange, with the stub's own Academy and our codec:
    stub physics (advance), stub encode (collect_encoded + step_message_bytes),
    trainer decode (codec.decode_message), trainer encode (codec.encode_answer),
    stub decode (parse + apply_action_list). Whatever the real run takes beyond the sum is gRPC
    transport plus thread/process hand-offs.
    """
    from protos.communicator_objects import unity_message_pb2
    from trainer.protocol import codec
    from unity_stub_env.academy import Academy
    from unity_stub_env.agents import build_brain_parameters
    from unity_stub_env.communicator import step_message_bytes

    task = make_task(task_name, num_areas=num_areas, seed=0)
    academy = Academy(task)
    spec_key = academy.behavior_key
    known: dict = {}
    totals = dict.fromkeys(("stub_physics", "stub_encode", "trainer_decode", "trainer_encode", "stub_decode"), 0.0)
    clock = time.perf_counter
    brains = [build_brain_parameters(spec_key, task.action_spec)]  # sent with the first message only
    for _ in range(exchanges):
        t0 = clock()
        wire_up = step_message_bytes([(spec_key, academy.collect_encoded().data)], b"", [] if known else brains)
        t1 = clock()
        result = codec.decode_message(wire_up, known).result  # as UnityEndpoint._wait_for_call
        known.update(result.specs)
        deciding = len(result.steps[spec_key][0])
        actions = {spec_key: known[spec_key].action_spec.empty_action(deciding)}
        t2 = clock()
        wire_down = codec.encode_answer(actions, b"")
        t3 = clock()
        answer = unity_message_pb2.UnityMessageProto.FromString(wire_down)
        academy.apply_action_list(answer.unity_input.rl_input.agent_actions.get(spec_key))
        t4 = clock()
        academy.advance()
        t5 = clock()
        totals["stub_encode"] += t1 - t0
        totals["trainer_decode"] += t2 - t1
        totals["trainer_encode"] += t3 - t2
        totals["stub_decode"] += t4 - t3
        totals["stub_physics"] += t5 - t4
    return {key: 1e3 * value / exchanges for key, value in totals.items()}


def rate(record: dict, key: str) -> float:
    return record[key] / record["seconds"]


def run(args) -> dict:
    report: dict = {"when": time.strftime("%Y-%m-%d %H:%M:%S"), "python": platform.python_version(),
                    "cpu_count": os.cpu_count(), "warmup": args.warmup, "exchanges": args.exchanges,
                    "rows": {}}
    rows = report["rows"]
    for areas in args.areas:
        rows[f"ours basic x{areas}"] = bench_endpoint("basic", areas, args.warmup, args.exchanges)
        mlagents = bench_mlagents_envs("basic", areas, args.warmup, args.exchanges)
        if mlagents is not None:
            rows[f"mlagents_envs basic x{areas}"] = mlagents
        rows[f"raw basic x{areas}"] = bench_raw_physics("basic", areas, args.exchanges)
    for ball_areas in args.ball3d_areas:
        rows[f"ours ball3d x{ball_areas * 12}"] = bench_endpoint("ball3d", ball_areas, args.warmup, args.exchanges)
        rows[f"raw ball3d x{ball_areas * 12}"] = bench_raw_physics("ball3d", ball_areas, args.exchanges)
    for record in rows.values():
        record["exchanges_per_s"] = rate(record, "exchanges") if "exchanges" in record else None
        record["agent_steps_per_s"] = rate(record, "agent_steps")
    report["ratios"] = {
        f"x{a}": rows[f"ours basic x{a}"]["exchanges_per_s"] / rows[f"mlagents_envs basic x{a}"]["exchanges_per_s"]
        for a in args.areas if f"mlagents_envs basic x{a}" in rows
    }
    report["ball3d"] = {}
    for ball_areas in args.ball3d_areas:
        agents = ball_areas * 12
        ours_ball, raw_ball = rows[f"ours ball3d x{agents}"], rows[f"raw ball3d x{agents}"]
        per_exchange = ours_ball["seconds"] / ours_ball["exchanges"]
        raw_physics = raw_ball["seconds"] / raw_ball["decisions"]
        # primary: the stub's own physics time during the very exchanges we timed (same run,
        # same machine state); the raw loop (separate run) is kept for reference
        in_run = ours_ball.get("stub_physics_seconds")
        physics_per_decision = in_run / ours_ball["exchanges"] if in_run else raw_physics
        report["ball3d"][f"x{agents}"] = {
            "seconds_per_exchange": per_exchange, "physics_seconds_per_decision": physics_per_decision,
            "physics_measured": "in the stub during the timed exchanges" if in_run else "raw loop",
            "raw_physics_seconds_per_decision": raw_physics,
            "overhead_percent": 100.0 * (per_exchange - physics_per_decision) / physics_per_decision,
            "overhead_vs_raw_percent": 100.0 * (per_exchange - raw_physics) / raw_physics,
            "breakdown_ms": bench_breakdown("ball3d", ball_areas, min(args.exchanges, 500)),
        }
    report["basic_breakdown_ms"] = {
        f"x{a}": bench_breakdown("basic", a, min(args.exchanges, 500)) for a in args.areas
    }
    return report


def markdown(report: dict) -> str:
    lines = ["| run | exchanges/s | agent-steps/s | physics steps/s |", "|---|---:|---:|---:|"]
    for name, record in report["rows"].items():
        exchanges = f"{record['exchanges_per_s']:,.0f}" if record.get("exchanges_per_s") else "—"
        physics = f"{record['steps'] / record['seconds']:,.0f}" if "steps" in record else "—"
        lines.append(f"| {name} | {exchanges} | {record['agent_steps_per_s']:,.0f} | {physics} |")
    lines.append("")
    for key, ratio in report["ratios"].items():
        verdict = "meets" if ratio >= 5 else "MISSES"
        lines.append(f"* ours / mlagents_envs, basic {key}: **{ratio:.2f}x** ({verdict} the >= 5x target)")
    for key, ball in report["ball3d"].items():
        verdict = "meets" if ball["overhead_percent"] <= 15 else "MISSES"
        lines.append(
            f"* ball3d {key}: {ball['seconds_per_exchange'] * 1e3:.3f} ms per exchange vs "
            f"{ball['physics_seconds_per_decision'] * 1e3:.3f} ms physics per decision "
            f"({ball['physics_measured']}) -> protocol overhead **{ball['overhead_percent']:.1f} %** "
            f"({verdict} the <= 15 % target); against the raw loop's "
            f"{ball['raw_physics_seconds_per_decision'] * 1e3:.3f} ms: {ball['overhead_vs_raw_percent']:.1f} %")
    lines += ["", "Per-exchange breakdown in one process without gRPC (ms); "
              "'gRPC + hand-offs' = measured exchange time minus the pieces:", "",
              "| run | stub physics | stub encode | trainer decode | trainer encode | stub decode | gRPC + hand-offs |",
              "|---|---:|---:|---:|---:|---:|---:|"]
    measured = {f"ball3d {k}": v["seconds_per_exchange"] * 1e3 for k, v in report["ball3d"].items()}
    pieces = {f"ball3d {k}": v["breakdown_ms"] for k, v in report["ball3d"].items()}
    for key, parts in report["basic_breakdown_ms"].items():
        pieces[f"basic {key}"] = parts
        measured[f"basic {key}"] = 1e3 / report["rows"][f"ours basic {key}"]["exchanges_per_s"]
    for name, parts in pieces.items():
        rest = measured[name] - sum(parts.values())
        cells = " | ".join(f"{parts[k]:.3f}" for k in
                           ("stub_physics", "stub_encode", "trainer_decode", "trainer_encode", "stub_decode"))
        lines.append(f"| {name} | {cells} | {rest:.3f} |")
    return "\n".join(lines)


def profile_report(args) -> str:
    """cProfile of the trainer loop and of the stub process for basic with the largest agent count."""
    areas = max(args.areas)
    with tempfile.TemporaryDirectory() as folder:
        stub_profile = Path(folder) / "stub.prof"
        record = bench_endpoint("basic", areas, args.warmup, args.exchanges, profile=True, stub_profile=stub_profile)
        parts = []
        for title, stats in (("trainer side (UnityEndpoint.step loop)", pstats.Stats(record["profile"])),
                             ("stub process (whole run)", pstats.Stats(str(stub_profile)))):
            buffer = io.StringIO()
            stats.stream = buffer
            stats.sort_stats("tottime").print_stats(18)
            parts.append(f"### {title}\n```\n{buffer.getvalue()}\n```")
    return "\n".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--exchanges", type=int, default=2000)
    parser.add_argument("--warmup", type=int, default=200)
    parser.add_argument("--areas", type=int, nargs="+", default=[16, 64], help="basic agent counts")
    parser.add_argument("--ball3d-areas", type=int, nargs="+", default=[1, 8],
                        help="ball3d areas (12 agents each)")
    parser.add_argument("--profile", action="store_true")
    args = parser.parse_args()
    report = run(args)
    table = markdown(report)
    print(table)
    if args.profile:
        profile = profile_report(args)
        print(profile)
        report["profile_markdown"] = profile
    OUT.mkdir(exist_ok=True)
    path = OUT / f"protocol-{time.strftime('%Y%m%d-%H%M%S')}.json"
    report["markdown"] = table
    path.write_text(json.dumps(report, indent=1, default=str))
    print(f"\nwrote {path.relative_to(REPO)}")


if __name__ == "__main__":
    main()
