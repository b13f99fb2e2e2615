"""Stats (Unity → Python): what a scene records with ``Academy.Instance.StatsRecorder``."""
from __future__ import annotations

from collections import defaultdict
from typing import Mapping

from mlagents_like_envs.side_channel.incoming_message import IncomingMessage
from mlagents_like_envs.side_channel.side_channel import SideChannel
from protos.side_channels import STATS_CHANNEL_ID, decode_stat
from protos.types import StatsAggregationMethod

StatList = list[tuple[float, StatsAggregationMethod]]
EnvironmentStats = Mapping[str, StatList]


class StatsSideChannel(SideChannel):
    """Collects (value, aggregation method) per key until ``get_and_reset_stats``."""

    def __init__(self) -> None:
        super().__init__(STATS_CHANNEL_ID)
        self.stats: EnvironmentStats = defaultdict(list)

    def on_message_received(self, msg: IncomingMessage) -> None:
        key, value, aggregation = decode_stat(bytes(msg.buffer[msg.offset:]))
        msg.offset = len(msg.buffer)
        self.stats[key].append((value, aggregation))

    def get_and_reset_stats(self) -> EnvironmentStats:
        stats, self.stats = self.stats, defaultdict(list)
        return stats


__all__ = ["EnvironmentStats", "StatList", "StatsAggregationMethod", "StatsSideChannel"]
