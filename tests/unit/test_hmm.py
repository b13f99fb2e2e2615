"""unity_stub_env.hmm: training recovers a known model, Baum-Welch climbs, samplers draw the model's
probabilities, the alias table matches a hand-built one, bad corpora and model files are refused."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from unity_stub_env import hmm

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

# A known generating model: three "sticky" states cycling a -> b -> c -> a, each mostly emitting
# its own label (0.9) and the others with 0.05.
TRUE_A = np.array([[0.9, 0.1, 0.0], [0.0, 0.9, 0.1], [0.1, 0.0, 0.9]])
TRUE_B = np.array([[0.9, 0.05, 0.05], [0.05, 0.9, 0.05], [0.05, 0.05, 0.9]])
TRUE = hmm.Hmm(["a", "b", "c"], TRUE_A, TRUE_B, np.ones(3) / 3)


def _aligned(model: hmm.Hmm) -> tuple[np.ndarray, np.ndarray]:
    """A and B with states reordered so that state i is the one emitting label i most."""
    order = np.argmax(model.emission, axis=0)  # for each label, the state emitting it most
    assert sorted(order.tolist()) == [0, 1, 2], f"two labels share a state: {model.emission}"
    return model.transition[np.ix_(order, order)], model.emission[order]


def test_fast_training_recovers_the_transition_structure_within_0_05():
    corpus = TRUE.sample(40, 500, seed=1)
    model = hmm.train(corpus, num_states=3, restarts=3, method="fast", seed=0)
    a, b = _aligned(model)
    assert np.abs(a - TRUE_A).max() < 0.05, a
    assert np.abs(b - TRUE_B).max() < 0.05, b
    assert model.training["converged"]


def test_baum_welch_recovers_the_structure_and_never_decreases_the_log_likelihood():
    corpus = TRUE.sample(4, 300, seed=2)
    model = hmm.train(corpus, num_states=3, restarts=3, method="baum-welch", seed=0, max_iterations=200)
    history = hmm.fit_baum_welch(model.encode(corpus), 3, 3, np.random.default_rng(1), max_iterations=200).history
    assert len(history) > 10
    steps = np.diff(history)
    assert steps.min() >= -1e-8 * abs(history[-1]), steps.min()
    # it climbed from the random start (-1461) to about the generating model's own -785
    assert history[0] < -1400 and history[-1] > -790
    a, _ = _aligned(model)
    assert np.abs(a - TRUE_A).max() < 0.08, a
    # the best restart's log-likelihood is the corpus' forward log-likelihood under the model
    assert model.training["log_likelihood"] == pytest.approx(model.log_likelihood(model.encode(corpus)))


def test_restarts_keep_the_best_log_likelihood():
    corpus = TRUE.sample(10, 200, seed=4)
    model = hmm.train(corpus, num_states=3, restarts=4, method="fast", seed=1)
    lls = model.training["restart_log_likelihoods"]
    assert len(lls) == 4 and model.training["log_likelihood"] == max(lls)


def test_cooccurrence_counts_pairs_within_lines_only():
    counts = hmm.cooccurrence([np.array([0, 1, 1]), np.array([1, 0])], 2)
    assert counts.tolist() == [[0, 1], [1, 1]]  # (0,1), (1,1) from the first line, (1,0) from the second


def test_alias_table_matches_the_hand_built_one():
    # p = [0.5, 0.25, 0.25], K = 3: scaled [1.5, 0.75, 0.75]; small = [1, 2], large = [0].
    # pop 2 with 0: prob[2] = 0.75, alias 0, scaled[0] = 1.25; pop 1 with 0: prob[1] = 0.75,
    # alias 0, scaled[0] = 1.0 -> large; leftover 0 keeps itself with prob 1.
    table = hmm.AliasTable(np.array([[0.5, 0.25, 0.25]]))
    assert table.prob[0].tolist() == [1.0, 0.75, 0.75]
    assert table.alias[0].tolist() == [0, 0, 0]
    # and every table gives back its distribution: p_k = (prob_k + sum of (1 - prob_j) aliased to k) / K
    p = np.array([[0.1, 0.2, 0.3, 0.4], [0.7, 0.0, 0.0, 0.3]])
    table = hmm.AliasTable(p)
    for r in range(2):
        implied = table.prob[r].copy()
        np.add.at(implied, table.alias[r], 1.0 - table.prob[r])
        assert np.allclose(implied / 4, p[r])


@pytest.mark.parametrize("method", hmm.SAMPLERS)
def test_sampler_frequencies_are_within_binomial_bounds(method):
    p = np.array([[0.05, 0.15, 0.3, 0.5, 0.0], [0.2, 0.2, 0.2, 0.2, 0.2]])
    table = hmm.AliasTable(p) if method == "alias" else hmm.CdfTable(p)
    rng = np.random.default_rng(7)
    n = 200_000
    for r in range(2):
        draws = table.draw(np.full(n, r), rng.random(n))
        freq = np.bincount(draws, minlength=5) / n
        bound = 5 * np.sqrt(p[r] * (1 - p[r]) / n) + 1e-12  # 5 standard deviations
        assert np.all(np.abs(freq - p[r]) <= bound), (freq, p[r])


@pytest.mark.parametrize("method", hmm.SAMPLERS)
def test_sequence_sampling_follows_the_model(method):
    """Label frequencies and label-pair frequencies of long samples match the model's stationary ones."""
    codes = TRUE.sample_codes(2000, 100, np.random.default_rng(11), method)
    freq = np.bincount(codes.ravel(), minlength=3) / codes.size
    # the chain is doubly stochastic: uniform marginal. Draws are correlated (a state lasts ~10 steps),
    # so about 2e5 / 19 are independent: one standard deviation ~0.0047, the bound is 4 of them.
    assert np.allclose(freq, 1 / 3, atol=0.019)
    pairs = hmm.cooccurrence(list(codes), 3)
    pairs /= pairs.sum()
    expected = TRUE_B.T @ (np.diag(np.ones(3) / 3) @ TRUE_A) @ TRUE_B
    assert np.abs(pairs - expected).max() < 0.01


def test_same_seed_same_samples_and_epsilon_is_a_label():
    model = hmm.Hmm(["-", "x"], [[0.5, 0.5], [0.5, 0.5]], [[1.0, 0.0], [0.0, 1.0]], [0.5, 0.5])
    assert model.sample(3, 10, seed=4) == model.sample(3, 10, seed=4)
    assert hmm.strip_epsilon(["-", "x", "-", "x"]) == ["x", "x"]


def test_save_and_load_round_trip_exactly(tmp_path):
    model = hmm.train(TRUE.sample(5, 100, seed=0), num_states=4, restarts=2, seed=0)
    path = tmp_path / "m.json"
    model.save(str(path))
    back = hmm.Hmm.load(str(path))
    assert back.labels == model.labels
    for name in ("transition", "emission", "initial"):
        assert np.array_equal(getattr(back, name), getattr(model, name))
    assert json.loads(path.read_text())["format"] == "mlagents-like-hmm"


@pytest.mark.parametrize("text, words", [
    ("", "empty"),
    ("\n  \n# only a comment\n", "empty"),
    ("a a a\na a\n", "single label"),
    ("a\nb\nc\n", "no line with two or more labels"),
])
def test_bad_corpora_are_one_clear_error(text, words):
    with pytest.raises(hmm.HmmError, match=words):
        hmm.parse_corpus(text)


def _cli(*args, cwd):
    env = dict(os.environ, PYTHONPATH=REPO + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "unity_stub_env.cli", "hmm", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


def test_cli_train_then_sample_gives_a_corpus_again(tmp_path):
    (tmp_path / "corpus.txt").write_text("Left Straight Straight Right\nStraight - Left Left Straight\n" * 5)
    done = _cli("train", "corpus.txt", "-o", "m.json", "--states", "3", "--restarts", "2", "--seed", "1",
                cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    out = _cli("sample", "m.json", "-n", "4", "--length", "6", "--seed", "2", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert len(lines) == 4 and all(len(line.split()) == 6 for line in lines)
    assert set(out.stdout.split()) <= {"Left", "Right", "Straight", "-"}
    assert hmm.parse_corpus(out.stdout) == [line.split() for line in lines]
    again = _cli("sample", "m.json", "-n", "4", "--length", "6", "--seed", "2", cwd=tmp_path)
    assert again.stdout == out.stdout


def test_cli_bad_inputs_exit_2_with_one_message(tmp_path):
    (tmp_path / "empty.txt").write_text("")
    (tmp_path / "binary.txt").write_bytes(b"Left Right\n\xff\xfe Straight\n")
    (tmp_path / "bad.json").write_text('{"format": "something else"}')
    for args, words in [(("train", "empty.txt", "-o", "m.json"), "empty"),
                        (("train", "binary.txt", "-o", "m.json"), "not UTF-8"),
                        (("train", "missing.txt", "-o", "m.json"), "cannot read corpus"),
                        (("sample", "bad.json", "-n", "1", "--length", "3"), "not an HMM model file")]:
        done = _cli(*args, cwd=tmp_path)
        assert done.returncode == 2, (args, done.stderr)
        assert words in done.stderr and "Traceback" not in done.stderr
        assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "m.json").exists()


# ---------------------------------------------------------------------------- sampler_type: hmm
def test_hmm_sampler_config_is_checked_at_load(tmp_path):
    from trainer.config.env_params import environment_parameters_as_dict, structure_environment_parameters
    from trainer.errors import ConfigError

    def load(parameters):
        return structure_environment_parameters({"track": {"sampler_type": "hmm", "sampler_parameters": parameters}})

    for parameters, words in [({"length": 3}, "exactly one of 'model'"),
                              ({"model": "m.json", "corpus": ["a b"]}, "exactly one of 'model'"),
                              ({"model": str(tmp_path / "nope.json")}, "cannot read model"),
                              ({"corpus": ["a a a"]}, "single label"),
                              ({"corpus": ["a b"], "length": 0}, "length' must be >= 1"),
                              ({"corpus": ["a b"], "count": 1000, "length": 1000}, "more than 100000"),
                              ({"corpus": [1, 2]}, "list of sequences"),
                              ({"corpus": ["a b"], "lenght": 3}, "lenght")]:
        with pytest.raises(ConfigError, match=words):
            load(parameters)
    params = load({"corpus": "a b a\nb b a", "states": 2, "length": 4, "count": 2, "seed": 3})
    written = environment_parameters_as_dict(params)["track"]["curriculum"][0]["value"]
    assert written == {"sampler_type": "hmm", "sampler_parameters": {
        "seed": 3, "model": "", "corpus": ["a b a", "b b a"], "states": 2, "length": 4, "count": 2}}
    assert load(written["sampler_parameters"]) == params  # the written configuration reads back


def test_sequences_encode_as_plain_float_parameters():
    from protos import side_channels as sc

    payloads = sc.encode_env_sequences("track", np.array([[0, 2], [1, 1]]), 3)
    decoded = [sc.decode_env_parameter(p) for p in payloads]
    assert [(key, param.kind, param.values) for key, param in decoded] == [
        ("track.count", "float", (2.0,)), ("track.length", "float", (2.0,)), ("track.labels", "float", (3.0,)),
        ("track.0", "float", (0.0,)), ("track.1", "float", (2.0,)), ("track.2", "float", (1.0,)),
        ("track.3", "float", (1.0,))]
    # string key (int32 length + bytes), int32 0 = float, float32 value, little-endian
    assert payloads[3] == b"\x07\x00\x00\x00track.0" + b"\x00\x00\x00\x00" + b"\x00\x00\x00\x00"
