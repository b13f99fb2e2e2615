"""The run's results folder, results/<run-id>: where it is, refusing to clobber an earlier run,
checking it can be written before the simulators start, and tidying what a killed run left."""
from __future__ import annotations

import logging
import os
import re
import tempfile

from trainer.artifacts.atomic import WRITE_ERRNOS, results_write_error
from trainer.errors import UserError

logger = logging.getLogger("mlagents_like")


def run_dir_of(options) -> str:
    ck = options.checkpoint_settings
    return os.path.join(ck.results_dir, ck.run_id)


_STARTUP_FILES = re.compile(r"configuration\.yaml|run_logs/(timers\.json|training_status\.json|behaviors\.json|Player-\d+\.log)")


def only_startup_files(run_dir: str) -> bool:
    """True if ``run_dir`` holds nothing but what a run writes before its first step (the
    configuration, timers, training status, simulator logs) and no checkpoint, model or
    TensorBoard data: every run that trained leaves those (Ctrl-C and a simulator that stops
    included; they end with a final checkpoint)."""
    for folder, _, files in os.walk(run_dir):
        for name in files:
            relative = os.path.relpath(os.path.join(folder, name), run_dir).replace(os.sep, "/")
            if not _STARTUP_FILES.fullmatch(relative):
                return False
    return True


def prepare_run_dir(options) -> str:
    """results/<run-id>: refuse to clobber an earlier run unless --resume or --force."""
    ck = options.checkpoint_settings
    run_dir = run_dir_of(options)
    exists = os.path.isdir(run_dir) and bool(os.listdir(run_dir))
    if not exists and ck.resume:
        raise UserError(f"--resume was given but {run_dir} does not exist. Start a new run without --resume.")
    if exists and not (ck.resume or ck.force or ck.inference):
        if not only_startup_files(run_dir):
            raise UserError(
                f"Previous data from this run ID was found in {run_dir}. Either use --resume to continue "
                "that run, --force to overwrite it, or pick another --run-id."
            )
        # e.g. a simulator that failed at start: nothing to lose
        logger.info("%s holds only the files of an earlier start that never trained; using it again.", run_dir)
    try:
        os.makedirs(os.path.join(run_dir, "run_logs"), exist_ok=True)
        for folder, _, _ in os.walk(run_dir):  # a folder we cannot write stops us now, not mid-run
            tempfile.TemporaryFile(dir=folder).close()
    except OSError as error:
        if error.errno in WRITE_ERRNOS:
            raise results_write_error(error.filename or run_dir, error) from None
        raise
    if ck.resume:
        remove_leftover_temp_files(run_dir)
    return run_dir


# the temp files of trainer.artifacts.atomic (tempfile.mkstemp: 8 random letters, digits or _)
_LEFTOVER_TMP = re.compile(r"\..+-[A-Za-z0-9_]{8}\.tmp")


def remove_leftover_temp_files(run_dir: str) -> None:
    """--resume: delete the temp files of writes a killed run did not finish (never read)."""
    removed = []
    for folder, _, files in os.walk(run_dir):
        for name in files:
            if _LEFTOVER_TMP.fullmatch(name):
                os.remove(os.path.join(folder, name))
                removed.append(os.path.relpath(os.path.join(folder, name), run_dir))
    if removed:
        logger.info("Removed %d unfinished temp file(s) of the previous run: %s", len(removed), ", ".join(removed))
