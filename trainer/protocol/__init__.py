"""The trainer's end of the wire protocol (docs/protocol.md); the shared pieces live in ``protos``.

* ``codec``  — one decode of a simulator's message into DecisionSteps/TerminalSteps, one encode
  of the answer; version check
* ``png``    — PNG camera observations → float32 C×H×W
* ``server`` — ``UnityEndpoint``: the gRPC server side of one simulator connection
* ``http2_server`` — the HTTP/2 server of unary gRPC calls it runs on (framing: ``protos/http2.py``)
"""
