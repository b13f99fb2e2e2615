"""Training analytics side channel payloads (trainer → Unity, optional; spec §4.2).

Each payload is a serialized ``google.protobuf.Any`` wrapping ``TrainingEnvironmentInitialized``
or ``TrainingBehaviorInitialized`` (type URL ``type.googleapis.com/communicator_objects.<Msg>``).
Names a user chose (behavior names, paths, lesson names) are sent only as HMAC-SHA256 hex digests
keyed with ``"unity.ml-agents"``, as the reference trainer does. Send only from worker 0 and only
when Unity reported the ``trainingAnalytics`` capability.
"""
from __future__ import annotations

import hashlib
import hmac
import json
import sys

from google.protobuf import any_pb2

from protos.communicator_objects import training_analytics_pb2

ANALYTICS_HASH_KEY = b"unity.ml-agents"


def hash_for_analytics(text: str) -> str:
    """HMAC-SHA256 of ``text`` keyed with "unity.ml-agents", as a lowercase hex string."""
    return hmac.new(ANALYTICS_HASH_KEY, text.encode("utf-8"), hashlib.sha256).hexdigest()


def _pack_any(message) -> bytes:
    wrapper = any_pb2.Any()
    wrapper.Pack(message)
    return wrapper.SerializeToString()


def sanitize_run_options(run_options: dict) -> dict:
    """A copy of the run options dict with behavior names, init/demo paths, environment parameter
    names, lesson names and completion-criteria behaviors replaced by their analytics hash."""
    result = json.loads(json.dumps(run_options, default=str))
    behaviors = result.get("behaviors") or {}
    if behaviors:
        result["behaviors"] = {hash_for_analytics(name): _hash_paths(cfg) for name, cfg in behaviors.items()}
    env_params = result.get("environment_parameters") or {}
    if env_params:
        result["environment_parameters"] = {
            hash_for_analytics(name): _hash_lessons(param) for name, param in env_params.items()
        }
    checkpoint = result.get("checkpoint_settings") or {}
    if checkpoint.get("initialize_from") is not None:
        checkpoint["initialize_from"] = hash_for_analytics(str(checkpoint["initialize_from"]))
    if checkpoint.get("results_dir") is not None:
        checkpoint["results_dir"] = hash_for_analytics(str(checkpoint["results_dir"]))
    return result


def _hash_paths(trainer_settings):
    if isinstance(trainer_settings, dict):
        for key in ("init_path", "demo_path"):
            if trainer_settings.get(key) is not None:
                trainer_settings[key] = hash_for_analytics(str(trainer_settings[key]))
    return trainer_settings


def _hash_lessons(param):
    if not isinstance(param, dict):
        return param
    for lesson in param.get("curriculum") or []:
        if "name" in lesson:
            lesson["name"] = hash_for_analytics(str(lesson["name"]))
        criteria = lesson.get("completion_criteria")
        if criteria and criteria.get("behavior") is not None:
            criteria["behavior"] = hash_for_analytics(str(criteria["behavior"]))
    return param


def encode_training_environment_initialized(
    *,
    mlagents_version: str,
    mlagents_envs_version: str,
    torch_version: str,
    torch_device_type: str,
    num_envs: int,
    num_environment_parameters: int,
    run_options: dict,
    python_version: str | None = None,
) -> bytes:
    """The ``TrainingEnvironmentInitialized`` payload; ``run_options`` is sanitized then JSON-encoded."""
    if python_version is None:
        python_version = "{}.{}.{}".format(*sys.version_info[:3])
    message = training_analytics_pb2.TrainingEnvironmentInitialized(
        mlagents_version=mlagents_version,
        mlagents_envs_version=mlagents_envs_version,
        python_version=python_version,
        torch_version=torch_version,
        torch_device_type=torch_device_type,
        num_envs=num_envs,
        num_environment_parameters=num_environment_parameters,
        run_options=json.dumps(sanitize_run_options(run_options)),
    )
    return _pack_any(message)


def encode_training_behavior_initialized(
    behavior_name: str,
    trainer_type: str,
    *,
    reward_signals: tuple[str, ...] = ("extrinsic",),
    behavioral_cloning_enabled: bool = False,
    recurrent_enabled: bool = False,
    visual_encoder: str = "simple",
    num_network_layers: int = 2,
    num_network_hidden_units: int = 128,
    trainer_threaded: bool = False,
    self_play_enabled: bool = False,
    curriculum_enabled: bool = False,
    config: dict | None = None,
) -> bytes:
    """The ``TrainingBehaviorInitialized`` payload; the behavior name (and init/demo paths in
    ``config``) are hashed."""
    message = training_analytics_pb2.TrainingBehaviorInitialized(
        behavior_name=hash_for_analytics(behavior_name),
        trainer_type=trainer_type,
        extrinsic_reward_enabled="extrinsic" in reward_signals,
        gail_reward_enabled="gail" in reward_signals,
        curiosity_reward_enabled="curiosity" in reward_signals,
        rnd_reward_enabled="rnd" in reward_signals,
        behavioral_cloning_enabled=behavioral_cloning_enabled,
        recurrent_enabled=recurrent_enabled,
        visual_encoder=visual_encoder,
        num_network_layers=num_network_layers,
        num_network_hidden_units=num_network_hidden_units,
        trainer_threaded=trainer_threaded,
        self_play_enabled=self_play_enabled,
        curriculum_enabled=curriculum_enabled,
        config=json.dumps(_hash_paths(json.loads(json.dumps(config or {}, default=str)))),
    )
    return _pack_any(message)
