"""checkpoint.pt: atomic round trips and refusing anything that is not plain tensors and containers."""
from __future__ import annotations

import os
import pickle

import pytest
import torch

import trainer.artifacts.checkpoints as checkpoints
from trainer.artifacts.checkpoints import FORMAT_KEY, CheckpointError, content_digest, load_checkpoint, save_checkpoint
from trainer.errors import UserError

STATE = {
    "Policy": {"weight": torch.arange(6.0).reshape(2, 3)},
    "global_step": {"step": torch.tensor(42)},
    "RNG": {"policy_sampling": torch.Generator().manual_seed(1).get_state()},
    "notes": ["a", 1, 2.5, None, True],
}


def test_round_trip(tmp_path):
    path = tmp_path / "Ball" / "checkpoint.pt"  # the folder is created
    save_checkpoint(path, STATE)
    loaded = load_checkpoint(path)
    assert torch.equal(loaded["Policy"]["weight"], STATE["Policy"]["weight"])
    assert int(loaded["global_step"]["step"]) == 42
    assert torch.equal(loaded["RNG"]["policy_sampling"], STATE["RNG"]["policy_sampling"])
    assert loaded["notes"] == ["a", 1, 2.5, None, True]
    assert os.listdir(path.parent) == ["checkpoint.pt"]


def test_failure_mid_write_keeps_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "checkpoint.pt"
    save_checkpoint(path, STATE)
    original = path.read_bytes()

    def write_half_then_fail(obj, handle):
        handle.write(b"half a checkpoint")
        raise OSError("disk full")

    monkeypatch.setattr(checkpoints.torch, "save", write_half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        save_checkpoint(path, {"Policy": {}})
    assert path.read_bytes() == original
    assert os.listdir(tmp_path) == ["checkpoint.pt"]


class Malicious:
    def __reduce__(self):
        return (os.system, ("touch pwned-marker",))


def test_malicious_pickle_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "checkpoint.pt"
    torch.save({"Policy": Malicious()}, path)  # torch.save pickles the __reduce__ payload
    with pytest.raises(UserError, match="corrupt, truncated or not a trainer checkpoint"):
        load_checkpoint(path)
    assert not (tmp_path / "pwned-marker").exists()
    path.write_bytes(pickle.dumps(Malicious(), protocol=2))
    with pytest.raises(UserError):
        load_checkpoint(path)
    assert not (tmp_path / "pwned-marker").exists()


def test_missing_and_corrupt_files_name_the_path_and_the_fix(tmp_path):
    missing = tmp_path / "nothing.pt"
    with pytest.raises(UserError, match="does not exist") as error:
        load_checkpoint(missing)
    assert str(missing) in str(error.value) and "--force" in str(error.value) and "--run-id" in str(error.value)
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"\x00not a checkpoint at all")
    with pytest.raises(UserError, match="corrupt") as error:
        load_checkpoint(garbage)
    assert str(garbage) in str(error.value) and "--force" in str(error.value)
    truncated = tmp_path / "truncated.pt"
    save_checkpoint(truncated, STATE)
    truncated.write_bytes(truncated.read_bytes()[:40])
    with pytest.raises(UserError, match="corrupt"):
        load_checkpoint(truncated)


def test_atomic_copy_replaces_whole_or_not_at_all(tmp_path, monkeypatch):
    """The final <Behavior>.onnx is copied from the last checkpoint's ONNX this way."""
    import shutil

    from trainer.artifacts import atomic

    final = tmp_path / "Basic.onnx"
    final.write_bytes(b"model of the previous run")
    source = tmp_path / "Basic-300.onnx"
    source.write_bytes(b"new model " * 1000)
    atomic.atomic_copy(source, final)
    assert final.read_bytes() == source.read_bytes()

    def copy_part_then_fail(src, dst):
        dst.write(src.read(7))
        raise OSError("disk full")

    monkeypatch.setattr(shutil, "copyfileobj", copy_part_then_fail)
    source.write_bytes(b"a third model")
    with pytest.raises(OSError, match="disk full"):
        atomic.atomic_copy(source, final)
    assert final.read_bytes() == b"new model " * 1000  # untouched, no temp file left behind
    assert sorted(os.listdir(tmp_path)) == ["Basic-300.onnx", "Basic.onnx"]


def test_files_carry_a_format_version_and_a_content_checksum(tmp_path):
    path = tmp_path / "checkpoint.pt"
    save_checkpoint(path, STATE)
    raw = torch.load(path, weights_only=True)  # still a plain torch archive
    assert int(raw[FORMAT_KEY]["version"]) == checkpoints.FORMAT_VERSION == 1
    body = {k: v for k, v in raw.items() if k != FORMAT_KEY}
    assert bytes(raw[FORMAT_KEY]["sha256"].tolist()) == content_digest(body) == content_digest(STATE)
    assert FORMAT_KEY not in load_checkpoint(path)


def test_content_digest_sees_every_value_dtype_and_shape():
    base = content_digest(STATE)
    changed = [
        {**STATE, "Policy": {"weight": STATE["Policy"]["weight"].clone().index_put_((torch.tensor([0]), torch.tensor([0])), torch.tensor(0.5))}},
        {**STATE, "Policy": {"weight": STATE["Policy"]["weight"].reshape(3, 2)}},
        {**STATE, "Policy": {"weight": STATE["Policy"]["weight"].double()}},
        {**STATE, "global_step": {"step": torch.tensor(43)}},
        {**STATE, "notes": ["a", 1, 2.5, None, False]},
        {k: v for k, v in STATE.items() if k != "notes"},
    ]
    digests = {content_digest(state) for state in changed}
    assert base not in digests and len(digests) == len(changed)
    assert content_digest(dict(reversed(list(STATE.items())))) == base  # key order does not matter


def _flip_a_weight_in_place(path):
    """Change one float of the stored weight, keeping the archive valid: bit rot, or an edit."""
    state = torch.load(path, weights_only=True)
    state["Policy"]["weight"][0, 1] += 1.0
    torch.save(state, path)  # the old Format entry (and its digest) kept


def test_a_changed_or_truncated_file_fails_naming_it(tmp_path):
    path = tmp_path / "Ball-42.pt"
    save_checkpoint(path, STATE)
    _flip_a_weight_in_place(path)
    with pytest.raises(CheckpointError, match="fails its checksum") as error:
        load_checkpoint(path)
    assert str(path) in str(error.value)
    save_checkpoint(path, STATE)
    whole = path.read_bytes()
    for cut in (len(whole) // 3, len(whole) - 30):
        path.write_bytes(whole[:cut])
        with pytest.raises(CheckpointError, match="corrupt, truncated") as error:
            load_checkpoint(path)
        assert str(path) in str(error.value)


def test_a_newer_format_is_refused_and_an_unstamped_file_loads_with_a_warning(tmp_path, caplog):
    path = tmp_path / "checkpoint.pt"
    future = dict(STATE)
    future[FORMAT_KEY] = {"version": torch.tensor(2), "sha256": torch.tensor(list(content_digest(STATE)),
                                                                             dtype=torch.uint8)}
    torch.save(future, path)
    with pytest.raises(CheckpointError, match="format version 2, newer than"):
        load_checkpoint(path)
    torch.save(STATE, path)  # ML-Agents' own checkpoints have no Format entry
    with caplog.at_level("WARNING", logger="mlagents_like"):
        assert int(load_checkpoint(path)["global_step"]["step"]) == 42
    assert "no format version or checksum" in caplog.text
