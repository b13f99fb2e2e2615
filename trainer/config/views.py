"""Flat, frozen views of one behavior's ``TrainerSettings`` for the algorithms, generated from the settings classes.

An algorithm reads everything it needs as one flat object: ``hp.batch_size``, ``hp.hidden_units``,
``hp.reward_signals``. Neither the fields nor their defaults are written here: ``algorithm_view``
builds the class from the settings classes of settings.py and ``from_settings`` fills it, so a key
added to settings.py reaches every algorithm with no second edit and no mapper to forget. A view
holds, in this order:

- every field of the algorithm's hyperparameters class (``PPOSettings``, ``SACSettings``);
- ``max_steps`` (the decay horizon of the linear schedules);
- every field of ``network_settings`` except ``memory``, which becomes ``memory_size`` (0: no LSTM)
  and ``sequence_length``;
- ``reward_signals``: signal name -> ``(gamma, strength)``;
- ``reward_signal_networks``: each intrinsic signal (every one but ``extrinsic``) -> its
  ``SignalNetwork``: the signal's own keys (``learning_rate``, ``use_actions``, ...) and its
  ``network_settings``, flat.

Defaults are those of a default-constructed settings object (so derived defaults such as SAC's
``reward_signal_steps_per_update`` are the settings class's own).
"""
from __future__ import annotations

import dataclasses
from typing import Any

from trainer.config.settings import (
    REWARD_SIGNAL_CLASSES,
    MemorySettings,
    NetworkSettings,
    RewardSignalSettings,
    TrainerSettings,
)

#: the keys every reward signal has; the others belong to the intrinsic signals' own learners
_SIGNAL_KEYS = tuple(f.name for f in dataclasses.fields(RewardSignalSettings))


def _default_field(name: str, annotation: Any, value: Any) -> tuple[str, Any, Any]:
    """A make_dataclass field spec whose default is ``value`` (a factory for dicts and lists)."""
    if isinstance(value, (dict, list)):
        return name, annotation, dataclasses.field(default_factory=lambda v=value: type(v)(v))
    return name, annotation, dataclasses.field(default=value)


def _fields_of(instance: Any, skip: tuple[str, ...] = ()) -> list[tuple[str, Any, Any]]:
    """Field specs for every field of the settings object ``instance``, defaulting to its values."""
    return [_default_field(f.name, f.type, getattr(instance, f.name))
            for f in dataclasses.fields(instance) if f.name not in skip]


def _network_fields() -> list[tuple[str, Any, Any]]:
    return _fields_of(NetworkSettings(), skip=("memory",))


def _network_values(network: NetworkSettings) -> dict[str, Any]:
    return {f.name: getattr(network, f.name) for f in dataclasses.fields(network) if f.name != "memory"}


def _make(name: str, fields: list[tuple[str, Any, Any]], module: str, namespace: dict[str, Any]) -> type:
    cls = dataclasses.make_dataclass(name, fields, frozen=True, namespace=namespace)
    cls.__module__ = module  # where it is defined for readers, repr and pickle
    return cls


def _signal_network_class() -> type:
    fields: list[tuple[str, Any, Any]] = []
    seen: set[str] = set()
    for cls in REWARD_SIGNAL_CLASSES.values():
        for spec in _fields_of(cls(), skip=_SIGNAL_KEYS):
            if spec[0] not in seen:  # the first signal that has a key gives its default
                seen.add(spec[0])
                fields.append(spec)
    fields += _network_fields()
    return _make("SignalNetwork", fields, __name__, {
        "__doc__": "An intrinsic reward signal's own learner: its keys and its network_settings, flat.",
    })


SignalNetwork = _signal_network_class()


def signal_networks(settings: TrainerSettings) -> dict[str, Any]:
    """Each intrinsic reward signal of ``settings`` -> its ``SignalNetwork``."""
    names = {f.name for f in dataclasses.fields(SignalNetwork)}
    networks = {}
    for name, signal in settings.reward_signals.items():
        if name == "extrinsic":
            continue
        values = {f.name: getattr(signal, f.name) for f in dataclasses.fields(signal) if f.name not in _SIGNAL_KEYS}
        values.update(_network_values(signal.network_settings))
        networks[name] = SignalNetwork(**{key: value for key, value in values.items() if key in names})
    return networks


def algorithm_view(name: str, hyperparameters_class: type, module: str) -> type:
    """The flat view class, named ``name`` in ``module``, of an algorithm whose YAML ``hyperparameters``
    are ``hyperparameters_class``.

    ``View.from_settings(trainer_settings)`` fills it; hyperparameters the behavior's class lacks
    (POCA's, which are PPO's without ``shared_critic``) keep the view's default, and a behavior with
    hyperparameters the view has no field for is a TypeError (a SAC block handed to PPO).
    """
    trainer_defaults = TrainerSettings(hyperparameters=hyperparameters_class())
    memory_defaults = MemorySettings()
    fields = _fields_of(trainer_defaults.hyperparameters)
    fields.append(_default_field("max_steps", "int", trainer_defaults.max_steps))
    fields += _network_fields()
    fields.append(_default_field("memory_size", "int", 0))
    fields.append(_default_field("sequence_length", "int", memory_defaults.sequence_length))
    fields.append(_default_field("reward_signals", "dict[str, tuple[float, float]]",
                                 _gamma_strength(trainer_defaults)))
    fields.append(_default_field("reward_signal_networks", "dict[str, SignalNetwork]", {}))
    hyperparameter_names = frozenset(f.name for f in dataclasses.fields(hyperparameters_class))

    def from_settings(cls, settings: TrainerSettings):
        hp = settings.hyperparameters
        values = {f.name: getattr(hp, f.name) for f in dataclasses.fields(hp)}
        foreign = sorted(set(values) - hyperparameter_names)
        if foreign:
            raise TypeError(f"{cls.__name__} has no field for the hyperparameters {foreign} of "
                            f"{type(hp).__name__}")
        memory = settings.network_settings.memory
        values.update(_network_values(settings.network_settings))
        values.update(max_steps=settings.max_steps,
                      memory_size=0 if memory is None else memory.memory_size,
                      sequence_length=memory_defaults.sequence_length if memory is None else memory.sequence_length,
                      reward_signals=_gamma_strength(settings),
                      reward_signal_networks=signal_networks(settings))
        return cls(**values)

    return _make(name, fields, module, {
        "__doc__": f"{hyperparameters_class.__name__}, max_steps, network_settings and reward signals of one "
                   f"behavior, flat (generated by trainer/config/views.py).",
        "from_settings": classmethod(from_settings),
    })


def _gamma_strength(settings: TrainerSettings) -> dict[str, tuple[float, float]]:
    return {name: (signal.gamma, signal.strength) for name, signal in settings.reward_signals.items()}
