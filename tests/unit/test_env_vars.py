"""Every MLAGENTS_LIKE_* variable is read in one place (trainer/config/env_vars.py): values by hand."""
from __future__ import annotations

import pytest

from trainer.config.env_vars import KNOWN, EnvVars
from trainer.errors import ConfigError


def test_defaults_when_nothing_is_set():
    assert EnvVars.from_environ({}) == EnvVars(torch_threads=1, blas_threads=None, spin_wait_s=0.001,
                                               transport="http2", numpy_update=True)
    # an empty value counts as unset
    assert EnvVars.from_environ({name: " " for name in KNOWN}) == EnvVars()


def test_every_variable_is_read():
    env = EnvVars.from_environ({
        "MLAGENTS_LIKE_TORCH_THREADS": "3", "MLAGENTS_LIKE_BLAS_THREADS": " 2 ", "MLAGENTS_LIKE_SPIN_WAIT_MS": "2.5",
        "MLAGENTS_LIKE_TRANSPORT": "GRPCIO", "MLAGENTS_LIKE_NUMPY_UPDATE": "0", "OTHER": "x"})
    assert env == EnvVars(torch_threads=3, blas_threads=2, spin_wait_s=0.0025, transport="grpcio",
                          numpy_update=False)
    assert EnvVars.from_environ({"MLAGENTS_LIKE_SPIN_WAIT_MS": "0"}).spin_wait_s == 0.0
    assert EnvVars.from_environ({"MLAGENTS_LIKE_NUMPY_UPDATE": "1"}).numpy_update is True


def test_the_object_is_frozen():
    with pytest.raises(AttributeError):
        EnvVars().transport = "grpcio"  # type: ignore[misc]


@pytest.mark.parametrize("name, value, allowed", [
    ("MLAGENTS_LIKE_TORCH_THREADS", "0", "whole number >= 1"),
    ("MLAGENTS_LIKE_TORCH_THREADS", "two", "whole number >= 1"),
    ("MLAGENTS_LIKE_TORCH_THREADS", "-2", "whole number >= 1"),
    ("MLAGENTS_LIKE_BLAS_THREADS", "1.5", "whole number >= 1"),
    ("MLAGENTS_LIKE_SPIN_WAIT_MS", "fast", "milliseconds >= 0"),
    ("MLAGENTS_LIKE_SPIN_WAIT_MS", "-1", "milliseconds >= 0"),
    ("MLAGENTS_LIKE_SPIN_WAIT_MS", "nan", "milliseconds >= 0"),
    ("MLAGENTS_LIKE_SPIN_WAIT_MS", "inf", "milliseconds >= 0"),
    ("MLAGENTS_LIKE_TRANSPORT", "h3", "http2 (the default) or MLAGENTS_LIKE_TRANSPORT=grpcio"),
    ("MLAGENTS_LIKE_NUMPY_UPDATE", "false", "neither 0 nor 1"),
    ("MLAGENTS_LIKE_TRANSPROT", "grpcio", "known: MLAGENTS_LIKE_TORCH_THREADS"),
])
def test_a_bad_value_names_the_variable_the_value_and_what_is_allowed(name, value, allowed):
    with pytest.raises(ConfigError) as error:
        EnvVars.from_environ({name: value})
    assert f"{name}={value!r}" in str(error.value) and allowed in str(error.value)


def test_the_job_templates_variables_reach_the_trainer_without_being_refused():
    """docker/slurm/train.sbatch reads MLAGENTS_LIKE_IMAGE / MLAGENTS_LIKE_VENV; sbatch exports the
    submitter's environment into the job, so the trainer inside sees them and must not refuse."""
    env = EnvVars.from_environ({"MLAGENTS_LIKE_IMAGE": "/images/mlagents-like.sif",
                                "MLAGENTS_LIKE_VENV": "/home/me/mlagents-like/.venv"})
    assert env == EnvVars()


def test_the_crash_hook_names_a_known_point_an_occurrence_and_optionally_a_stop_signal():
    assert EnvVars.from_environ({}).crash_at is None
    assert EnvVars.from_environ({"MLAGENTS_LIKE_CRASH_AT": "checkpoint.onnx:3"}).crash_at == ("checkpoint.onnx", 3)
    assert EnvVars.from_environ({"MLAGENTS_LIKE_CRASH_AT": "update:2:SIGUSR1"}).crash_at == ("update", 2, "SIGUSR1")
    assert EnvVars.from_environ({"MLAGENTS_LIKE_CRASH_AT": "update:18:SIGSTOP"}).crash_at == ("update", 18, "SIGSTOP")
    for bad in ("nowhere:1", "act:0", "act", "act:x", "act:1:SIGSEGV", "act:1:2:3"):
        with pytest.raises(ConfigError, match="MLAGENTS_LIKE_CRASH_AT"):
            EnvVars.from_environ({"MLAGENTS_LIKE_CRASH_AT": bad})
