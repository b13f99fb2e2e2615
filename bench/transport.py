"""Transport benchmark (run by hand, not a test): what does one Exchange cost each transport?

    PYTHONPATH=$PWD .venv/bin/python bench/transport.py [--exchanges 200] [--repeats 30] [--only server]

Payloads are the sizes of real messages (the stub's step message and the trainer's answer):
basic x1 150 B up / 38 B down, basic x16 1981 / 207 B, ball3d x12 846 / 296 B, and a 64 KiB
camera-sized request. Two measurements, each the minimum over ``--repeats`` batches of the
mean over ``--exchanges`` exchanges (the minimum, because the machine may be shared):

* ``server``: the trainer side alone, on one thread: a raw client socket in this process writes a
  pre-encoded request (HEADERS + DATA), then the transport's ``take`` + ``call.answer`` are timed;
  the client reads the answer off the socket outside the timed part. Compares the hand-written
  framing (``http2``) with ``h2``'s state machine. grpcio's server has no single-threaded form.
  Also printed: the median over batches of each batch's fastest exchange, which other processes
  on the CPUs disturb far less than a mean (a longer exchange is more often interrupted).
* ``round trip``: the transport in this process answering a client in another process
  (our blocking HTTP/2 client for ``http2`` and ``h2``, grpcio's client for ``grpcio``): wall
  time per exchange, both ends' transport work plus the wake-ups between them; no codec.

With ``--protocol``: instead, ``bench/protocol.py``'s endpoint row (``UnityEndpoint`` against the
stub process, codec included) for basic x1, basic x16 and ball3d x12 with each transport
(MLAGENTS_LIKE_TRANSPORT set for both ends), transports interleaved, best of ``--rounds``.
With ``--learn``: wall time of ``mlagents-like-learn configs/<config>.yaml --env stub:<task>`` per
transport, interleaved, ``--rounds`` times (run it on a quiet machine; it takes minutes).

Prints a markdown table and writes JSON to bench/out/transport-<time>.json.
"""
from __future__ import annotations

import argparse
import json
import os
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from protos import http2  # noqa: E402
from trainer.protocol import http2_server  # noqa: E402
from trainer.protocol.server import EXCHANGE_PATH, MAX_MESSAGE_BYTES, _GrpcioTransport  # noqa: E402
from unity_stub_env.http2_client import request_headers  # noqa: E402

OUT = Path(__file__).resolve().parent / "out"
PEERS = Path(__file__).resolve().parent / "peers"
sys.path.insert(0, str(PEERS))  # h2_transport: the h2-based server measured against ours
PAYLOADS = {  # name: (request bytes, answer bytes), measured from the stub and the codec
    "basic x1": (150, 38),
    "basic x16": (1981, 207),
    "ball3d x12": (846, 296),
    "64 KiB request": (65536, 296),
}


def make_transport(kind: str, port: int = 0):
    if kind == "http2":
        return http2_server.Http2Transport("127.0.0.1", port, EXCHANGE_PATH, MAX_MESSAGE_BYTES)
    if kind == "h2":
        from h2_transport import H2Transport

        return H2Transport("127.0.0.1", port, EXCHANGE_PATH, MAX_MESSAGE_BYTES)
    if kind == "grpcio":
        return _GrpcioTransport("127.0.0.1", port, MAX_MESSAGE_BYTES)
    raise ValueError(kind)


def make_transport_class(kind: str):
    """The class UnityEndpoint builds for its HTTP/2 transport (``h2``: the h2-based one)."""
    if kind == "h2":
        from h2_transport import H2Transport

        return H2Transport
    return http2_server.Http2Transport


# mlagents-like-learn with the h2-based server swapped in when argv[1] is "h2"
_LEARN = ("import sys; sys.path.insert(0, sys.argv.pop(1)); kind = sys.argv.pop(1)\n"
          "if kind == 'h2':\n"
          "    import h2_transport, trainer.protocol.server as s; s.Http2Transport = h2_transport.H2Transport\n"
          "from trainer.cli import entry; sys.argv[0] = 'mlagents-like-learn'; entry()")


def _request_frames(stream_id: int, headers: bytes, message: bytes) -> bytes:
    body = b"\x00" + struct.pack(">I", len(message)) + message
    out = http2.frame(http2.HEADERS, http2.END_HEADERS, stream_id, headers)
    for offset in range(0, len(body), 16384):
        end = min(offset + 16384, len(body))
        out += http2.frame(http2.DATA, http2.END_STREAM if end == len(body) else 0, stream_id, body[offset:end])
    return out


def _read_answer(sock: socket.socket, buffer: bytearray, stream_id: int) -> None:
    """Read frames until the trailers (HEADERS with END_STREAM) of ``stream_id``."""
    while True:
        for kind, flags, sid, _ in http2.take_frames(buffer):
            if kind == http2.HEADERS and flags & http2.END_STREAM and sid == stream_id:
                return
        chunk = sock.recv(1 << 20)
        if not chunk:
            raise RuntimeError("the server closed the connection")
        buffer += chunk


def bench_server(kind: str, request_size: int, answer_size: int, exchanges: int, repeats: int) -> tuple[float, float]:
    """Seconds per exchange spent in the trainer's take + answer: the lowest batch mean, and the
    median of every batch's fastest exchange (steadier when other processes take the CPUs)."""
    transport = make_transport(kind)
    transport.start()
    clock = time.perf_counter
    try:
        sock = socket.create_connection(("127.0.0.1", transport.port))
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        settings = struct.pack(">HIHIHI", 0x2, 0, http2.SETTINGS_INITIAL_WINDOW_SIZE, http2.MAX_WINDOW,
                               http2.SETTINGS_MAX_FRAME_SIZE, http2.OUR_MAX_FRAME)
        sock.sendall(http2.PREFACE + http2.frame(http2.SETTINGS, 0, 0, settings)
                     + http2.frame(http2.WINDOW_UPDATE, 0, 0, struct.pack(">I", http2.MAX_WINDOW - 65535)))
        headers = request_headers(EXCHANGE_PATH, f"127.0.0.1:{transport.port}".encode())
        message, answer = b"\x07" * request_size, b"\x08" * answer_size
        buffer = bytearray()
        stream_id = 1
        best, fastest = float("inf"), []
        for repeat in range(repeats + 1):  # the first batch warms up
            times = []
            for _ in range(exchanges):
                sock.sendall(_request_frames(stream_id, headers, message))
                started = clock()
                call = transport.take(5.0)
                call.answer(answer)
                times.append(clock() - started)
                _read_answer(sock, buffer, stream_id)
                stream_id += 2
            if repeat:
                best = min(best, sum(times) / exchanges)
                fastest.append(min(times))
        sock.close()
    finally:
        transport.close(grace=0.1)
    return best, sorted(fastest)[len(fastest) // 2]


def run_client(port: int, kind: str, request_size: int, calls: int) -> None:
    """The peer of ``bench_round_trip`` (``--client``): ``calls`` blocking calls, then exit."""
    message = b"\x07" * request_size
    if kind == "grpcio":
        import grpc

        channel = grpc.insecure_channel(f"127.0.0.1:{port}", options=[("grpc.max_receive_message_length", -1),
                                                                      ("grpc.max_send_message_length", -1)])
        exchange = channel.unary_unary(EXCHANGE_PATH.decode())
        grpc.channel_ready_future(channel).result(timeout=30)
        for _ in range(calls):
            exchange(message, timeout=30)
        channel.close()
        return
    from unity_stub_env.http2_client import Http2Channel

    channel = Http2Channel("127.0.0.1", port, EXCHANGE_PATH)
    deadline = time.monotonic() + 30
    while not channel.connect(1.0):
        if time.monotonic() > deadline:
            raise SystemExit("no server")
        time.sleep(0.05)
    for _ in range(calls):
        channel.call(message, timeout=30)
    channel.close()


def bench_round_trip(kind: str, request_size: int, answer_size: int, exchanges: int, repeats: int) -> float:
    """Seconds per exchange with the client in another process (min over repeats)."""
    transport = make_transport(kind)
    transport.start()
    answer = b"\x08" * answer_size
    calls = exchanges * (repeats + 1)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
    client = subprocess.Popen([sys.executable, __file__, "--client", str(transport.port), kind,
                               str(request_size), str(calls)], env=env)
    best = float("inf")
    try:
        for repeat in range(repeats + 1):
            started = time.perf_counter()
            for _ in range(exchanges):
                call = transport.take(30.0)
                if call is None:
                    raise RuntimeError(f"{kind}: the client stopped calling")
                call.answer(answer)
            if repeat:
                best = min(best, (time.perf_counter() - started) / exchanges)
        client.wait(timeout=30)
    finally:
        if client.poll() is None:
            client.kill()
        transport.close(grace=0.1)
    return best


def bench_protocol(transports: list[str], rounds: int, warmup: int, exchanges: int) -> dict:
    """exchanges/s of bench/protocol.py's endpoint row per transport and scene (best of rounds)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import protocol
    from trainer.protocol import server

    scenes = [("basic", 1, "basic x1"), ("basic", 16, "basic x16"), ("ball3d", 1, "ball3d x12")]
    rows: dict = {}
    for _ in range(rounds):
        for task, areas, name in scenes:
            for kind in transports:
                # both ends read it; "h2" = our client with the h2 server swapped in below
                os.environ["MLAGENTS_LIKE_TRANSPORT"] = "http2" if kind == "h2" else kind
                server.Http2Transport = make_transport_class(kind)
                try:
                    record = protocol.bench_endpoint(task, areas, warmup, exchanges)
                finally:
                    server.Http2Transport = http2_server.Http2Transport
                rate = record["exchanges"] / record["seconds"]
                runs = rows.setdefault(f"{kind} {name}", [])
                runs.append(rate)
                print(f"{kind} {name}: {rate:,.0f} exchanges/s", file=sys.stderr)
    os.environ.pop("MLAGENTS_LIKE_TRANSPORT", None)
    return {name: {"best_exchanges_per_s": max(runs), "runs": runs} for name, runs in rows.items()}


def bench_learn(transports: list[str], rounds: int, config: str, task: str) -> dict:
    """Wall seconds of one training run per transport, interleaved (best and all)."""
    import tempfile

    rows: dict = {}
    for round_ in range(rounds):
        for kind in transports:
            env = dict(os.environ, MLAGENTS_LIKE_TRANSPORT="http2" if kind == "h2" else kind,
                       PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])))
            with tempfile.TemporaryDirectory() as results:
                started = time.perf_counter()
                subprocess.run([sys.executable, "-c", _LEARN, str(PEERS), kind,
                                str(REPO / "configs" / f"{config}.yaml"), "--env", f"stub:{task}",
                                "--run-id", f"transport-{kind}-{round_}", "--force", "--results-dir", results],
                               cwd=REPO, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                seconds = time.perf_counter() - started
            rows.setdefault(f"{kind} {config}", []).append(seconds)
            print(f"{kind} {config}: {seconds:.2f} s", file=sys.stderr)
    return {name: {"best_seconds": min(runs), "runs": runs} for name, runs in rows.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--exchanges", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--only", choices=("server", "round-trip"))
    parser.add_argument("--transports", nargs="+", default=["http2", "h2", "grpcio"])
    parser.add_argument("--protocol", action="store_true", help="bench/protocol.py's endpoint rows instead")
    parser.add_argument("--learn", metavar="CONFIG:TASK", help="end-to-end training instead, e.g. basic:basic")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--client", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client:
        port, kind, size, calls = args.client
        run_client(int(port), kind, int(size), int(calls))
        return
    if args.protocol or args.learn:
        if args.protocol:
            rows = bench_protocol(args.transports, args.rounds, 200, args.exchanges * 10)
        else:
            config, task = args.learn.split(":")
            rows = bench_learn(args.transports, args.rounds, config, task)
        print(json.dumps(rows, indent=1))
        OUT.mkdir(exist_ok=True)
        path = OUT / f"transport-{'protocol' if args.protocol else 'learn'}-{time.strftime('%Y%m%d-%H%M%S')}.json"
        path.write_text(json.dumps({"when": time.strftime("%Y-%m-%d %H:%M:%S"), "rows": rows}, indent=1))
        print(f"wrote {path.relative_to(REPO)}")
        return
    rows: dict = {}
    for name, (request_size, answer_size) in PAYLOADS.items():
        for kind in args.transports:
            row = rows.setdefault(f"{kind} {name}", {})
            if args.only != "round-trip" and kind != "grpcio":
                best, fastest = bench_server(kind, request_size, answer_size, args.exchanges, args.repeats)
                row["server_us"], row["server_fastest_us"] = 1e6 * best, 1e6 * fastest
            if args.only != "server":
                row["round_trip_us"] = 1e6 * bench_round_trip(kind, request_size, answer_size,
                                                              args.exchanges, args.repeats)
            print(f"{kind} {name}: {row}", file=sys.stderr)
    lines = ["| transport, payload | trainer side, best batch mean (us) | trainer side, fastest exchange (us) "
             "| round trip (us) |", "|---|---:|---:|---:|"]
    for name, row in rows.items():
        cells = [f"{row[k]:.1f}" if k in row else "-" for k in ("server_us", "server_fastest_us", "round_trip_us")]
        lines.append(f"| {name} | {' | '.join(cells)} |")
    table = "\n".join(lines)
    print(table)
    OUT.mkdir(exist_ok=True)
    path = OUT / f"transport-{time.strftime('%Y%m%d-%H%M%S')}.json"
    path.write_text(json.dumps({"when": time.strftime("%Y-%m-%d %H:%M:%S"), "exchanges": args.exchanges,
                                "repeats": args.repeats, "rows": rows, "markdown": table}, indent=1))
    print(f"\nwrote {path.relative_to(REPO)}")


if __name__ == "__main__":
    main()
