"""What the trainer tells the simulators through side channels: the environment parameters (and
their samplers or HMM sequences) and the engine configuration; one router per simulator for what
they send back."""
from __future__ import annotations

from protos import side_channels as sc
from trainer.config.env_params import ConstantSampler, HmmSampler, hmm_model, hmm_sequences
from trainer.curriculum import EnvironmentParameterManager


def environment_parameter_messages(manager: EnvironmentParameterManager) -> list[tuple]:
    msgs = []
    for key, sampler in manager.current_samplers().items():
        if isinstance(sampler, HmmSampler):
            codes = hmm_sequences(sampler)
            num_labels = hmm_model(sampler).num_labels
            msgs += [(sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID, payload)
                     for payload in sc.encode_env_sequences(key, codes, num_labels)]
            continue
        if isinstance(sampler, ConstantSampler):
            payload = sc.encode_env_float(key, sampler.value)
        elif sampler.sampler_type == "uniform":
            payload = sc.encode_env_sampler(key, "uniform", sampler.seed, (sampler.min_value, sampler.max_value))
        elif sampler.sampler_type == "gaussian":
            payload = sc.encode_env_sampler(key, "gaussian", sampler.seed, (sampler.mean, sampler.st_dev))
        else:
            payload = sc.encode_env_sampler(key, "multirangeuniform", sampler.seed, sampler.intervals)
        msgs.append((sc.ENVIRONMENT_PARAMETERS_CHANNEL_ID, payload))
    return msgs


def engine_config_messages(engine) -> list[tuple]:
    payloads = sc.encode_engine_config(engine.width, engine.height, engine.quality_level, engine.time_scale,
                                       engine.target_frame_rate, engine.capture_frame_rate)
    return [(sc.ENGINE_CONFIG_CHANNEL_ID, p) for p in payloads]


def make_routers(num_envs: int) -> list[sc.SideChannelRouter]:
    """One side-channel router per simulator; an unknown channel id is warned about once per run."""
    warned: set = set()
    return [sc.SideChannelRouter(warned) for _ in range(num_envs)]
