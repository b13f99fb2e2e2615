"""``--capture-spec FILE``: watch the simulators for a few steps and write the behaviors they
declare (docs/mirror.md), without training."""
from __future__ import annotations

import logging

from protos import side_channels as sc
from trainer.config.env_vars import EnvVars
from trainer.curriculum import EnvironmentParameterManager
from trainer.envs.pool import EnvPool
from trainer.errors import UserError
from trainer.run_setup import behavior_recorder, pool_settings_of
from trainer.side_channel_payloads import engine_config_messages, environment_parameter_messages, make_routers
from trainer.stop import EXIT_STOPPED, STOP

logger = logging.getLogger("mlagents_like")


CAPTURE_STEPS = 20  # exchanges --capture-spec watches before it writes the file


def capture_spec(options, env_vars: EnvVars | None = None, steps: int = CAPTURE_STEPS) -> int:
    """``--capture-spec FILE``: connect to the simulator(s), step ``steps`` times with zero
    actions, write what was seen to FILE (docs/mirror.md) and exit without training."""
    env_vars = env_vars or EnvVars()
    path = options.capture_spec
    params = EnvironmentParameterManager(options.environment_parameters, options.env_settings.seed, {})
    side_channel = sc.pack_messages(environment_parameter_messages(params)
                                    + engine_config_messages(options.engine_settings))
    pool = EnvPool(pool_settings_of(options, env_vars), initial_side_channel=lambda: side_channel)
    recorder = behavior_recorder(options)
    routers = make_routers(pool.num_envs)
    try:
        pool.start()
        results = pool.reset(side_channel)
        for _ in range(steps):
            STOP.check()
            recorder.observe(results)
            for router, res in zip(routers, results):
                if res.side_channel:
                    recorder.observe_stats(key for key, _, _ in router.dispatch(res.side_channel).stats)
            results = pool.step([{} for _ in results], b"").results
        recorder.observe(results)
    except KeyboardInterrupt:
        logger.info("Stopped before the capture finished; nothing written.")
        return EXIT_STOPPED
    finally:
        pool.close()
    if not recorder.write(path):
        raise UserError(f"--capture-spec: the simulator sent no agent in {steps} steps, so there is no "
                        "behavior spec to record; check that the scene's agents request decisions.")
    spec = recorder.spec_file()
    logger.info("Wrote the specs of %d behavior(s) to %s: %s", len(spec.behaviors), path,
                ", ".join(f"{b.name} ({b.agents} agents)" for b in spec.behaviors))
    return 0
