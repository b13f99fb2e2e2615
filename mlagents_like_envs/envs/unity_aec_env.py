"""``UnityAECEnv``: a ``BaseEnv`` as a PettingZoo ``AECEnv``, in the role of mlagents_envs' wrapper
of the same name: agents act one after another and the environment steps once every live agent
has acted, which is PettingZoo's own ``parallel_to_aec`` conversion of ``UnityParallelEnv`` (agent
names, spaces, rewards and infos as described there)."""
from __future__ import annotations

from pettingzoo.utils.conversions import parallel_to_aec_wrapper

from mlagents_like_envs.base_env import BaseEnv
from mlagents_like_envs.envs.unity_parallel_env import UnityParallelEnv


class UnityAECEnv(parallel_to_aec_wrapper):
    def __init__(self, env: BaseEnv, seed: int | None = None) -> None:
        """Wrap ``env`` (closed when this closes); ``seed``: the action spaces' sampler seed."""
        super().__init__(UnityParallelEnv(env, seed))

    @property
    def possible_agents(self) -> list[str]:
        """Every agent seen since the last reset: it grows as agents begin new episodes."""
        return self.env.possible_agents

    @possible_agents.setter
    def possible_agents(self, _value) -> None:
        pass  # the conversion copies the list once; this reads the parallel env's instead

    def close(self) -> None:
        self.env.close()
