"""The stub against our own trainer endpoint (trainer/protocol/server.py UnityEndpoint)."""
from __future__ import annotations

import numpy as np
import pytest

from trainer.protocol import side_channels as sc
from trainer.protocol.server import UnityEndpoint
from trainer.protocol.types import ActionTuple


@pytest.fixture
def endpoint():
    with UnityEndpoint(0, timeout_wait=20) as server:
        server.start()
        yield server


def test_endpoint_trains_basic_through_the_stub(endpoint, launch):
    process = launch(endpoint.port, "basic", "--num-areas", "2")
    init = endpoint.handshake(seed=5, num_areas=2)
    assert init.communication_version == "1.5.0"
    result = endpoint.reset(sc.pack_messages([(sc.ENGINE_CONFIG_CHANNEL_ID, payload)
                                              for payload in sc.encode_engine_config(84, 84, 5, 20.0, -1, 60)]))
    spec = result.specs["Basic?team=0"]
    assert spec.action_spec.discrete_branches == (3,) and spec.observation_specs[0].shape == (20,)
    decision, terminal = result.steps["Basic?team=0"]
    assert len(decision) == 2 and len(terminal) == 0
    for _ in range(7):  # agent 0 walks right to the large goal, agent 1 stays
        result = endpoint.step({"Basic?team=0": ActionTuple(np.zeros((2, 0), np.float32),
                                                            np.array([[2], [0]], np.int32))})
    decision, terminal = result.steps["Basic?team=0"]
    assert terminal.reward.tolist() == pytest.approx([0.99])
    assert not terminal.interrupted[0]
    assert len(decision) == 2 and terminal.agent_id[0] not in decision.agent_id.tolist()
    assert np.argmax(decision.obs[0], axis=1).tolist() == [10, 10]  # agent 1 stayed; agent 0 restarted
    endpoint.close()
    assert process.wait(timeout=10) == 0
