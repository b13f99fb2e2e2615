"""``UnityEnvironment``: one Unity build, the Unity Editor or the stub, stepped from Python.

The environment is launched and spoken to exactly as ``mlagents-like-learn`` does it: the
executable lookup, command line and process handling of ``trainer.envs.launcher``, the gRPC
server of ``trainer.protocol.server`` (Python is the server, the environment the client) and its
codec. What this module adds is mlagents_envs 1.1.0's contract on top: its constructor
arguments, the reset/step/get_steps/set_actions cycle, side channels, and its exception classes
in place of the trainer's errors (docs/python-api.md, "Porting a script").
"""
from __future__ import annotations

import atexit
import contextlib
import logging
from collections.abc import Mapping

import numpy as np

from mlagents_like_envs.base_env import (
    ActionTuple,
    AgentId,
    BaseEnv,
    BehaviorMapping,
    BehaviorName,
    BehaviorSpec,
    DecisionSteps,
    TerminalSteps,
)
from mlagents_like_envs.exception import (
    UnityActionException,
    UnityCommunicationException,
    UnityCommunicatorStoppedException,
    UnityEnvironmentException,
    UnityTimeOutException,
    UnityWorkerInUseException,
)
from mlagents_like_envs.side_channel.side_channel import SideChannel
from mlagents_like_envs.side_channel.side_channel_manager import SideChannelManager
from protos.errors import ProtocolError
from protos.versions import COMMUNICATION_VERSION
from trainer.config.env_vars import EnvVars
from trainer.envs.cpus import spin_budget
from trainer.envs.launcher import PORT_ARG, SimulatorProcess, build_launch_command, resolve_env_path
from trainer.errors import (
    PortInUseError,
    SimulatorExitedError,
    UnityCommunicatorStoppedError,
    UnityTimeOutError,
    UserError,
)
from trainer.protocol.server import UnityEndpoint

logger = logging.getLogger(__name__)


class _AgentNotDeciding(UnityActionException, IndexError):
    """``set_action_for_agent`` for an agent that did not ask for a decision (mlagents_envs
    raises IndexError here; this is both)."""


@contextlib.contextmanager
def _as_unity_exceptions(worker_id: int):
    """The trainer's errors, raised as the mlagents_envs exception a script expects."""
    try:
        yield
    except UnityTimeOutError as error:
        raise UnityTimeOutException(str(error)) from None
    except UnityCommunicatorStoppedError as error:
        raise UnityCommunicatorStoppedException(str(error)) from None
    except PortInUseError as error:
        raise UnityWorkerInUseException(worker_id, str(error)) from None
    except (SimulatorExitedError, UserError) as error:  # process exited, no executable, versions
        raise UnityEnvironmentException(str(error)) from None
    except ProtocolError as error:
        raise UnityCommunicationException(str(error)) from None


class UnityEnvironment(BaseEnv):
    API_VERSION = COMMUNICATION_VERSION
    DEFAULT_EDITOR_PORT = 5004  # the Editor connects here when no executable is given
    BASE_ENVIRONMENT_PORT = 5005  # an executable's port is base_port + worker_id
    _PORT_COMMAND_LINE_ARG = PORT_ARG

    def __init__(
        self,
        file_name: str | None = None,
        worker_id: int = 0,
        base_port: int | None = None,
        seed: int = 0,
        no_graphics: bool = False,
        no_graphics_monitor: bool = False,
        timeout_wait: int = 60,
        additional_args: list[str] | None = None,
        side_channels: list[SideChannel] | None = None,
        log_folder: str | None = None,
        num_areas: int = 1,
    ) -> None:
        """Launch ``file_name`` (a Unity build's path, with or without its extension, or
        ``stub:TASK`` for the built-in MuJoCo stub), or wait for the Editor's Play button when it
        is None, and connect. Listens on 127.0.0.1:``base_port + worker_id``; ``seed`` and
        ``num_areas`` go to the environment in the handshake, ``additional_args`` on its command
        line, its log to ``log_folder/Player-<worker_id>.log``. Waits up to ``timeout_wait`` s
        for each answer."""
        self._loaded = False
        self._process: SimulatorProcess | None = None
        self._endpoint: UnityEndpoint | None = None
        self._worker_id = worker_id
        self._timeout_wait = timeout_wait
        self._env_state: dict[str, tuple[DecisionSteps, TerminalSteps]] = {}
        self._env_actions: dict[str, ActionTuple] = {}
        self._is_first_message = True
        if file_name is None and worker_id != 0:
            raise UnityEnvironmentException(
                "With file_name=None the environment is the Unity Editor, which connects as worker 0 only; "
                "pass worker_id=0, or a built player's path as file_name.")
        self._side_channel_manager = SideChannelManager(side_channels)
        if base_port is None:
            base_port = self.BASE_ENVIRONMENT_PORT if file_name else self.DEFAULT_EDITOR_PORT
        self._port = base_port + worker_id
        atexit.register(self._close)
        try:
            with _as_unity_exceptions(worker_id):
                self._connect(file_name, base_port, seed, no_graphics, no_graphics_monitor,
                              additional_args, log_folder, num_areas)
        except BaseException:
            self._close(0)
            raise
        self._loaded = True

    def _connect(self, file_name, base_port, seed, no_graphics, no_graphics_monitor, additional_args,
                 log_folder, num_areas) -> None:
        """Listen, launch, handshake: as a worker of the trainer's pool does (trainer/envs/pool.py)."""
        choices = EnvVars.from_environ()  # MLAGENTS_LIKE_TRANSPORT and _SPIN_WAIT_MS, as the trainer reads them
        spin_wait = spin_budget(2, choices.spin_wait_s)  # this process and the environment's
        if file_name is not None:
            command = build_launch_command(
                resolve_env_path(file_name), self._worker_id, base_port, no_graphics, no_graphics_monitor,
                log_folder, list(additional_args or []), seed, num_areas, spin_wait, choices.transport)
            self._process = SimulatorProcess(command, self._worker_id, log_folder=log_folder)
        process = self._process
        self._endpoint = UnityEndpoint(
            self._port, timeout_wait=self._timeout_wait,
            is_alive=process.is_alive if process else None,
            describe=process.describe if process else "the Unity Editor",
            spin_wait=spin_wait, transport=choices.transport, editor=process is None)
        self._endpoint.start()  # listen before launching, so the environment finds us
        if process is not None:
            process.start()
        else:
            logger.info("Listening on port %d. Start training by pressing the Play button in the Unity Editor.",
                        self._port)
        init = self._endpoint.handshake(seed, num_areas)
        self.academy_capabilities = init.capabilities
        logger.info("Connected to Unity environment with package version %s and communication version %s",
                    init.package_version, init.communication_version)

    # ------------------------------------------------------------------ the cycle
    def reset(self) -> None:
        self._require_loaded()
        with _as_unity_exceptions(self._worker_id):
            result = self._endpoint.reset(bytes(self._side_channel_manager.generate_side_channel_messages()))
        self._take(result)
        self._is_first_message = False

    def step(self) -> None:
        if self._is_first_message:
            return self.reset()
        self._require_loaded()
        # behaviors without actions get zeros from the endpoint, as in mlagents_envs
        side_channel = bytes(self._side_channel_manager.generate_side_channel_messages())
        with _as_unity_exceptions(self._worker_id):
            result = self._endpoint.step(self._env_actions, side_channel)
        self._take(result)

    def _take(self, result) -> None:
        self._env_state = dict(result.steps)
        self._env_actions.clear()
        self._side_channel_manager.process_side_channel_message(result.side_channel)

    @property
    def behavior_specs(self) -> Mapping[BehaviorName, BehaviorSpec]:
        return BehaviorMapping(self._endpoint.behavior_specs if self._endpoint is not None else {})

    def get_steps(self, behavior_name: BehaviorName) -> tuple[DecisionSteps, TerminalSteps]:
        self._assert_behavior_exists(behavior_name)
        return self._env_state[behavior_name]

    def set_actions(self, behavior_name: BehaviorName, action: ActionTuple) -> None:
        self._assert_behavior_exists(behavior_name)
        if behavior_name not in self._env_state:
            return
        n_agents = len(self._env_state[behavior_name][0])
        self._env_actions[behavior_name] = self._validated(behavior_name, action, n_agents)

    def set_action_for_agent(self, behavior_name: BehaviorName, agent_id: AgentId, action: ActionTuple) -> None:
        self._assert_behavior_exists(behavior_name)
        if behavior_name not in self._env_state:
            return
        action = self._validated(behavior_name, action, 1)
        decision = self._env_state[behavior_name][0]
        rows = np.flatnonzero(decision.agent_id == agent_id)
        if len(rows) == 0:
            raise _AgentNotDeciding(
                f"Agent {agent_id} of behavior {behavior_name} did not request a decision at the last step; "
                f"the deciding agents are {decision.agent_id.tolist()}.")
        spec = self.behavior_specs[behavior_name].action_spec
        actions = self._env_actions.setdefault(behavior_name, spec.empty_action(len(decision)))
        actions.continuous[rows[0]] = action.continuous[0]
        actions.discrete[rows[0]] = action.discrete[0]

    def _validated(self, behavior_name: str, action: ActionTuple, n_agents: int) -> ActionTuple:
        """``action`` if it holds [n_agents, size] arrays for both parts, else UnityActionException."""
        if not isinstance(action, ActionTuple):
            raise UnityActionException(
                f"Actions for behavior {behavior_name} must be an ActionTuple (mlagents_like_envs.base_env), "
                f"not {type(action).__name__}; e.g. ActionTuple(continuous=array) or ActionTuple(discrete=array).")
        spec = self.behavior_specs[behavior_name].action_spec
        for part, size, given in (("continuous", spec.continuous_size, action.continuous),
                                  ("discrete", spec.discrete_size, action.discrete)):
            shape = None if given is None else given.shape
            if shape != (n_agents, size):
                raise UnityActionException(
                    f"The behavior {behavior_name} needs a {part} input of dimension {(n_agents, size)} for "
                    f"(<number of agents>, <action size>) but received input of dimension {shape}")
        return action

    def _assert_behavior_exists(self, behavior_name: str) -> None:
        if behavior_name not in self.behavior_specs:
            known = ", ".join(self.behavior_specs) or "none yet: call reset() first"
            raise UnityActionException(
                f"The group {behavior_name} does not correspond to an existing agent group in the "
                f"environment (behaviors: {known}).")

    def _require_loaded(self) -> None:
        if not self._loaded:
            raise UnityEnvironmentException("No Unity environment is loaded.")

    # ------------------------------------------------------------------ closing
    def close(self) -> None:
        """Tell the environment to quit (status 400), stop listening, and wait up to
        ``timeout_wait`` s for the process to exit before it is ended."""
        self._require_loaded()
        self._close()

    def _close(self, timeout: float | None = None) -> None:
        timeout = self._timeout_wait if timeout is None else timeout
        self._loaded = False
        atexit.unregister(self._close)
        if self._endpoint is not None:
            self._endpoint.close()
        if self._process is not None:
            if not self._process.wait_for_exit(timeout) and timeout > 0:
                logger.warning("Environment timed out shutting down. Killing...")
            self._process.close(timeout=1.0)
            logger.debug("%s", self._process.describe())
            self._process = None

    def __enter__(self) -> "UnityEnvironment":
        return self

    def __exit__(self, *exc) -> None:
        if self._loaded:
            self._close()
