"""The code of ML-Agents' "Python Low Level API" page (docs/Python-LLAPI.md of Release 22), ported
to this project's package by changing only its imports.

The page's three snippets, in order, each completed where the page writes "...":

1. "Loading a Unity Environment": a build named ``3DBall`` in the working directory, seed 1;
   completed with the loop the page's "The BaseEnv interface" section describes (get_steps,
   DecisionSteps / TerminalSteps by agent id, set_actions with an ActionTuple, step), played for
   ``EPISODES`` episodes of one tracked agent.
2. "EngineConfigurationChannel": the Unity Editor (no file_name), time scale 2.
3. "EnvironmentParameters": the Editor again, a float parameter.

Run it where ``3DBall`` is a Unity build (or the stub's: ``unity-stub-env --task ball3d
--write-launcher .`` writes ``StubBall3D.x86_64``; rename it ``3DBall.x86_64``), then press Play in
the Editor twice (or start ``unity-stub-env --task basic --mlagents-port 5004`` twice). The last line printed is a JSON summary
(tests/interop/test_llapi_example.py runs this file under both packages and compares them).
"""
import json

import numpy as np

from mlagents_like_envs.base_env import ActionTuple
from mlagents_like_envs.environment import UnityEnvironment
from mlagents_like_envs.side_channel.engine_configuration_channel import EngineConfigurationChannel
from mlagents_like_envs.side_channel.environment_parameters_channel import EnvironmentParametersChannel

EPISODES = 3
summary = {}

# 1. "Loading a Unity Environment"
# This is a non-blocking call that only loads the environment.
env = UnityEnvironment(file_name="3DBall", seed=1, side_channels=[])
# Start interacting with the environment.
env.reset()
behavior_names = env.behavior_specs.keys()
# ... the BaseEnv interface, as the page describes it:
behavior_name = list(behavior_names)[0]
spec = env.behavior_specs[behavior_name]
summary["behavior"] = behavior_name
summary["observation_shapes"] = [list(o.shape) for o in spec.observation_specs]
summary["action"] = [spec.action_spec.continuous_size, list(spec.action_spec.discrete_branches)]
np.random.seed(1)
episode_rewards = []
for episode in range(EPISODES):
    env.reset()
    decision_steps, terminal_steps = env.get_steps(behavior_name)
    tracked_agent = decision_steps.agent_id[0]
    episode_reward = 0.0
    done = False
    while not done:
        # one random action per deciding agent, as an ActionTuple of the spec's shapes
        action = spec.action_spec.random_action(len(decision_steps))
        env.set_actions(behavior_name, ActionTuple(continuous=action.continuous, discrete=action.discrete))
        env.step()
        decision_steps, terminal_steps = env.get_steps(behavior_name)
        if tracked_agent in decision_steps:
            episode_reward += float(decision_steps[tracked_agent].reward)
        if tracked_agent in terminal_steps:
            episode_reward += float(terminal_steps[tracked_agent].reward)
            done = True
    episode_rewards.append(episode_reward)
summary["episode_rewards"] = episode_rewards
env.close()

# 2. "EngineConfigurationChannel"
channel = EngineConfigurationChannel()

env = UnityEnvironment(side_channels=[channel])

channel.set_configuration_parameters(time_scale = 2.0)

i = env.reset()
summary["editor_behaviors"] = sorted(env.behavior_specs)
env.close()

# 3. "EnvironmentParameters"
channel = EnvironmentParametersChannel()

env = UnityEnvironment(side_channels=[channel])

channel.set_float_parameter("parameter_1", 2.0)

i = env.reset()
summary["editor_reset_returns"] = i
env.close()

print(json.dumps(summary))
