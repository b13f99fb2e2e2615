"""docs/configuration.md's tables against the code: every flag, YAML key and MLAGENTS_LIKE_* variable is
listed, nothing else is, and each documented default, given explicitly, changes nothing."""
from __future__ import annotations

import dataclasses
import os
import re

import pytest
import yaml

from trainer.config import build_parser, run_options_from_dict
from trainer.config.cli_args import SECTIONS
from trainer.config.env_vars import JOB_TEMPLATE_ONLY, KNOWN, EnvVars
from trainer.config.settings import (
    MemorySettings,
    NetworkSettings,
    PPOSettings,
    SACSettings,
    SelfPlaySettings,
    TrainerSettings,
)

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
with open(os.path.join(REPO, "docs", "configuration.md"), encoding="utf-8") as _stream:
    DOC = _stream.read()

# Cells that describe a default instead of giving it; the key must still exist.
DESCRIBED = {"= `steps_per_update`", "5 × `save_steps`", "see below", "`extrinsic` only"}


def table(heading: str) -> list[list[str]]:
    """The rows (cells, stripped) of the first table under the markdown heading ``heading``."""
    match = re.search(rf"^#+ {re.escape(heading)}\n", DOC, re.M)
    assert match, f"no heading {heading!r} in docs/configuration.md"
    rows = []
    for line in DOC[match.end():].splitlines():
        if line.startswith("#"):
            break
        if line.startswith("|"):
            rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
        elif rows:
            break
    assert len(rows) > 2, f"no table under {heading!r}"
    return rows[2:]  # without the header and the |---| line


def names(cell: str) -> list[str]:
    return re.findall(r"`([^`]+)`", cell)


def yaml_value(cell: str):
    """A documented default as YAML: ``none`` is null, backticks are dropped."""
    return None if cell == "none" else yaml.safe_load(cell.strip("`"))


# ----------------------------------------------------------------------------------------------------
# Command line


def test_every_flag_is_in_the_table_and_every_row_is_a_flag():
    parser = build_parser()
    documented = [flag for row in table("Command line") for flag in names(row[0])]
    options = sorted(flag for action in parser._actions for flag in action.option_strings if flag != "-h"
                     and flag != "--help")
    assert sorted(documented) == options


@pytest.mark.parametrize("row", table("Command line"), ids=lambda row: row[0])
def test_a_flags_yaml_location_and_default(row):
    parser = build_parser()
    by_flag = {flag: action for action in parser._actions for flag in action.option_strings}
    for flag in names(row[0]):
        action = by_flag[flag]
        sections = [name for name, cls in SECTIONS.items() if action.dest in {f.name for f in dataclasses.fields(cls)}]
        if sections:
            assert f"`{sections[0]}.{action.dest}`" in row[1], (flag, row[1])
        elif action.dest in ("debug", "deterministic"):
            assert action.dest in row[1]
        else:
            assert row[1].startswith("—"), (flag, row[1])
        default = row[2]
        if default == "off":
            assert action.nargs == 0 and action.default is False, flag
        elif default == "none":
            assert action.default is None, flag
        else:  # given explicitly, the documented default parses to the parser's default
            value = parser.parse_args([flag, default.strip("`")]).__dict__[action.dest]
            assert value == action.default and type(value) is type(action.default), (flag, default)


# ----------------------------------------------------------------------------------------------------
# YAML


def behavior(block: dict) -> TrainerSettings:
    return run_options_from_dict({"behaviors": {"A": block}}).behaviors["A"]


def nested(path: str, value) -> dict:
    """``a.b.c``, v -> {"a": {"b": {"c": v}}}"""
    *parents, last = path.split(".")
    block = {last: value}
    for parent in reversed(parents):
        block = {parent: block}
    return block


def keys_of(cls: type, prefix: str = "") -> set[str]:
    return {prefix + f.name for f in dataclasses.fields(cls)}


TABLES = {  # heading -> (where its keys sit in a behavior block, trainer_type, the keys the code has)
    "Per behavior (`behaviors.<Name>`)": (
        "", "ppo", keys_of(TrainerSettings) - {"hyperparameters"} | keys_of(PPOSettings, "hyperparameters.")),
    "SAC (`trainer_type: sac`) hyperparameters": ("", "sac", keys_of(SACSettings, "hyperparameters.")),
    "`network_settings`": ("network_settings.", "ppo", keys_of(NetworkSettings) | keys_of(MemorySettings, "memory.")),
    "`self_play`": ("self_play.", "ppo", keys_of(SelfPlaySettings)),
}


@pytest.mark.parametrize("heading", TABLES)
def test_every_key_is_in_its_table(heading):
    documented = [names(row[0])[0] for row in table(heading)]
    assert sorted(documented) == sorted(TABLES[heading][2])


@pytest.mark.parametrize("heading, row", [(heading, row) for heading in TABLES for row in table(heading)],
                         ids=lambda value: value if isinstance(value, str) else value[0])
def test_a_keys_documented_default_changes_nothing(heading, row):
    prefix, trainer_type, _ = TABLES[heading]
    key, default = names(row[0])[0], row[1]
    if default in DESCRIBED:
        return
    path = prefix + key
    parent = path.rsplit(".", 1)[0] if "." in path else None
    # the block that holds the key, present but empty (memory: {} means an LSTM of the default size)
    baseline = {"trainer_type": trainer_type, **(nested(parent, {}) if parent else {})}
    given = {"trainer_type": trainer_type, **nested(path, yaml_value(default))}
    assert behavior(given) == behavior(baseline), (path, default)


def test_reward_signal_keys_and_defaults():
    from trainer.config.settings import REWARD_SIGNAL_CLASSES

    rows = table("`reward_signals`")
    assert sorted(names(row[0])[0] for row in rows) == sorted(REWARD_SIGNAL_CLASSES)
    for row in rows:
        signal = names(row[0])[0]
        pairs = re.findall(r"`(\w+)`(?: (\(required\)|[-0-9.e]+|true|false))?", row[1])
        assert sorted(key for key, _ in pairs) == sorted(keys_of(REWARD_SIGNAL_CLASSES[signal])), signal
        extra = {"demo_path": "x.demo"} if signal == "gail" else {}
        baseline = behavior({"reward_signals": {signal: extra}}).reward_signals[signal]
        for key, value in pairs:
            if value and value != "(required)":
                given = behavior({"reward_signals": {signal: {**extra, key: yaml.safe_load(value)}}})
                assert given.reward_signals[signal] == baseline, (signal, key, value)


# ----------------------------------------------------------------------------------------------------
# Environment variables


def test_every_variable_is_in_the_table():
    documented = [names(row[0])[0] for row in table("Environment variables (speed knobs)")]
    assert sorted(documented) == sorted(KNOWN)
    section = DOC[DOC.index("## Environment variables"):]
    for name in JOB_TEMPLATE_ONLY:
        assert f"`{name}`" in section, name


@pytest.mark.parametrize("row", [row for row in table("Environment variables (speed knobs)") if row[1] != "unset"],
                         ids=lambda row: row[0])
def test_a_variables_documented_default_changes_nothing(row):
    name, default = names(row[0])[0], row[1].strip("`")
    assert EnvVars.from_environ({name: default}) == EnvVars.from_environ({}), (name, default)
