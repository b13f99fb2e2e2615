"""Strict structuring of raw YAML values into frozen dataclasses.

Every problem becomes one ``ConfigError`` that names the full key path (``behaviors.3DBall.
hyperparameters.lambd``), what was expected and what was given, and for unknown keys or values
the closest valid spelling (difflib).
"""
from __future__ import annotations

import dataclasses
import difflib
import math
import types
import typing
from typing import Any, Callable, Iterable, Mapping

from trainer.errors import ConfigError

#: A hook that turns one raw value into its structured form: (raw_value, key_path) -> value.
FieldHook = Callable[[Any, str], Any]


def join_path(path: str, key: object) -> str:
    """``join_path("behaviors", "3DBall") == "behaviors.3DBall"``; an empty path gives the key."""
    return f"{path}.{key}" if path else str(key)


def closest(word: str, candidates: Iterable[str]) -> str | None:
    """The candidate most similar to ``word`` (difflib ratio >= 0.5), or None."""
    matches = difflib.get_close_matches(str(word), list(candidates), n=1, cutoff=0.5)
    return matches[0] if matches else None


def suggestion(word: str, candidates: Iterable[str]) -> str:
    """`` Did you mean 'x'?`` or an empty string."""
    best = closest(word, candidates)
    return f" Did you mean '{best}'?" if best else ""


def describe_value(value: Any) -> str:
    """How a raw YAML value reads in an error message: ``the string 'big'``, ``the list [1, 2]``."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    if isinstance(value, str):
        return f"the string '{value}'"
    if isinstance(value, (int, float)):
        return f"the number {value}"
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, list):
        return f"the list {value}"
    return f"a {type(value).__name__}"


def check_known_keys(raw: Mapping, valid: Iterable[str], path: str) -> None:
    """Raise on the first key of ``raw`` that is not in ``valid``, suggesting the closest one."""
    valid = list(valid)
    for key in raw:
        if key not in valid:
            where = join_path(path, key)
            raise ConfigError(
                f"Unknown key '{where}'.{suggestion(str(key), valid)} "
                f"Valid keys here: {', '.join(valid)}."
            )


def require_mapping(raw: Any, path: str, what: str = "a mapping") -> Mapping:
    """Return ``raw`` if it is a mapping (``None`` reads as empty), else raise naming the path."""
    if raw is None:
        return {}
    if not isinstance(raw, Mapping):
        raise ConfigError(f"'{path}' must be {what}, got {describe_value(raw)}.")
    return raw


def to_bool(value: Any, path: str) -> bool:
    if isinstance(value, bool):
        return value
    raise ConfigError(f"'{path}' must be true or false, got {describe_value(value)}.")


def to_int(value: Any, path: str) -> int:
    """Ints, integral floats (``5.0``) and numeric strings with an integral value (``"5.0e5"``)."""
    if isinstance(value, bool):
        raise ConfigError(f"'{path}' must be an integer, got {describe_value(value)}.")
    if isinstance(value, int):
        return value
    number: float | None = None
    if isinstance(value, float):
        number = value
    elif isinstance(value, str):
        try:
            number = float(value)
        except ValueError:
            number = None
    if number is None or not math.isfinite(number) or number != int(number):
        raise ConfigError(f"'{path}' must be an integer, got {describe_value(value)}.")
    return int(number)


def to_float(value: Any, path: str) -> float:
    """Numbers, and numeric strings (PyYAML reads ``1e-3`` without a dot as a string)."""
    if isinstance(value, bool):
        raise ConfigError(f"'{path}' must be a number, got {describe_value(value)}.")
    if isinstance(value, (int, float)):
        number = float(value)
    elif isinstance(value, str):
        try:
            number = float(value)
        except ValueError:
            raise ConfigError(f"'{path}' must be a number, got {describe_value(value)}.") from None
    else:
        raise ConfigError(f"'{path}' must be a number, got {describe_value(value)}.")
    if math.isnan(number):
        raise ConfigError(f"'{path}' must be a number, got NaN.")
    return number


def to_str(value: Any, path: str) -> str:
    """Strings; plain integers are accepted as their decimal text (``run_id: 2024``)."""
    if isinstance(value, str):
        return value
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    raise ConfigError(f"'{path}' must be a string, got {describe_value(value)}.")


def to_str_list(value: Any, path: str) -> list[str]:
    if not isinstance(value, list):
        raise ConfigError(f"'{path}' must be a list of strings, got {describe_value(value)}.")
    return [to_str(item, f"{path}[{i}]") for i, item in enumerate(value)]


def to_choice(value: Any, path: str, choices: tuple[str, ...]) -> str:
    text = to_str(value, path)
    if text not in choices:
        raise ConfigError(
            f"'{path}' must be one of {', '.join(choices)}, got '{text}'.{suggestion(text, choices)}"
        )
    return text


def convert_value(value: Any, hint: Any, path: str, choices: tuple[str, ...] | None = None) -> Any:
    """Convert one raw value to the annotated type ``hint`` (scalars, Optional, nested dataclass)."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if value is None:
            return None
        return convert_value(value, args[0], path, choices)
    if choices is not None:
        return to_choice(value, path, choices)
    if hint is bool:
        return to_bool(value, path)
    if hint is int:
        return to_int(value, path)
    if hint is float:
        return to_float(value, path)
    if hint is str:
        return to_str(value, path)
    if origin is list:
        return to_str_list(value, path)
    if dataclasses.is_dataclass(hint):
        return structure(hint, value, path)
    raise TypeError(f"no converter for {hint!r} at {path}")  # a bug in the schema, not user input


def structure(cls: type, raw: Any, path: str, hooks: Mapping[str, FieldHook] | None = None) -> Any:
    """Build dataclass ``cls`` from mapping ``raw``: strict keys, typed values, defaults for the rest.

    ``hooks`` maps a field name to a custom converter. Fields listed in ``cls.required_keys`` (a
    ClassVar tuple, optional) must be present. Field metadata ``choices`` restricts string values.
    """
    raw = require_mapping(raw, path)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    check_known_keys(raw, fields, path)
    for key in getattr(cls, "required_keys", ()):
        if raw.get(key) is None:
            raise ConfigError(f"'{join_path(path, key)}' is required but missing.")
    hints = typing.get_type_hints(cls)
    hooks = hooks or {}
    kwargs = {}
    for key, value in raw.items():
        key_path = join_path(path, key)
        if key in hooks:
            kwargs[key] = hooks[key](value, key_path)
        else:
            kwargs[key] = convert_value(value, hints[key], key_path, fields[key].metadata.get("choices"))
    return cls(**kwargs)


def deep_merge(base: Mapping, update: Mapping) -> dict:
    """A new dict: ``base`` with ``update`` laid over it, nested mappings merged key by key."""
    merged = {key: (deep_merge(val, {}) if isinstance(val, Mapping) else val) for key, val in base.items()}
    for key, val in update.items():
        if isinstance(merged.get(key), Mapping) and isinstance(val, Mapping):
            merged[key] = deep_merge(merged[key], val)
        else:
            merged[key] = deep_merge(val, {}) if isinstance(val, Mapping) else val
    return merged
