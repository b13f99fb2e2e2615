"""PPO's acting and update, alone, for instruction counts under callgrind: one tree against another.

    PYTHONPATH=TREE valgrind --tool=callgrind --compress-strings=no --compress-pos=no \
        --zero-before=getppid --dump-before=getpgrp --callgrind-out-file=OUT \
        .venv/bin/python bench/ppo_instructions.py {basic|ball3d} {act|update} N

Instruction counts do not depend on the load, so two trees can be compared on a busy machine,
where times cannot. Builds a seeded PPOTrainer with the task's network and buffer settings
(configs/basic.yaml, configs/ball3d.yaml), then does N ``policy.act`` calls on fixed observations
(basic: 1 agent, ball3d: 12) or N whole updates (each on a buffer filled with random episodes).
The measured part lies between ``os.getppid()`` and ``os.getpgrp()``, which the callgrind flags
above turn into "zero the counters" and "write them out" (``OUT.1``: its ``summary:`` line is the
count); a background thread keeps the update in this process (numpy_update.fork_pays_off), so the
count is all of its work. Runs unchanged on trees from before issue 29 (f1ce40b), whose PPO
modules had other homes. Prints a checksum of what it computed: equal across trees = same numbers.
"""
from __future__ import annotations

import os
import sys
import threading
import time

import numpy as np

from protos.types import ActionSpec, BehaviorSpec, DimensionProperty, ObservationSpec, ObservationType
from trainer.ppo.hyperparams import PPOHyperparams
from trainer.ppo.trainer import PPOTrainer

try:
    from trainer.common.trajectory import Trajectory
except ImportError:  # trees before issue 29
    from trainer.ppo.buffer import Trajectory

TASKS = {  # observation size, actions, agents, episode length; the YAML's settings
    "basic": (20, ActionSpec(0, (3,)), 1, 3, dict(hidden_units=20, num_layers=1, batch_size=32, buffer_size=256,
                                                 num_epoch=3, normalize=False, beta=5e-3, lambd=0.95,
                                                 max_steps=80000)),
    "ball3d": (8, ActionSpec(2, ()), 12, 1000, dict(hidden_units=128, num_layers=2, batch_size=64, buffer_size=12000,
                                                   num_epoch=3, normalize=True, beta=1e-3, lambd=0.99,
                                                   max_steps=100000)),
}


def main() -> None:
    task, part, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
    threading.Thread(target=time.sleep, args=(1e6,), daemon=True).start()  # no critic child process
    obs_size, actions, agents, length, settings = TASKS[task]
    spec = BehaviorSpec((ObservationSpec((obs_size,), (DimensionProperty.NONE,), ObservationType.DEFAULT, "v"),),
                        actions)
    trainer = PPOTrainer("B", spec, PPOHyperparams(**settings), seed=1)
    policy = trainer.policy
    rng = np.random.default_rng(0)
    checksum = 0.0
    if part == "act":
        obs = [rng.standard_normal((agents, obs_size)).astype(np.float32)]
        policy.act(obs)  # warm
        os.getppid()  # callgrind: --zero-before=getppid
        for _ in range(n):
            checksum += float(policy.act(obs).log_probs.sum())
        os.getpgrp()  # callgrind: --dump-before=getpgrp
    else:
        def fill() -> None:
            while not trainer.ready_to_update():
                o = rng.standard_normal((length, obs_size)).astype(np.float32)
                out = policy.act([o])
                trainer.process_trajectory(Trajectory(
                    obs=[o], next_obs=[o[-1]], rewards=rng.standard_normal(length).astype(np.float32),
                    continuous_actions=out.continuous_raw, discrete_actions=out.discrete,
                    log_probs=out.log_probs, action_masks=None, done=True, interrupted=False))

        fill()
        trainer.update()  # warm
        os.getppid()
        for _ in range(n):
            fill()
            checksum += sum(float(v) for v in trainer.update().values())
        os.getpgrp()
    print(task, part, n, repr(checksum), flush=True)
    os._exit(0)  # no interpreter teardown under callgrind


if __name__ == "__main__":
    main()
