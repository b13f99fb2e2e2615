"""Which lesson every environment parameter is in, and when it advances (docs/configuration.md,
"environment_parameters").

The run's curriculum state; the settings it works from (samplers, lessons, completion criteria)
are the frozen ``trainer.config.env_params`` types read from the YAML.
"""
from __future__ import annotations

import logging
import math
from typing import Mapping, Sequence

from trainer.config.env_params import (
    CompletionCriteria,
    EnvironmentParameterSettings,
    Sampler,
    assign_seeds,
)

logger = logging.getLogger("mlagents_like")


def criteria_met(
    criteria: CompletionCriteria, progress: float, returns: Sequence[float], smoothed: float
) -> tuple[bool, float]:
    """Whether a lesson with ``criteria`` is complete, and the new smoothed reward.

    progress: trainer step / max_steps. returns: the most recent episode returns of the behavior
    (already cut to the reward-buffer size N). smoothed: the previous smoothed value of this
    parameter. Needs at least ``min_lesson_length`` returns. ``reward`` with smoothing uses
    ``0.25 * smoothed + 0.75 * mean(returns)``; the lesson advances when the value > threshold.
    """
    if len(returns) < criteria.min_lesson_length:
        return False, smoothed
    if criteria.measure == "progress":
        return progress > criteria.threshold, smoothed
    if not returns:
        return False, smoothed
    measure = sum(returns) / len(returns)
    if math.isnan(measure):
        return False, smoothed
    if criteria.signal_smoothing:
        measure = 0.25 * smoothed + 0.75 * measure
        smoothed = measure
    return measure > criteria.threshold, smoothed


class EnvironmentParameterManager:
    """Holds the lesson index of every parameter and advances lessons from trainer statistics.

    params: the run's environment parameters; seeds of -1 are resolved from ``run_seed``
    (docs/protocol.md, "Sampler seeds").
    restore_lessons: lesson numbers read from ``training_status.json`` on --resume.
    """

    def __init__(
        self,
        params: Mapping[str, EnvironmentParameterSettings],
        run_seed: int,
        restore_lessons: Mapping[str, int] | None = None,
    ) -> None:
        self.settings: dict[str, EnvironmentParameterSettings] = assign_seeds(params, run_seed)
        self._lesson_numbers = {name: 0 for name in self.settings}
        self._smoothed = {name: 0.0 for name in self.settings}
        self._waiting_warned: set[str] = set()  # parameters already warned about a missing behavior
        for name, lesson_number in (restore_lessons or {}).items():
            if name not in self.settings:
                logger.warning("Ignoring saved lesson of unknown environment parameter '%s'.", name)
                continue
            last = len(self.settings[name].curriculum) - 1
            if not 0 <= int(lesson_number) <= last:
                logger.warning(
                    "Saved lesson %s of parameter '%s' does not exist; using lesson %s.",
                    lesson_number, name, min(max(int(lesson_number), 0), last),
                )
            self._lesson_numbers[name] = min(max(int(lesson_number), 0), last)

    def reward_buffer_size(self, behavior_name: str) -> int:
        """N: the largest min_lesson_length among lessons naming this behavior (at least 1)."""
        size = 1
        for settings in self.settings.values():
            for lesson in settings.curriculum:
                criteria = lesson.completion_criteria
                if criteria is not None and criteria.behavior == behavior_name:
                    size = max(size, criteria.min_lesson_length)
        return size

    def current_samplers(self) -> dict[str, Sampler]:
        """Parameter name -> the sampler of its current lesson (what the side channel sends)."""
        return {
            name: settings.curriculum[self._lesson_numbers[name]].value
            for name, settings in self.settings.items()
        }

    def lesson_numbers(self) -> dict[str, int]:
        """Parameter name -> current lesson index (saved in training_status.json)."""
        return dict(self._lesson_numbers)

    def update_lessons(
        self,
        trainer_steps: Mapping[str, int],
        trainer_max_steps: Mapping[str, int],
        trainer_reward_buffers: Mapping[str, Sequence[float]],
    ) -> tuple[bool, bool]:
        """Advance every parameter whose current lesson is complete; at most one lesson per call.

        Returns (updated, must_reset): updated if any lesson changed (the caller then clears every
        behavior's reward buffer and re-sends the samplers), must_reset if one of the completed
        lessons has ``require_reset``. Behaviors without a trainer yet are skipped.
        """
        updated = must_reset = False
        for name, settings in self.settings.items():
            number = self._lesson_numbers[name]
            criteria = settings.curriculum[number].completion_criteria
            if criteria is None or number + 1 >= len(settings.curriculum):
                continue
            behavior = criteria.behavior
            if behavior not in trainer_steps:
                self._warn_waiting(name, behavior, trainer_steps)
                continue
            progress = trainer_steps[behavior] / max(trainer_max_steps.get(behavior, 1), 1)
            window = self.reward_buffer_size(behavior)
            returns = list(trainer_reward_buffers.get(behavior, ()))[-window:]
            advance, self._smoothed[name] = criteria_met(criteria, progress, returns, self._smoothed[name])
            if advance:
                self._lesson_numbers[name] = number + 1
                logger.info(self.describe_parameter(name))
                updated = True
                must_reset = must_reset or criteria.require_reset
        return updated, must_reset

    def _warn_waiting(self, name: str, behavior: str, trainer_steps: Mapping[str, int]) -> None:
        """Once per parameter, after some behavior has trained: its curriculum waits for a behavior
        no simulator has reported (a typo in completion_criteria.behavior is the usual cause; with
        default_settings any name is valid at load, since behaviors may connect later)."""
        if name in self._waiting_warned or not any(trainer_steps.values()):
            return
        self._waiting_warned.add(name)
        lesson = self.settings[name].curriculum[self._lesson_numbers[name]].name
        logger.warning(
            "environment_parameters.%s: lesson '%s' waits for behavior '%s', which no simulator has "
            "reported (behaviors so far: %s); its lessons advance only once that behavior trains. "
            "Check completion_criteria.behavior.", name, lesson, behavior, ", ".join(sorted(trainer_steps)))

    def describe_parameter(self, name: str) -> str:
        lesson = self.settings[name].curriculum[self._lesson_numbers[name]]
        return f"Parameter '{name}' is in lesson '{lesson.name}' and has value '{lesson.value}'."

    def describe(self) -> list[str]:
        """One console line per parameter, in configuration order (docs/outputs.md, "Console", item 6)."""
        return [self.describe_parameter(name) for name in self.settings]
