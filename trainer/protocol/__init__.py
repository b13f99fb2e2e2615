"""The wire protocol to ML-Agents simulators (spec §1–§3).

* ``types``         — BehaviorSpec, DecisionSteps, TerminalSteps, ActionTuple, StepResult
* ``codec``         — pure proto ⇄ numpy translation, version check, capabilities
* ``png``           — PNG camera observations → float32 C×H×W
* ``server``        — ``UnityEndpoint``: the gRPC server side of one simulator connection
* ``side_channels`` — framing of the ``side_channel`` bytes

Nothing is imported here so that ``trainer.protocol.types`` stays cheap to import.
"""
