"""One brain's training state in a run: its trainer (PPO, SAC or POCA), settings, summaries and checkpoints.

The run loop (trainer/run.py) owns the simulators and the data flow; a ``BehaviorRunner`` owns
what belongs to one brain name: when to summarise, when to checkpoint, what to write where.
"""
from __future__ import annotations

import logging
import os
import re
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch

from protos.types import BehaviorSpec
from trainer.artifacts.atomic import atomic_copy
from trainer import crash_points
from trainer.artifacts.checkpoints import CheckpointError, checkpoint_step, load_checkpoint, save_checkpoint
from trainer.artifacts.training_status import CheckpointEntry, TrainingStatus
from trainer.errors import ConfigError, UserError
from trainer.common.trainer_interface import Trainer
from trainer.common.trajectory import Trajectory
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.trainer import PPOTrainer
from trainer.selfplay import ELO_STAT, SelfPlay, TeamController

logger = logging.getLogger("mlagents_like")


def make_trainer(brain: str, spec: BehaviorSpec, settings, seed: int, device: str, use_numpy_update: bool
                 ) -> Trainer:
    """The trainer of ``settings.trainer_type`` (the config refuses the types not trained here)."""
    if settings.trainer_type == "sac":
        from trainer.sac.hyperparams import SACHyperparams
        from trainer.sac.trainer import SACTrainer

        trainer = SACTrainer(brain, spec, SACHyperparams.from_settings(settings), seed=seed, device=device,
                             use_numpy_update=use_numpy_update)
    elif settings.trainer_type == "poca":
        from trainer.poca.trainer import POCATrainer

        trainer = POCATrainer(brain, spec, PPOHyperparams.from_settings(settings), seed=seed, device=device)
    else:
        trainer = PPOTrainer(brain, spec, PPOHyperparams.from_settings(settings), seed=seed, device=device,
                             use_numpy_update=use_numpy_update)
    attach_demonstrations(trainer, brain, spec, settings, seed)
    return trainer


def attach_demonstrations(trainer: Trainer, brain: str, spec: BehaviorSpec, settings, seed: int) -> None:
    """behavioral_cloning's learner and GAIL's expert data, from their demo_path (read once per
    path); ConfigError (exit 2) if a demonstration does not fit the behavior."""
    from trainer.config.support import demo_paths
    from trainer.demonstrations import load_demonstrations

    loaded = {}
    for key, path in demo_paths(settings):
        if path not in loaded:
            loaded[path] = load_demonstrations(path, spec, f"behaviors.{brain}.{key}")
    bc = settings.behavioral_cloning
    gail = settings.reward_signals.get("gail")
    provider = trainer.providers.get("gail")
    if gail is not None and provider is None:  # a trainer that built no GAIL learner must not train without it
        raise ConfigError(f"behaviors.{brain}.reward_signals.gail: not implemented for trainer_type "
                          f"{settings.trainer_type} yet; remove it or use trainer_type ppo")
    if bc is not None:
        from trainer.behavioral_cloning import BehavioralCloning

        h = settings.hyperparameters
        trainer.behavioral_cloning = BehavioralCloning(trainer.policy, bc, loaded[bc.demo_path], h.learning_rate,
                                                       h.batch_size, seed + 7)
    if gail is not None:
        provider.set_demonstrations(loaded[gail.demo_path])


@dataclass
class CheckpointPaths:
    run_dir: str
    brain: str

    @property
    def folder(self) -> str:
        return os.path.join(self.run_dir, self.brain)

    def step_files(self, step: int) -> tuple[str, str]:
        base = os.path.join(self.folder, f"{self.brain}-{step}")
        return base + ".onnx", base + ".pt"

    def steps_on_disk(self) -> dict[int, dict[str, str]]:
        """{step: {"pt": path, "onnx": path}} of the numbered checkpoint files in the folder."""
        pattern = re.compile(re.escape(self.brain) + r"-(\d+)\.(pt|onnx)")
        found: dict[int, dict[str, str]] = {}
        for name in os.listdir(self.folder) if os.path.isdir(self.folder) else ():
            match = pattern.fullmatch(name)
            if match:
                found.setdefault(int(match.group(1)), {})[match.group(2)] = os.path.join(self.folder, name)
        return found

    @property
    def latest(self) -> str:
        return os.path.join(self.folder, "checkpoint.pt")

    @property
    def replay_buffer(self) -> str:
        """SAC's replay buffer (save_replay_buffer), rewritten with every checkpoint."""
        return os.path.join(self.folder, "last_replay_buffer.npz")

    @property
    def final_onnx(self) -> str:
        return os.path.join(self.run_dir, f"{self.brain}.onnx")


@dataclass
class BehaviorRunner:
    brain: str
    spec: BehaviorSpec
    settings: object  # TrainerSettings
    trainer: Trainer  # PPO, SAC or POCA (trainer/common/trainer_interface.py)
    paths: CheckpointPaths
    training: bool
    next_summary: int = 0
    next_checkpoint: int = 0
    reward_buffer: deque = field(default_factory=lambda: deque(maxlen=1000))
    returns_since_checkpoint: list[float] = field(default_factory=list)
    last_checkpoint_step: int = -1
    resumed_next_summary: int | None = None  # from the checkpoint's "Summaries" entry (--resume)
    writes_files: bool = True  # False on data-parallel ranks other than 0 (trainer/distributed.py)
    self_play: SelfPlay | None = None  # ``self_play:`` while training (trainer/selfplay.py)
    # (brain, onnx path, step, final) after each checkpoint is written: --record-video's clip
    on_checkpoint: Callable[[str, str, int, bool], object] | None = None

    @classmethod
    def create(cls, brain: str, spec: BehaviorSpec, settings, run_dir: str, seed: int, device: str,
               training: bool, use_numpy_update: bool = True,
               teams: TeamController | None = None) -> "BehaviorRunner":
        """``use_numpy_update``: MLAGENTS_LIKE_NUMPY_UPDATE (trainer.config.env_vars); ``teams``:
        the run's learning-team controller, for a behavior with ``self_play`` (trainer/selfplay.py)."""
        trainer = make_trainer(brain, spec, settings, seed, device, use_numpy_update)
        runner = cls(brain, spec, settings, trainer, CheckpointPaths(run_dir, brain), training)
        if settings.self_play is not None and training:  # inference: every team plays the trained policy
            runner.self_play = SelfPlay(settings.self_play, trainer, teams or TeamController(), seed)
        os.makedirs(runner.paths.folder, exist_ok=True)
        return runner

    # ----------------------------------------------------------------------------- lifecycle
    def restore(self, path: str, reset_step: bool) -> None:
        """--resume (reset_step False) or --initialize-from / init_path (reset_step True)."""
        if not os.path.isfile(path):
            raise UserError(
                f"No checkpoint for behavior '{self.brain}' at {path}. Check --run-id / --initialize-from, "
                "or start a new run without --resume."
            )
        self._load_state(path, load_checkpoint(path), reset_step)

    def _load_state(self, path: str, state: dict, reset_step: bool) -> None:
        try:
            self.trainer.load_state_dict(state)
        except (KeyError, RuntimeError, ValueError) as err:
            raise UserError(
                f"Checkpoint {path} does not fit behavior '{self.brain}' (its network or observation/action "
                f"spec differs): {err}. Use a checkpoint of the same configuration or start fresh with --force."
            ) from None
        if reset_step:
            self.trainer.restart_counters()
        else:
            if self.self_play is not None and "SelfPlay" in state:  # the window, ELO and schedule
                self.self_play.load_state_dict(state["SelfPlay"])
            if "Summaries" in state:
                self.resumed_next_summary = int(state["Summaries"]["next_step"])
            if self.saves_replay_buffer and self.training:  # --resume continues the replay buffer it saved
                if os.path.isfile(self.paths.replay_buffer):
                    self.trainer.load_replay_buffer(self.paths.replay_buffer)
                    logger.info("Loaded the replay buffer of behavior %s (%d experiences) from %s.",
                                self.brain, self.trainer.replay_buffer_size(), self.paths.replay_buffer)
                else:
                    logger.warning("No replay buffer at %s: behavior %s starts with an empty one.",
                                   self.paths.replay_buffer, self.brain)
        logger.info("Loaded %s for behavior %s at step %d.", path, self.brain, self.trainer.step)

    def resume(self, status: TrainingStatus) -> None:
        """--resume: load the newest checkpoint that verifies, then tidy the folder for it.

        checkpoint.pt is written last of a checkpoint's files (``save_checkpoint``), so a run
        killed in between leaves a newer ``<brain>-<step>.pt``: the newest of the two that loads
        and passes its checksum wins; a damaged file is named in an error line and the next older
        one is tried (docs/reliability.md)."""
        candidates = [(step, files["pt"]) for step, files in self.paths.steps_on_disk().items() if "pt" in files]
        candidates.sort(reverse=True)
        chosen: tuple[int, str, dict] | None = None
        failures: list[str] = []
        if os.path.isfile(self.paths.latest):
            try:
                state = load_checkpoint(self.paths.latest)
                chosen = (checkpoint_step(state), self.paths.latest, state)
            except CheckpointError as error:
                logger.error("%s; trying the previous checkpoint.", error.problem)
                failures.append(self.paths.latest)
        for step, path in candidates:
            if chosen is not None and step <= chosen[0]:
                break
            try:
                state = load_checkpoint(path)
            except CheckpointError as error:
                logger.error("%s; trying the previous checkpoint.", error.problem)
                failures.append(path)
                continue
            chosen = (checkpoint_step(state), path, state)
            break
        if chosen is None:
            tried = ", ".join(failures) if failures else f"no checkpoint in {self.paths.folder}"
            raise CheckpointError(
                f"No usable checkpoint for behavior '{self.brain}' ({tried}). Start a new run with --force, "
                "or pick another --run-id."
            )
        step, path, state = chosen
        self._load_state(path, state, reset_step=False)
        elo = status.get_elo(self.brain)
        if self.self_play is not None and "SelfPlay" not in state and elo is not None:
            self.self_play.start_from_elo(elo)  # e.g. a run of mlagents-learn: its rating, a new window
        self.tidy_after_resume(status)

    def tidy_after_resume(self, status: TrainingStatus) -> None:
        """Make the folder and training_status.json agree with the step resumed from: numbered
        files of later steps (a checkpoint the killed run had not finished, or a damaged one) and
        orphan halves (a .pt without its .onnx or the reverse) are removed, the resumed step's
        missing .onnx is exported again, and checkpoints beyond keep_checkpoints are deleted
        (leftover temp files went earlier: ``trainer.results_dir.prepare_run_dir``)."""
        step = self.trainer.step
        removed: list[str] = []
        on_disk = self.paths.steps_on_disk()
        if step in on_disk and "onnx" not in on_disk[step]:
            onnx_path, _ = self.paths.step_files(step)
            self.trainer.export_onnx(onnx_path)
            on_disk[step]["onnx"] = onnx_path
        complete: dict[int, dict[str, str]] = {}
        for s, files in on_disk.items():
            if s > step or len(files) < 2:
                for f in files.values():
                    os.remove(f)
                    removed.append(f)
            else:
                complete[s] = files
        tracked = {entry.steps: entry for entry in status.checkpoints(self.brain)}
        entries = []
        for s in sorted(complete):
            entry = tracked.get(s)
            if entry is None:
                entry = CheckpointEntry(steps=s, file_path=complete[s]["onnx"], reward=None,
                                        creation_time=os.path.getmtime(complete[s]["pt"]),
                                        auxillary_file_paths=[complete[s]["pt"]])
            entries.append(entry)
        keep = self.settings.keep_checkpoints
        if keep > 0 and len(entries) > keep:
            for old in entries[:-keep]:
                for f in complete[old.steps].values():
                    os.remove(f)
                    removed.append(f)
            entries = entries[-keep:]
        status.set_checkpoints(self.brain, entries)
        if removed:
            logger.info("Removed %d file(s) a previous run left unfinished or beyond keep_checkpoints: %s",
                        len(removed), ", ".join(os.path.basename(f) for f in removed))
        self.last_checkpoint_step = step

    def schedule_from_step(self) -> None:
        """Next summary and checkpoint after (re)starting at the trainer's step. A resumed run
        continues with the first summary its checkpoint's run had not written (a stop writes the
        unfinished period's summary early, ``RunState.summarize_partial``): every TensorBoard
        step is written once (docs/cluster.md)."""
        s = self.settings
        step = self.trainer.step
        self.next_summary = (step // s.summary_freq + 1) * s.summary_freq
        if self.resumed_next_summary is not None and self.resumed_next_summary > step:
            self.next_summary = self.resumed_next_summary
        interval = self.checkpoint_interval
        self.next_checkpoint = (step // interval + 1) * interval

    @property
    def checkpoint_interval(self) -> int:
        s = self.settings
        if s.even_checkpoints:
            return max(1, s.max_steps // max(1, s.keep_checkpoints))
        return max(1, s.checkpoint_interval)

    @property
    def saves_replay_buffer(self) -> bool:
        return self.trainer.saves_replay_buffer

    @property
    def max_steps(self) -> int:
        return self.settings.max_steps

    @property
    def done(self) -> bool:
        return not self.training or self.trainer.step > self.settings.max_steps

    # ----------------------------------------------------------------------------- experience
    def policy_for(self, team: int):
        """THE place that decides which policy acts for a team of this behavior: the trainer's,
        unless self-play gives the team a snapshot (trainer/selfplay.py)."""
        if self.self_play is None:
            return self.trainer.policy
        return self.self_play.policy_for(team)

    def learns_from(self, team: int) -> bool:
        """Whether the trajectories of ``team`` train this behavior (all teams without self-play)."""
        return self.self_play is None or self.self_play.is_learning(team)

    def add_trajectory(self, traj: Trajectory, status: TrainingStatus) -> dict[str, float]:
        """Checkpoint if this trajectory crosses the next interval (named with the step before it),
        then hand it to the trainer (with self-play, an episode's end is also a game for the ELO)."""
        if not self.training:  # --inference: the steps count (summaries at summary_freq), nothing learns
            self.trainer.step += len(traj)
            return {}
        if self.done:  # past max_steps while other behaviors still train
            return {}
        elo = None
        if self.self_play is not None and len(traj):
            group_done = traj.group is None or traj.group.all_done  # GroupTracker's columns (POCA)
            elo = self.self_play.rate_trajectory(float(traj.rewards[-1]), traj.done, traj.interrupted, group_done)
        if self.trainer.step + len(traj) >= self.next_checkpoint:
            if self.writes_files:
                self.save_checkpoint(status, summary_follows=self.trainer.step + len(traj) >= self.next_summary)
            while self.next_checkpoint <= self.trainer.step + len(traj):
                self.next_checkpoint += self.checkpoint_interval
        stats = self.trainer.process_trajectory(traj)
        if elo is not None:
            stats = {**stats, ELO_STAT: elo}
        return stats

    def add_episodes(self, returns: list[float]) -> None:
        self.reward_buffer.extend(returns)
        self.returns_since_checkpoint.extend(returns)

    # ----------------------------------------------------------------------------- files
    def save_checkpoint(self, status: TrainingStatus, final: bool = False, summary_follows: bool = True) -> str:
        """<brain>-<step>.pt, then its .onnx, then checkpoint.pt (each atomic); the caller writes
        training_status.json next. A kill between any two leaves the previous checkpoint.pt intact
        and files that ``tidy_after_resume`` recognises."""
        step = self.trainer.step
        onnx_path, pt_path = self.paths.step_files(step)
        state = self.trainer.state_dict()
        # The first summary a run resumed from this checkpoint writes. The final save comes after
        # the last summary (and a stop's early one): the next is the first not written. A periodic
        # save whose trajectory also reaches the next summary comes just before that summary, which
        # this run goes on to write in the same iteration (a run killed without warning too, unless
        # it dies in between): the one after. Otherwise (checkpoint_interval not a multiple of
        # summary_freq) the next summary is still far: a run killed before it must not skip it (the
        # soak lost one label per kill that way, bench/RESULTS.md).
        next_summary = self.next_summary
        if not final and summary_follows:
            next_summary += self.settings.summary_freq
        state["Summaries"] = {"next_step": torch.tensor(next_summary, dtype=torch.int64)}
        if self.self_play is not None:
            state["SelfPlay"] = self.self_play.state_dict()
            status.set_elo(self.brain, self.self_play.current_elo)
        save_checkpoint(pt_path, state)
        crash_points.reached("checkpoint.pt")
        self.trainer.export_onnx(onnx_path)
        crash_points.reached("checkpoint.onnx")
        save_checkpoint(self.paths.latest, state)
        crash_points.reached("checkpoint.latest")
        if self.saves_replay_buffer:  # after checkpoint.pt: a kill in between resumes with the older buffer
            self.trainer.save_replay_buffer(self.paths.replay_buffer)
        logger.info("Exported %s", onnx_path)
        reward = float(np.mean(self.returns_since_checkpoint)) if self.returns_since_checkpoint else None
        self.returns_since_checkpoint = []
        entry = CheckpointEntry(steps=step, file_path=onnx_path, reward=reward, creation_time=time.time(),
                                auxillary_file_paths=[pt_path])
        if step != self.last_checkpoint_step:
            for old in status.add_checkpoint(self.brain, entry, self.settings.keep_checkpoints):
                for f in [old.file_path, *old.auxillary_file_paths]:
                    if f and os.path.exists(f) and f not in (onnx_path, pt_path):
                        os.remove(f)
        self.last_checkpoint_step = step
        if final:
            atomic_copy(onnx_path, self.paths.final_onnx)
            logger.info("Copied %s to %s.", onnx_path, self.paths.final_onnx)
            status.set_final_checkpoint(self.brain, CheckpointEntry(
                steps=step, file_path=self.paths.final_onnx, reward=reward, creation_time=entry.creation_time,
                auxillary_file_paths=[pt_path]))
        if self.on_checkpoint is not None:
            self.on_checkpoint(self.brain, onnx_path, step, final)
        return onnx_path
