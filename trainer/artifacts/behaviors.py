"""``run_logs/behaviors.json``: the behavior specs a run met (protos/spec_file.py, docs/mirror.md).

The run loop hands every decoded step to ``BehaviorRecorder.observe``: new behaviors bring their
spec and compressions (``StepResult.specs`` / ``compressions``); during the first
``COUNT_STEPS`` exchanges the recorder also counts each behavior's agents (the most that
decided at once in one simulator), its groups and whether masks forbid anything. The custom
stats keys come from the stats side channel. The file is written atomically.
"""
from __future__ import annotations

import dataclasses
import os

import numpy as np

from protos.spec_file import BehaviorRecord, SpecFile
from protos.types import StepResult
from trainer.artifacts.atomic import atomic_write

COUNT_STEPS = 1000  # exchanges during which agents, groups and masks are counted


@dataclasses.dataclass
class _Seen:
    record: BehaviorRecord
    agents: int = 0
    groups: int = 0
    masked: bool = False


class BehaviorRecorder:
    def __init__(self, num_areas: int, source: str = "", environment_parameters=()) -> None:
        self.num_areas = max(int(num_areas), 1)
        self.source = source
        self.environment_parameters = tuple(environment_parameters)
        self.stats: dict[str, None] = {}
        self.seen: dict[str, _Seen] = {}
        self.steps = 0

    def observe(self, results: list[StepResult]) -> None:
        """One exchange: every simulator's decoded message."""
        for result in results:
            for name, spec in result.specs.items():
                if name not in self.seen:
                    compressions = result.compressions.get(name, ("none",) * len(spec.observation_specs))
                    self.seen[name] = _Seen(BehaviorRecord(name, spec, compressions, agents=1))
        if self.steps >= COUNT_STEPS:
            return
        self.steps += 1
        for result in results:
            for name, (decision, _terminal) in result.steps.items():
                seen = self.seen.get(name)
                if seen is None or not len(decision):
                    continue
                seen.agents = max(seen.agents, len(decision))
                if decision.group_id.any():
                    seen.groups = max(seen.groups, len(np.unique(decision.group_id[decision.group_id != 0])))
                if not seen.masked and decision.action_mask is not None:
                    seen.masked = any(mask.any() for mask in decision.action_mask)

    def observe_stats(self, keys) -> None:
        for key in keys:
            self.stats.setdefault(key, None)

    def spec_file(self) -> SpecFile:
        records = []
        for seen in self.seen.values():
            agents = max(seen.agents, 1)
            per_area = agents // self.num_areas if agents % self.num_areas == 0 else None
            groups = seen.groups // self.num_areas if seen.groups % self.num_areas == 0 else seen.groups
            records.append(dataclasses.replace(seen.record, agents=agents, agents_per_area=per_area,
                                               groups_per_area=groups, action_mask=seen.masked))
        return SpecFile(behaviors=tuple(records), num_areas=self.num_areas,
                        environment_parameters=self.environment_parameters, stats=tuple(self.stats),
                        source=self.source)

    def write(self, path: str) -> bool:
        """Write the file (atomically); False, writing nothing, before any behavior was met."""
        if not self.seen:
            return False
        text = self.spec_file().dumps()
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        atomic_write(path, lambda f: f.write(text), binary=False)
        return True
