"""Security posture (docs/reliability.md): one warning when the server listens beyond loopback,
and every YAML read with a safe loader."""
from __future__ import annotations

import logging
import re
from pathlib import Path

import pytest

from trainer.config.loader import read_yaml_file
from trainer.errors import ConfigError
from trainer.run_setup import warn_if_not_loopback

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("bind", ["127.0.0.1", "127.0.0.2", "::1", "[::1]", "localhost"])
def test_loopback_binds_are_quiet(bind, caplog):
    with caplog.at_level(logging.WARNING, logger="mlagents_like"):
        warn_if_not_loopback(bind, "5005")
    assert caplog.records == []


@pytest.mark.parametrize("bind", ["0.0.0.0", "::", "[::]", "10.1.2.3", "node17.cluster"])
def test_other_binds_warn_once_that_simulators_cannot_authenticate(bind, caplog):
    with caplog.at_level(logging.WARNING, logger="mlagents_like"):
        warn_if_not_loopback(bind, "5005-5008")
    assert len(caplog.records) == 1
    text = caplog.records[0].getMessage()
    assert f"--bind {bind}" in text and "5005-5008" in text and "cannot authenticate" in text
    assert "SSH tunnel" in text and "private network" in text


def test_every_yaml_read_in_the_code_uses_a_safe_loader():
    unsafe = re.compile(r"yaml\.(load|load_all|full_load|full_load_all|unsafe_load|unsafe_load_all)\(|"
                        r"yaml\.(Loader|FullLoader|UnsafeLoader|UnsafeConstructor)\b")
    offenders = []
    for folder in ("trainer", "unity_stub_env", "protos", "bench", "scripts", "tests"):
        for path in (ROOT / folder).rglob("*.py"):
            for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
                if unsafe.search(line) and path.name != Path(__file__).name:
                    offenders.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert offenders == []


def test_a_python_object_tag_is_refused_without_running_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    bad = tmp_path / "bad.yaml"
    bad.write_text("behaviors: !!python/object/apply:os.system ['touch pwned']\n")
    with pytest.raises(ConfigError, match="bad.yaml"):
        read_yaml_file(str(bad))
    assert not (tmp_path / "pwned").exists()
