"""The versions and capabilities this project speaks, in one place for the trainer and the stub.

* ``COMMUNICATION_VERSION``: the communication API of ML-Agents Release 22 (both ends send it in
  the handshake; Unity and the trainer compare majors, docs/protocol.md).
* ``PACKAGE_VERSION``: the ML-Agents Python package the trainer stands in for (sent in the
  handshake, written as ``mlagents_version`` in training_status.json).
* ``UNITY_PACKAGE_VERSION``: the com.unity.ml-agents package the stub stands in for.
"""
from __future__ import annotations

from protos.communicator_objects import capabilities_pb2

COMMUNICATION_VERSION = "1.5.0"
PACKAGE_VERSION = "1.1.0"
UNITY_PACKAGE_VERSION = "3.0.0"


def all_true_capabilities() -> capabilities_pb2.UnityRLCapabilitiesProto:
    """Every feature of communication API 1.5.0: what the trainer and Unity 3.0 both report."""
    return capabilities_pb2.UnityRLCapabilitiesProto(
        baseRLCapabilities=True,
        concatenatedPngObservations=True,
        compressedChannelMapping=True,
        hybridActions=True,
        trainingAnalytics=True,
        variableLengthObservation=True,
        multiAgentGroups=True,
    )
