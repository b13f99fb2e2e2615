"""Drive a Unity ML-Agents build (or the stub) from Python with mlagents_envs 1.1.0's API.

The module paths are mlagents_envs' own: ``mlagents_like_envs.environment.UnityEnvironment``,
``mlagents_like_envs.base_env``, ``mlagents_like_envs.exception`` and
``mlagents_like_envs.side_channel.*``, so porting a script means replacing the top-level name
(docs/python-api.md, "Porting a script"). The wire work is the trainer's: its codec, its gRPC
server and its launcher.
"""
# the mlagents_envs release whose API this package follows
__version__ = "1.1.0"
