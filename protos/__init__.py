"""The wire contract shared by the trainer and ``unity_stub_env`` (neither imports the other).

* ``communicator_objects`` — the ML-Agents .proto files and their generated code (``regenerate.py``)
* ``versions``       — communication API / package versions, the capabilities both ends report
* ``types``          — BehaviorSpec, ObservationSpec, ActionSpec, ActionTuple, DecisionSteps, ...
* ``wire``           — protobuf field writers (varints, tags, length prefixes, rows of records)
* ``records``        — the fast reader of many equal-layout records (agent infos, agent actions)
* ``side_channels``  — the ``side_channel`` bytes (framing in ``side_channel_wire``)
* ``http2``, ``pacing`` — the single-threaded HTTP/2 gRPC server and client, and when they poll
* ``errors``         — ``ProtocolError``, raised on bytes the protocol does not allow

Nothing is imported here, so that importing one module stays cheap.
"""
