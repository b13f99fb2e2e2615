"""Samplers, seed offsets (docs/protocol.md, "Sampler seeds") and lesson advancement (docs/configuration.md,
"environment_parameters") with hand-computed numbers."""
from __future__ import annotations

import logging

import pytest

from trainer.config import (
    CompletionCriteria,
    ConstantSampler,
    EnvironmentParameterSettings,
    GaussianSampler,
    Lesson,
    MultiRangeUniformSampler,
    UniformSampler,
    assign_seeds,
)
from trainer.config.env_params import sampler_as_dict, structure_environment_parameters
from trainer.curriculum import EnvironmentParameterManager


def single(name, sampler):
    return EnvironmentParameterSettings((Lesson(name=name, value=sampler),))


def chain(*lessons):
    return EnvironmentParameterSettings(tuple(lessons))


def test_sampler_defaults_and_yaml_forms():
    params = structure_environment_parameters({
        "g": 9.81,
        "u": {"sampler_type": "uniform", "sampler_parameters": {}},
        "n": {"sampler_type": "gaussian", "sampler_parameters": {}},
        "m": {"sampler_type": "multirangeuniform", "sampler_parameters": {}},
        "c": {"sampler_type": "constant", "sampler_parameters": {}},
    })
    assert params["g"].curriculum == (Lesson(name="g", value=ConstantSampler(9.81, -1)),)
    assert params["u"].curriculum[0].value == UniformSampler(0.0, 1.0, -1)
    assert params["n"].curriculum[0].value == GaussianSampler(1.0, 1.0, -1)
    assert params["m"].curriculum[0].value == MultiRangeUniformSampler(((0.0, 1.0),), -1)
    assert params["c"].curriculum[0].value == ConstantSampler(0.0, -1)
    criteria = CompletionCriteria(behavior="A")
    assert (criteria.measure, criteria.min_lesson_length, criteria.signal_smoothing) == ("reward", 0, True)
    assert (criteria.threshold, criteria.require_reset) == (0.0, False)
    assert sampler_as_dict(UniformSampler(0.5, 3.0, 43)) == {
        "sampler_type": "uniform", "sampler_parameters": {"seed": 43, "min_value": 0.5, "max_value": 3.0}}


def test_final_lesson_criteria_are_warned_and_dropped(caplog):
    with caplog.at_level("WARNING", logger="mlagents_like"):
        params = structure_environment_parameters(
            {"p": {"curriculum": [{"name": "only", "value": 1, "completion_criteria": {"behavior": "A"}}]}})
    assert params["p"].curriculum[0].completion_criteria is None
    assert "'only'" in caplog.text and "ignored" in caplog.text


def test_seed_offsets_follow_parameter_then_lesson_order():
    params = {
        "a": single("a", ConstantSampler(1.0)),
        "b": single("b", UniformSampler(0.0, 1.0, seed=43)),
        "c": chain(
            Lesson("c0", GaussianSampler(), CompletionCriteria("A")),
            Lesson("c1", UniformSampler(seed=5), CompletionCriteria("A")),
            Lesson("c2", MultiRangeUniformSampler()),
        ),
        "d": single("d", GaussianSampler()),
    }
    seeded = assign_seeds(params, run_seed=100)
    seeds = {name: [lesson.value.seed for lesson in s.curriculum] for name, s in seeded.items()}
    assert seeds == {"a": [100], "b": [43], "c": [101, 5, 102], "d": [103]}
    assert params["a"].curriculum[0].value.seed == -1  # input untouched


def reward_curriculum():
    """p advances on A's smoothed reward > 0.5 (min 3 episodes); q keeps N for A at 5."""
    return {
        "p": chain(Lesson("easy", ConstantSampler(1.0), CompletionCriteria("A", "reward", 3, True, 0.5)),
                   Lesson("hard", UniformSampler(2.0, 4.0))),
        "q": chain(Lesson("q0", ConstantSampler(0.0), CompletionCriteria("A", "reward", 5, False, 100.0)),
                   Lesson("q1", ConstantSampler(1.0))),
    }


def test_reward_measure_with_smoothing_and_window():
    manager = EnvironmentParameterManager(reward_curriculum(), run_seed=0)
    assert manager.reward_buffer_size("A") == 5 and manager.reward_buffer_size("B") == 1
    steps, max_steps = {"A": 10}, {"A": 1000}
    # 2 episodes < min_lesson_length 3: nothing happens, smoothing untouched.
    assert manager.update_lessons(steps, max_steps, {"A": [0.2, 0.4]}) == (False, False)
    # mean 0.5 -> smoothed 0.25*0 + 0.75*0.5 = 0.375, not > 0.5.
    assert manager.update_lessons(steps, max_steps, {"A": [0.2, 0.4, 0.9]}) == (False, False)
    # Only the last N=5 returns count: mean(0.4, 0.9, 0.8, 1.0, 0.4) = 0.7;
    # smoothed 0.25*0.375 + 0.75*0.7 = 0.61875 > 0.5 -> advance (with -10 included it would not).
    assert manager.update_lessons(steps, max_steps, {"A": [-10.0, 0.4, 0.9, 0.8, 1.0, 0.4]}) == (True, False)
    assert manager.lesson_numbers() == {"p": 1, "q": 0}
    assert manager.current_samplers()["p"] == UniformSampler(2.0, 4.0, seed=1)  # run_seed 0 + offset 1
    assert manager.describe() == [
        "Parameter 'p' is in lesson 'hard' and has value 'Uniform sampler: min=2.0, max=4.0'.",
        "Parameter 'q' is in lesson 'q0' and has value 'Float: value=0.0'.",
    ]
    # p is in its final lesson and never advances; q's mean 50 is not > 100.
    assert manager.update_lessons(steps, max_steps, {"A": [50.0] * 5}) == (False, False)
    assert manager.lesson_numbers() == {"p": 1, "q": 0}


def test_reward_without_smoothing_needs_strictly_greater():
    params = {"p": chain(Lesson("l0", ConstantSampler(0.0), CompletionCriteria("A", "reward", 2, False, 1.0)),
                         Lesson("l1", ConstantSampler(1.0)))}
    manager = EnvironmentParameterManager(params, run_seed=0)
    assert manager.update_lessons({"A": 1}, {"A": 10}, {"A": [0.5, 1.5]}) == (False, False)   # mean 1.0
    assert manager.update_lessons({"A": 1}, {"A": 10}, {"A": [1.5, 0.6]}) == (True, False)    # mean 1.05


def test_progress_measure_require_reset_and_one_lesson_per_call():
    params = {"w": chain(
        Lesson("w0", ConstantSampler(1.0), CompletionCriteria("A", "progress", 0, True, 0.3, require_reset=True)),
        Lesson("w1", ConstantSampler(2.0), CompletionCriteria("A", "progress", 0, True, 0.1)),
        Lesson("w2", ConstantSampler(3.0)),
    )}
    manager = EnvironmentParameterManager(params, run_seed=0)
    assert manager.update_lessons({"B": 999}, {"B": 1000}, {}) == (False, False)         # A not training yet
    assert manager.update_lessons({"A": 300}, {"A": 1000}, {"A": []}) == (False, False)  # 0.3 is not > 0.3
    assert manager.update_lessons({"A": 301}, {"A": 1000}, {"A": []}) == (True, True)    # reset requested
    assert manager.update_lessons({"A": 301}, {"A": 1000}, {"A": []}) == (True, False)   # 0.301 > 0.1
    assert manager.lesson_numbers() == {"w": 2}
    assert manager.current_samplers()["w"].value == 3.0


def test_restore_lessons_and_clamping(caplog):
    params = {"w": chain(Lesson("w0", ConstantSampler(1.0), CompletionCriteria("A", "progress", 0, True, 0.5)),
                         Lesson("w1", ConstantSampler(2.0)))}
    assert EnvironmentParameterManager(params, 0, {"w": 1}).current_samplers()["w"].value == 2.0
    with caplog.at_level("WARNING", logger="mlagents_like"):
        manager = EnvironmentParameterManager(params, 0, {"w": 7, "gone": 0})
    assert manager.lesson_numbers() == {"w": 1}
    assert "gone" in caplog.text


@pytest.mark.parametrize("sampler, text", [
    (ConstantSampler(9.81), "Float: value=9.81"),
    (GaussianSampler(0.5, 2.0), "Gaussian sampler: mean=0.5, stddev=2.0"),
    (MultiRangeUniformSampler(((1.0, 2.0), (5.0, 6.0))), "MultiRangeUniform sampler: intervals=[[1.0, 2.0], [5.0, 6.0]]"),
])
def test_sampler_console_formats(sampler, text):
    assert str(sampler) == text


def test_upgrade_script_lesson_form_is_read_with_a_warning(caplog):
    raw = {"h": {"curriculum": [
        {"Lesson0": {"completion_criteria": {"behavior": "A", "measure": "progress", "threshold": 0.1},
                     "value": {"sampler_type": "uniform", "sampler_parameters": {"min_value": 0.0, "max_value": 4.0}}}},
        {"Lesson1": {"value": 8.0}},
    ]}}
    with caplog.at_level("WARNING", logger="mlagents_like"):
        params = structure_environment_parameters(raw, behavior_names=["A"])
    lessons = params["h"].curriculum
    assert [lesson.name for lesson in lessons] == ["Lesson0", "Lesson1"]
    assert lessons[0].value == UniformSampler(0.0, 4.0, -1) and lessons[1].value == ConstantSampler(8.0)
    assert lessons[0].completion_criteria.threshold == 0.1
    assert "Lesson0" in caplog.text


def test_curriculum_waiting_for_an_unreported_behavior_is_warned_once(caplog):
    params = {"w": chain(
        Lesson("w0", ConstantSampler(1.0), CompletionCriteria("Nope", "progress", 0, True, 0.1)),
        Lesson("w1", ConstantSampler(2.0)),
    )}
    manager = EnvironmentParameterManager(params, run_seed=0)
    with caplog.at_level(logging.WARNING, logger="mlagents_like"):
        assert manager.update_lessons({"Basic": 0}, {"Basic": 100}, {}) == (False, False)
        assert caplog.records == []  # nothing has trained yet: the behavior may still connect
        for step in (50, 90):
            assert manager.update_lessons({"Basic": step}, {"Basic": 100}, {}) == (False, False)
    warnings = [r.getMessage() for r in caplog.records]
    assert warnings == ["environment_parameters.w: lesson 'w0' waits for behavior 'Nope', which no simulator "
                        "has reported (behaviors so far: Basic); its lessons advance only once that behavior "
                        "trains. Check completion_criteria.behavior."]
    assert manager.lesson_numbers() == {"w": 0}
