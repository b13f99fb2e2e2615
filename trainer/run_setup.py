"""What a run checks and builds before its loop starts: the simulators' launch (with the simulator
pool's settings, which configurations data-parallel ranks cannot run, and the results folder), the
torch device and thread count, the behaviors.json recorder, and a warning when the server listens
beyond this machine.

Imported before torch and the loop's modules (trainer/cli.py): the simulators are launched first,
so this module and what it imports at the top use neither numpy nor protobuf
(tests/integration/test_startup_order.py); the rest is imported where it is used."""
from __future__ import annotations

import ipaddress
import logging
import os
from typing import TYPE_CHECKING, NamedTuple

from trainer.config.env_vars import EnvVars
from trainer.envs.pool import DEFAULT_EDITOR_PORT, EnvPool, PoolSettings
from trainer.errors import ConfigError, UserError
from trainer.results_dir import prepare_run_dir, run_dir_of

if TYPE_CHECKING:
    from trainer.artifacts.behaviors import BehaviorRecorder

logger = logging.getLogger("mlagents_like")


class Launched(NamedTuple):
    """What ``launch_simulators`` started: the simulators (booting) and the run's results folder."""

    pool: EnvPool
    run_dir: str


def launch_simulators(options, env_vars: EnvVars) -> Launched:
    """The last checks that need no simulator, the results folder, then listen and launch every
    simulator: from here on they boot while the trainer imports and sets up the rest, and
    ``run_training`` starts the background import of torch (docs/performance.md, "Start-up and
    exit"). The caller closes the pool."""
    env = options.env_settings
    # resolves --env first: a wrong path must not leave a results folder that blocks the rerun
    pool = EnvPool(pool_settings_of(options, env_vars))
    if env_vars.ranks.rank == 0:  # data-parallel ranks: rank 0 alone writes files (trainer/distributed.py)
        run_dir = prepare_run_dir(options)  # refuses before anything starts; the simulators log into it
    else:
        run_dir = run_dir_of(options)
        os.makedirs(os.path.join(run_dir, "run_logs"), exist_ok=True)  # this rank's simulators' logs
    warn_if_not_loopback(env.bind, str(DEFAULT_EDITOR_PORT) if env.env_path is None else
                         f"{env.base_port}" + (f"-{env.base_port + env.num_envs - 1}" if env.num_envs > 1 else ""))
    pool.launch()
    return Launched(pool, run_dir)


def warn_if_not_loopback(bind: str, ports: str) -> None:
    """One warning when the server listens beyond this machine: the gRPC protocol of Unity ML-Agents
    has no authentication, so whoever reaches the port can connect as a simulator."""
    host = bind.strip().strip("[]")
    if host == "localhost":
        return
    try:
        if ipaddress.ip_address(host).is_loopback:
            return
    except ValueError:
        pass
    logger.warning(
        "--bind %s: the trainer listens beyond this machine on port(s) %s. Unity simulators cannot "
        "authenticate, so anyone who can reach these ports can connect and send steps. Keep the default "
        "127.0.0.1 and reach simulators on other nodes through an SSH tunnel or a private network "
        "(README: Simulators on other machines).", bind, ports)


def configure_torch_threads(threads: int) -> None:
    """``threads`` intra-op threads: one unless MLAGENTS_LIKE_TORCH_THREADS says otherwise. The
    simulators run in other processes on the same cores, and for the small networks RL uses,
    torch's thread pool costs more in hand-offs than it gains (measured: act for 256 agents
    3.2 ms with 2 threads, 0.8 ms with 1 on a 2-core machine)."""
    import torch

    torch.set_num_threads(threads)


def check_torch_device(device: str | None) -> None:
    """A --torch-device (torch_settings.device) that torch cannot parse or this machine cannot
    use is a user error, reported before the first network is built on it. None means the CPU."""
    if device is None:
        return
    import torch

    try:
        torch.zeros(1, device=torch.device(device))
    except (RuntimeError, AssertionError, ValueError) as error:
        reason = str(error).strip().splitlines()[0] if str(error).strip() else type(error).__name__
        raise ConfigError(
            f"--torch-device / torch_settings.device {device!r} cannot be used here ({reason}). "
            f"Use cpu, or a device this torch build and machine have (cuda / cuda:N needs a CUDA "
            f"build of torch and a GPU)."
        ) from error


def pool_settings_of(options, env_vars: EnvVars) -> PoolSettings:
    env = options.env_settings
    rank, world = env_vars.ranks.rank, env_vars.ranks.world_size
    if world > 1 and not env.env_path:
        raise UserError(f"{world} data-parallel ranks need --env: each rank launches its own simulators "
                        "(the Unity Editor is one environment).")
    configured = [options.default_settings, *options.behaviors.values()]
    not_ppo = sorted({s.trainer_type for s in configured if s is not None and s.trainer_type != "ppo"})
    if world > 1 and not_ppo:
        raise UserError(f"{world} data-parallel ranks average PPO gradients only; this config uses "
                        f"trainer_type {', '.join(not_ppo)}. Run it as one rank (srun -n 1, or without "
                        "torchrun), or use PPO (docs/cluster.md).")
    if world > 1 and any(s is not None and s.self_play is not None for s in configured):
        raise UserError(f"{world} data-parallel ranks cannot share one self-play schedule; run a config with "
                        "self_play as one rank (srun -n 1, or without torchrun).")
    if world > 1:  # buffer_size and batch_size each rank can take (exit 2 before anything starts)
        from trainer.distributed import check_split  # (numpy: a run alone launches without it)

        check_split(options, world)
    return PoolSettings(
        env_path=env.env_path, env_args=tuple(env.env_args or ()), base_port=env.base_port,
        num_envs=env.num_envs, num_areas=env.num_areas, seed=env.seed, timeout_wait=env.timeout_wait,
        bind=env.bind, no_graphics=options.engine_settings.no_graphics,
        no_graphics_monitor=options.engine_settings.no_graphics_monitor,
        log_folder=os.path.abspath(os.path.join(run_dir_of(options), "run_logs")),
        max_lifetime_restarts=env.max_lifetime_restarts, restarts_rate_limit_n=env.restarts_rate_limit_n,
        restarts_rate_limit_period_s=env.restarts_rate_limit_period_s, debug=options.debug,
        spin_wait_s=env_vars.spin_wait_s, transport=env_vars.transport, first_worker=rank * env.num_envs,
    )


def behavior_recorder(options) -> BehaviorRecorder:
    from trainer.artifacts.behaviors import BehaviorRecorder

    env = options.env_settings
    return BehaviorRecorder(env.num_areas, env.env_path or "editor", tuple(options.environment_parameters))
