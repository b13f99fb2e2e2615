"""``run_logs/training_status.json``: what --resume needs that is not inside a model (docs/outputs.md, "Outputs").

Layout (one JSON object)::

    {
      "<env parameter>": {"lesson_num": 2},
      "<brain>": {
        "checkpoints": [{"steps": 792, "file_path": "results/id/Ball/Ball-792.onnx",
                         "reward": 1.5, "creation_time": 1700000000.0,
                         "auxillary_file_paths": ["results/id/Ball/Ball-792.pt"]}],
        "final_checkpoint": {... same shape, file_path "results/id/Ball.onnx" ...},
        "elo": 1200.0                                   # self-play only
      },
      "metadata": {"stats_format_version": "0.3.0", "mlagents_version": "1.1.0",
                   "torch_version": "..."}
    }

``auxillary_file_paths`` keeps ML-Agents' spelling so its tools can read our files and vice versa.
"""
from __future__ import annotations

import copy
import json
import logging
import os
from dataclasses import dataclass, field
from typing import Any

from protos.versions import PACKAGE_VERSION
from trainer.artifacts.timers import package_version, write_json_atomic
from trainer.errors import UserError

__all__ = [
    "CheckpointEntry",
    "TrainingStatus",
    "STATS_FORMAT_VERSION",
    "MLAGENTS_VERSION",
    "TRAINING_STATUS_FILE_NAME",
]

logger = logging.getLogger(__name__)

STATS_FORMAT_VERSION = "0.3.0"
MLAGENTS_VERSION = PACKAGE_VERSION  # the ML-Agents Python package we stand in for
TRAINING_STATUS_FILE_NAME = "training_status.json"

METADATA = "metadata"
LESSON_NUM = "lesson_num"
CHECKPOINTS = "checkpoints"
FINAL_CHECKPOINT = "final_checkpoint"
ELO = "elo"


def current_metadata() -> dict[str, str]:
    return {
        "stats_format_version": STATS_FORMAT_VERSION,
        "mlagents_version": MLAGENTS_VERSION,
        "torch_version": package_version("torch", module="torch"),
    }


@dataclass
class CheckpointEntry:
    """One saved model: the .onnx path plus side files (the .pt) and the reward at that time."""

    steps: int
    file_path: str
    reward: float | None
    creation_time: float
    auxillary_file_paths: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "steps": int(self.steps),
            "file_path": self.file_path,
            "reward": None if self.reward is None else float(self.reward),
            "creation_time": float(self.creation_time),
            "auxillary_file_paths": list(self.auxillary_file_paths),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CheckpointEntry:
        return cls(
            steps=int(data["steps"]),
            file_path=str(data["file_path"]),
            reward=None if data.get("reward") is None else float(data["reward"]),
            creation_time=float(data["creation_time"]),
            auxillary_file_paths=[str(p) for p in data.get("auxillary_file_paths", [])],
        )


class TrainingStatus:
    """In-memory training_status.json. Entries it does not know are kept as read."""

    def __init__(self, state: dict[str, Any] | None = None) -> None:
        self.state: dict[str, Any] = copy.deepcopy(state) if state else {}

    # -- file I/O -------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> TrainingStatus:
        """Read a status file written by us or by ML-Agents.

        A missing file only warns (a fresh status is returned, as ML-Agents does); unreadable
        JSON or a missing ``metadata`` block raises :class:`UserError` naming the file; a
        different ML-Agents or torch version only warns.
        """
        path = os.fspath(path)
        try:
            with open(path, encoding="utf-8") as f:
                loaded = json.load(f)
        except FileNotFoundError:
            logger.warning("Training status file %s not found. Not all state will resume.", path)
            return cls()
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise UserError(
                f"{path} is not valid JSON ({exc}). Delete it, or start a new run "
                "without --resume."
            ) from exc
        if not isinstance(loaded, dict) or not isinstance(loaded.get(METADATA), dict):
            raise UserError(
                f"{path} has no 'metadata' block, so it was written by an incompatible "
                "trainer version. Start a new run without --resume (or use --force)."
            )
        cls._check_compatibility(path, loaded[METADATA])
        return cls(loaded)

    @staticmethod
    def _check_compatibility(path: str, saved: dict[str, Any]) -> None:
        ours = current_metadata()
        if saved.get("mlagents_version") != ours["mlagents_version"]:
            logger.warning(
                "%s was written by ML-Agents version %s (we write %s). Some state may not "
                "resume properly.", path, saved.get("mlagents_version"), ours["mlagents_version"]
            )
        if saved.get("torch_version") != ours["torch_version"]:
            logger.warning(
                "%s was written with PyTorch %s (this is %s). The model may not resume "
                "properly.", path, saved.get("torch_version"), ours["torch_version"]
            )

    def to_dict(self) -> dict[str, Any]:
        """The file contents, with our current ``metadata`` block."""
        out = copy.deepcopy(self.state)
        out[METADATA] = current_metadata()
        return out

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write atomically (temp file + ``os.replace``), creating the folder if needed."""
        write_json_atomic(path, self.to_dict())

    # -- per-category helpers -------------------------------------------------------------------
    def _category(self, name: str) -> dict[str, Any]:
        entry = self.state.get(name)
        if not isinstance(entry, dict):
            entry = self.state[name] = {}
        return entry

    def set_lesson_num(self, parameter: str, lesson_num: int) -> None:
        self._category(parameter)[LESSON_NUM] = int(lesson_num)

    def get_lesson_num(self, parameter: str) -> int | None:
        entry = self.state.get(parameter)
        return entry.get(LESSON_NUM) if isinstance(entry, dict) else None

    def checkpoints(self, brain: str) -> list[CheckpointEntry]:
        """The brain's tracked checkpoints, oldest first."""
        entry = self.state.get(brain)
        if not isinstance(entry, dict):
            return []
        return [CheckpointEntry.from_dict(c) for c in entry.get(CHECKPOINTS) or []]

    def add_checkpoint(
        self, brain: str, checkpoint: CheckpointEntry, keep_checkpoints: int
    ) -> list[CheckpointEntry]:
        """Append a checkpoint and drop the oldest beyond ``keep_checkpoints``.

        Returns the dropped entries (oldest first) so the caller can delete their files.
        ``keep_checkpoints <= 0`` keeps everything, as ML-Agents does.
        """
        entry = self._category(brain)
        tracked = list(entry.get(CHECKPOINTS) or [])
        tracked.append(checkpoint.to_dict())
        dropped: list[dict[str, Any]] = []
        if keep_checkpoints > 0 and len(tracked) > keep_checkpoints:
            cut = len(tracked) - keep_checkpoints
            dropped, tracked = tracked[:cut], tracked[cut:]
        entry[CHECKPOINTS] = tracked
        return [CheckpointEntry.from_dict(d) for d in dropped]

    def set_checkpoints(self, brain: str, entries: list[CheckpointEntry]) -> None:
        """Replace the brain's tracked checkpoints (oldest first)."""
        self._category(brain)[CHECKPOINTS] = [e.to_dict() for e in entries]

    def set_final_checkpoint(self, brain: str, checkpoint: CheckpointEntry) -> None:
        self._category(brain)[FINAL_CHECKPOINT] = checkpoint.to_dict()

    def set_elo(self, brain: str, elo: float) -> None:
        """Self-play: the learning policy's rating at the last checkpoint (ML-Agents' "elo")."""
        self._category(brain)[ELO] = float(elo)

    def get_elo(self, brain: str) -> float | None:
        entry = self.state.get(brain)
        return entry.get(ELO) if isinstance(entry, dict) else None

    def final_checkpoint(self, brain: str) -> CheckpointEntry | None:
        entry = self.state.get(brain)
        if not isinstance(entry, dict) or not entry.get(FINAL_CHECKPOINT):
            return None
        return CheckpointEntry.from_dict(entry[FINAL_CHECKPOINT])
