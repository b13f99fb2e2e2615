"""Discrete hidden Markov models for level generation: training, save/load and sampling (numpy only).

A model is λ = (A, B, π) over N hidden states and M labels (docs/hmm.md):

  transition  A  float64 [N, N]  rows sum to 1, A[i, j] = P(q_{t+1} = j | q_t = i)
  emission    B  float64 [N, M]  rows sum to 1, B[i, k] = P(O_t = labels[k] | q_t = i)
  initial     π  float64 [N]     sums to 1
  labels         list[str] [M]   sorted; ``-`` is the epsilon label (an empty slot, a gap)

Two trainers, both with random restarts that keep the best log-likelihood:

* ``fast`` -- training from observed transitions (Shashanka, "A fast algorithm for discrete HMM
  training using observed transitions"). Count the M×M co-occurrence matrix C of consecutive
  label pairs (pairs never cross a line of the corpus), normalise it to a joint distribution, and
  fit C ≈ C̄ = Bᵀ Ā B, with Ā = diag(π)·A the N×N joint distribution of consecutive states, by the
  multiplicative updates (here B is the N×M emission matrix, so the docs' M×N "B" is our Bᵀ)::

      R  = C ⊘ C̄
      Ā' = Ā ⊙ (B R Bᵀ)                   normalised over the whole matrix
      B' = B ⊙ (Ā B Rᵀ + Āᵀ B R)           normalised per state (the docs' "per column")

  The runner thesis (docs/stub-tasks.md, "Seed projects") prints the emission update as
  ``B ⊙ (R Āᵀ + Rᵀ B Ā)``; the first term has lost a B (its shapes do not even multiply). The gradient
  of Σ C log C̄ has both B's, and so does the thesis' own code; we use that. Each iteration is O(M²N + MN²); with the O(T)
  counting the whole cost is O(I·M²·N + T) (bench/hmm.py measures it). The updates ignore π; after
  training A is Ā with rows normalised and π is Ā's row sums (the stationary state marginal, our choice:
  the thesis uses π only to pick the first state). The objective it maximises, and the log-likelihood
  its restarts compare, is the pair log-likelihood Σ C_kl log C̄_kl (counts, not normalised): computing
  the sequence log-likelihood instead would cost the O(N²T) the method avoids.
* ``baum-welch`` -- scaled forward-backward EM on every line of the corpus, O(I·N²·T). Its
  log-likelihood (Σ log of the scale factors) never decreases; tests check that.

Stop rule (both): the L2 norms of the changes of A and B (and, for ``fast``, of R) between two
iterations are all below ``tol`` = 1e-6, or ``max_iterations`` is reached.

Sampling draws from rows of π, A and B with either per-row CDFs and binary search
(``np.searchsorted``, O(log K) per draw) or Vose's alias method (O(1) per draw after an O(K)
table build per row). ``sample(..., method=...)`` picks one; both produce exactly the model's
probabilities (tests check frequencies against binomial bounds).

Save/load: a JSON document (no pickle), see ``Hmm.to_json``.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

EPSILON_LABEL = "-"
FORMAT = "mlagents-like-hmm"
FORMAT_VERSION = 1
METHODS = ("fast", "baum-welch")
SAMPLERS = ("alias", "cdf")
_TINY = 1e-300


class HmmError(ValueError):
    """A bad corpus or model file: the message names the thing and what to do."""


# ------------------------------------------------------------------------------------ corpora
def parse_corpus(text: str, source: str = "corpus") -> list[list[str]]:
    """One sequence per non-blank line, labels separated by whitespace; '#' starts a comment line.

    Raises HmmError for a corpus with no labels, with fewer than two distinct labels (nothing
    to learn), or without any line of two or more labels (no transition to count).
    """
    sequences = [line.split() for line in text.splitlines()
                 if line.strip() and not line.lstrip().startswith("#")]
    if not sequences:
        raise HmmError(f"{source} is empty: write one sequence per line, labels separated by spaces "
                       f"(e.g. 'Left Straight Right').")
    labels = {label for seq in sequences for label in seq}
    if len(labels) < 2:
        raise HmmError(f"{source} uses a single label ({next(iter(labels))!r}); an HMM needs at least two "
                       "distinct labels. Add sequences with the other labels.")
    if not any(len(seq) >= 2 for seq in sequences):
        raise HmmError(f"{source} has no line with two or more labels, so no transition to learn from; "
                       "put each whole sequence on one line.")
    return sequences


def read_corpus(path: str) -> list[list[str]]:
    """``parse_corpus`` of a UTF-8 text file; undecodable bytes (a binary or mixed-encoding file)
    are one HmmError naming the line."""
    try:
        with open(path, "rb") as handle:
            raw = handle.read()
    except OSError as error:
        raise HmmError(f"cannot read corpus {path}: {error.strerror}.") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as error:
        line = raw[:error.start].count(b"\n") + 1
        raise HmmError(f"corpus {path} is not UTF-8 text (bad byte at line {line}); save it as UTF-8 "
                       "with one sequence of labels per line.") from None
    if "\x00" in text:
        raise HmmError(f"corpus {path} contains NUL bytes: it is not a text file of labels.")
    return parse_corpus(text, f"corpus {path}")


def format_sequences(sequences: Iterable[Sequence[str]]) -> str:
    """The corpus text of ``sequences`` (what ``hmm sample`` prints; it reads back as a corpus)."""
    return "".join(" ".join(seq) + "\n" for seq in sequences)


def cooccurrence(encoded: Sequence[np.ndarray], num_labels: int) -> np.ndarray:
    """float64 [M, M]: counts of consecutive pairs (O_t, O_{t+1}) within each sequence. O(T)."""
    counts = np.zeros(num_labels * num_labels, dtype=np.int64)
    for seq in encoded:
        if len(seq) >= 2:
            counts += np.bincount(seq[:-1] * num_labels + seq[1:], minlength=num_labels * num_labels)
    return counts.reshape(num_labels, num_labels).astype(np.float64)


# ------------------------------------------------------------------------------------ samplers
class CdfTable:
    """Per-row CDFs searched by binary search: ``draw(rows, u)`` -> column index per row, O(log K).

    All rows live in one sorted array (row r's CDF shifted by r), so a batch of draws from
    different rows is one ``np.searchsorted`` call.
    """

    def __init__(self, probabilities: np.ndarray) -> None:
        p = np.atleast_2d(np.asarray(probabilities, dtype=np.float64))
        self.rows, self.width = p.shape
        cdf = np.cumsum(p / p.sum(axis=1, keepdims=True), axis=1)
        cdf[:, -1] = 1.0
        self.flat = (cdf + np.arange(self.rows)[:, None]).ravel()

    def draw(self, rows: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
        rows = np.asarray(rows, dtype=np.int64)
        index = np.searchsorted(self.flat, rows + uniforms, side="right") - rows * self.width
        return np.minimum(index, self.width - 1)  # u rounding up to the row's end


class AliasTable:
    """Vose's alias method per row: ``draw(rows, u)`` -> column index per row, O(1) per draw.

    For row r: pick column k = floor(u·K); keep it with probability ``prob[r, k]``, else take
    ``alias[r, k]``. Built in O(K) per row with two worklists (small: scaled p < 1, large: >= 1),
    each popped from its end.
    """

    def __init__(self, probabilities: np.ndarray) -> None:
        p = np.atleast_2d(np.asarray(probabilities, dtype=np.float64))
        self.rows, self.width = p.shape
        self.prob = np.ones((self.rows, self.width))
        self.alias = np.tile(np.arange(self.width), (self.rows, 1))
        for r in range(self.rows):
            self._build_row(r, p[r] / p[r].sum())

    def _build_row(self, r: int, p: np.ndarray) -> None:
        scaled = list(p * self.width)
        small = [k for k, s in enumerate(scaled) if s < 1.0]
        large = [k for k, s in enumerate(scaled) if s >= 1.0]
        while small and large:
            less, more = small.pop(), large.pop()
            self.prob[r, less] = scaled[less]
            self.alias[r, less] = more
            scaled[more] = scaled[more] + scaled[less] - 1.0
            (small if scaled[more] < 1.0 else large).append(more)
        for k in small + large:  # only rounding leftovers: they keep themselves
            self.prob[r, k] = 1.0

    def draw(self, rows: np.ndarray, uniforms: np.ndarray) -> np.ndarray:
        """One uniform per draw: its integer part (×K) picks the column, its fraction the coin."""
        rows = np.asarray(rows, dtype=np.int64)
        scaled = np.asarray(uniforms) * self.width
        column = np.minimum(scaled.astype(np.int64), self.width - 1)
        coin = scaled - column
        return np.where(coin < self.prob[rows, column], column, self.alias[rows, column])


_TABLES = {"alias": AliasTable, "cdf": CdfTable}


# ------------------------------------------------------------------------------------ the model
@dataclass
class Hmm:
    labels: list[str]
    transition: np.ndarray
    emission: np.ndarray
    initial: np.ndarray
    training: dict = field(default_factory=dict)  # how it was trained (saved alongside, informative)

    def __post_init__(self) -> None:
        self.transition = np.asarray(self.transition, dtype=np.float64)
        self.emission = np.asarray(self.emission, dtype=np.float64)
        self.initial = np.asarray(self.initial, dtype=np.float64)
        self._tables: dict[str, tuple] = {}

    @property
    def num_states(self) -> int:
        return self.transition.shape[0]

    @property
    def num_labels(self) -> int:
        return len(self.labels)

    def encode(self, sequences: Iterable[Sequence[str]]) -> list[np.ndarray]:
        index = {label: k for k, label in enumerate(self.labels)}
        try:
            return [np.array([index[label] for label in seq], dtype=np.int64) for seq in sequences]
        except KeyError as error:
            raise HmmError(f"label {error.args[0]!r} is not one of the model's labels {self.labels}.") from None

    def decode(self, codes: np.ndarray) -> list[list[str]]:
        return [[self.labels[k] for k in row] for row in np.atleast_2d(codes).tolist()]

    # -------------------------------------------------------------------------------- scoring
    def log_likelihood(self, encoded: Sequence[np.ndarray]) -> float:
        """Σ over sequences of log P(O | λ), by the scaled forward pass. O(N²T)."""
        return sum(_forward(self.transition, self.emission, self.initial, seq)[2] for seq in encoded)

    # -------------------------------------------------------------------------------- sampling
    def sample_codes(self, count: int, length: int, rng: np.random.Generator,
                     method: str = "alias") -> np.ndarray:
        """int64 [count, length]: label codes of ``count`` independent sequences, all drawn at once
        (one draw per sequence per step for the state and one for the label)."""
        if method not in _TABLES:
            raise ValueError(f"unknown sampling method {method!r}; use one of {SAMPLERS}")
        if method not in self._tables:
            table = _TABLES[method]
            self._tables[method] = (table(self.initial), table(self.transition), table(self.emission))
        start, step, emit = self._tables[method]
        out = np.empty((count, length), dtype=np.int64)
        if length == 0:
            return out
        zeros = np.zeros(count, dtype=np.int64)
        state = start.draw(zeros, rng.random(count))
        for t in range(length):
            out[:, t] = emit.draw(state, rng.random(count))
            if t + 1 < length:
                state = step.draw(state, rng.random(count))
        return out

    def sample(self, count: int, length: int, seed: int | None = None, method: str = "alias") -> list[list[str]]:
        return self.decode(self.sample_codes(count, length, np.random.default_rng(seed), method)) if count else []

    # -------------------------------------------------------------------------------- storage
    def to_json(self) -> str:
        """{"format": "mlagents-like-hmm", "version": 1, "labels", "transition" [N][N],
        "emission" [N][M], "initial" [N], "training"}: floats written with full precision."""
        return json.dumps({
            "format": FORMAT, "version": FORMAT_VERSION, "labels": list(self.labels),
            "transition": self.transition.tolist(), "emission": self.emission.tolist(),
            "initial": self.initial.tolist(), "training": self.training,
        }, indent=1) + "\n"

    def save(self, path: str) -> None:
        """Atomic: written to a temporary file in the same folder, then renamed over ``path``."""
        folder = os.path.dirname(os.path.abspath(path))
        handle, temp = tempfile.mkstemp(dir=folder, prefix=".hmm-", suffix=".json")
        try:
            with os.fdopen(handle, "w", encoding="utf-8") as out:
                out.write(self.to_json())
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(temp, 0o666 & ~umask)  # mkstemp's 0600 is for the half-written file only
            os.replace(temp, path)
        except BaseException:
            if os.path.exists(temp):
                os.unlink(temp)
            raise

    @classmethod
    def from_json(cls, text: str, source: str = "model") -> "Hmm":
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as error:
            raise HmmError(f"{source} is not JSON ({error.msg} at line {error.lineno}); give a file written "
                           "by 'unity-stub-env hmm train'.") from None
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise HmmError(f"{source} is not an HMM model file (no \"format\": \"{FORMAT}\"); give a file "
                           "written by 'unity-stub-env hmm train'.")
        if doc.get("version") != FORMAT_VERSION:
            raise HmmError(f"{source} has model format version {doc.get('version')!r}; this build reads "
                           f"version {FORMAT_VERSION}.")
        try:
            labels = [str(label) for label in doc["labels"]]
            a = np.array(doc["transition"], dtype=np.float64)
            b = np.array(doc["emission"], dtype=np.float64)
            pi = np.array(doc["initial"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as error:
            raise HmmError(f"{source} lacks or has a malformed field ({error}).") from None
        n, m = len(pi), len(labels)
        if a.shape != (n, n) or b.shape != (n, m) or n == 0 or m < 2 or len(set(labels)) != m:
            raise HmmError(f"{source}: shapes do not agree (initial [{n}], transition {list(a.shape)}, "
                           f"emission {list(b.shape)}, {m} labels); expected [N], [N, N], [N, M], M >= 2 "
                           "distinct labels.")
        for name, matrix in (("initial", pi[None, :]), ("transition", a), ("emission", b)):
            if not np.all(np.isfinite(matrix)) or (matrix < 0).any() or \
                    not np.allclose(matrix.sum(axis=1), 1.0, atol=1e-6):
                raise HmmError(f"{source}: '{name}' has a row that is not a probability distribution "
                               "(non-negative, summing to 1).")
        return cls(labels, a, b, pi, dict(doc.get("training") or {}))

    @classmethod
    def load(cls, path: str) -> "Hmm":
        try:
            with open(path, encoding="utf-8") as handle:
                text = handle.read()
        except (OSError, UnicodeDecodeError) as error:
            raise HmmError(f"cannot read model {path}: {getattr(error, 'strerror', None) or error}.") from None
        return cls.from_json(text, f"model {path}")


# ------------------------------------------------------------------------------------ training
@dataclass
class FitResult:
    """One restart: the fitted parameters, its log-likelihood (the method's own, see the module
    docstring), the log-likelihood after every iteration, and whether the stop rule fired."""

    transition: np.ndarray
    emission: np.ndarray
    initial: np.ndarray
    log_likelihood: float
    history: list[float]
    converged: bool

    @property
    def iterations(self) -> int:
        return len(self.history)


def _random_stochastic(rng: np.random.Generator, rows: int, cols: int) -> np.ndarray:
    m = rng.uniform(0.0, 1.0, (rows, cols)) + 1e-3
    return m / m.sum(axis=1, keepdims=True)


def _pair_log_likelihood(c: np.ndarray, c_bar: np.ndarray) -> float:
    mask = c > 0
    return float(np.sum(c[mask] * np.log(np.maximum(c_bar[mask], _TINY))))


def fit_fast(counts: np.ndarray, num_states: int, rng: np.random.Generator,
             max_iterations: int = 1000, tol: float = 1e-6) -> FitResult:
    """One restart of the co-occurrence training on pair counts ``counts`` [M, M]."""
    m = counts.shape[0]
    c = counts / counts.sum()
    a_bar = _random_stochastic(rng, 1, num_states * num_states).reshape(num_states, num_states)
    b = _random_stochastic(rng, num_states, m)  # [N, M]
    r_old = np.zeros_like(c)
    history: list[float] = []
    converged = False
    for _ in range(max_iterations):
        c_bar = b.T @ a_bar @ b
        r = c / np.maximum(c_bar, _TINY)
        a_new = a_bar * (b @ r @ b.T)
        b_new = b * (a_bar @ b @ r.T + a_bar.T @ b @ r)
        a_new /= a_new.sum()
        b_new /= np.maximum(b_new.sum(axis=1, keepdims=True), _TINY)
        change = max(np.linalg.norm(a_new - a_bar), np.linalg.norm(b_new - b), np.linalg.norm(r - r_old))
        a_bar, b, r_old = a_new, b_new, r
        history.append(_pair_log_likelihood(counts, b.T @ a_bar @ b))
        if change < tol:
            converged = True
            break
    marginal = a_bar.sum(axis=1)
    transition = a_bar / np.maximum(marginal[:, None], _TINY)
    dead = marginal <= _TINY  # a state the fit emptied: any row will do, it is never entered
    transition[dead] = 1.0 / num_states
    return FitResult(transition, b, marginal / marginal.sum(), history[-1], history, converged)


def _forward(a: np.ndarray, b: np.ndarray, pi: np.ndarray, seq: np.ndarray):
    """Scaled forward pass: (alpha_hat [T, N], scales c [T], log-likelihood Σ log c)."""
    t_len, n = len(seq), len(pi)
    alpha = np.empty((t_len, n))
    scale = np.empty(t_len)
    emit = b[:, seq].T  # [T, N]
    current = pi * emit[0]
    for t in range(t_len):
        if t:
            current = (current @ a) * emit[t]
        s = current.sum()
        scale[t] = s if s > 0 else _TINY
        current = current / scale[t]
        alpha[t] = current
    return alpha, scale, float(np.log(scale).sum())


def fit_baum_welch(encoded: Sequence[np.ndarray], num_labels: int, num_states: int, rng: np.random.Generator,
                   max_iterations: int = 1000, tol: float = 1e-6) -> FitResult:
    """One restart of scaled Baum-Welch over all sequences (Rabiner's scaling)."""
    a = _random_stochastic(rng, num_states, num_states)
    b = _random_stochastic(rng, num_states, num_labels)
    pi = _random_stochastic(rng, 1, num_states)[0]
    history: list[float] = []
    converged = False
    for _ in range(max_iterations):
        xi_sum = np.zeros((num_states, num_states))
        emit_sum = np.zeros((num_states, num_labels))
        pi_sum = np.zeros(num_states)
        total = 0.0
        for seq in encoded:
            alpha, scale, ll = _forward(a, b, pi, seq)
            total += ll
            emit = b[:, seq].T
            beta = np.empty_like(alpha)
            beta[-1] = 1.0
            for t in range(len(seq) - 2, -1, -1):
                beta[t] = a @ (emit[t + 1] * beta[t + 1]) / scale[t + 1]
            gamma = alpha * beta  # [T, N], rows sum to 1
            pi_sum += gamma[0]
            for k in range(num_labels):
                emit_sum[:, k] += gamma[seq == k].sum(axis=0)
            if len(seq) >= 2:
                weighted = emit[1:] * beta[1:] / scale[1:, None]  # [T-1, N]
                xi_sum += a * (alpha[:-1].T @ weighted)
        history.append(total)  # the likelihood of the parameters this iteration started from
        a_new = xi_sum / np.maximum(xi_sum.sum(axis=1, keepdims=True), _TINY)
        a_new[xi_sum.sum(axis=1) <= _TINY] = 1.0 / num_states
        b_new = emit_sum / np.maximum(emit_sum.sum(axis=1, keepdims=True), _TINY)
        b_new[emit_sum.sum(axis=1) <= _TINY] = 1.0 / num_labels
        pi_new = pi_sum / pi_sum.sum()
        change = max(np.linalg.norm(a_new - a), np.linalg.norm(b_new - b))
        a, b, pi = a_new, b_new, pi_new
        if change < tol:
            converged = True
            break
    final = sum(_forward(a, b, pi, seq)[2] for seq in encoded)
    history.append(final)
    return FitResult(a, b, pi, final, history, converged)


def train(sequences: Sequence[Sequence[str]], num_states: int = 5, restarts: int = 5, method: str = "fast",
          seed: int = 0, max_iterations: int = 1000, tol: float = 1e-6) -> Hmm:
    """Train on labelled sequences with ``restarts`` random initialisations; keep the best
    log-likelihood (the pair log-likelihood for ``fast``, the sequence one for ``baum-welch``)."""
    if method not in METHODS:
        raise HmmError(f"unknown training method {method!r}; use one of {', '.join(METHODS)}.")
    if num_states < 1 or restarts < 1 or max_iterations < 1:
        raise HmmError(f"states ({num_states}), restarts ({restarts}) and max iterations ({max_iterations}) "
                       "must all be at least 1.")
    labels = sorted({label for seq in sequences for label in seq})
    model = Hmm(labels, np.eye(1), np.ones((1, len(labels))) / len(labels), np.ones(1))
    encoded = model.encode(sequences)
    rng = np.random.default_rng(seed)
    if method == "fast":
        counts = cooccurrence(encoded, len(labels))
        fits = [fit_fast(counts, num_states, rng, max_iterations, tol) for _ in range(restarts)]
    else:
        fits = [fit_baum_welch(encoded, len(labels), num_states, rng, max_iterations, tol) for _ in range(restarts)]
    best = max(fits, key=lambda fit: fit.log_likelihood)
    info = {"method": method, "states": num_states, "restarts": restarts, "seed": seed,
            "max_iterations": max_iterations, "tol": tol, "log_likelihood": best.log_likelihood,
            "iterations": best.iterations, "converged": best.converged,
            "restart_log_likelihoods": [fit.log_likelihood for fit in fits],
            "labels_counted": int(sum(len(seq) for seq in encoded))}
    return Hmm(labels, best.transition, best.emission, best.initial, info)


def strip_epsilon(sequence: Sequence[str]) -> list[str]:
    """The sequence without epsilon labels (what is placed when gaps are dropped)."""
    return [label for label in sequence if label != EPSILON_LABEL]


# ------------------------------------------------------------------------------------ the CLI
def build_parser():
    import argparse

    parser = argparse.ArgumentParser(prog="unity-stub-env hmm", allow_abbrev=False,
                                     description="Train hidden Markov models on label corpora and sample from them.")
    sub = parser.add_subparsers(dest="command", required=True)
    tr = sub.add_parser("train", help="train a model on CORPUS (one sequence per line, labels separated by spaces)")
    tr.add_argument("corpus")
    tr.add_argument("-o", "--output", required=True, metavar="MODEL", help="write the model here (JSON)")
    tr.add_argument("--states", type=int, default=5, help="hidden states N (default 5)")
    tr.add_argument("--restarts", type=int, default=5, help="random restarts; the best log-likelihood wins (default 5)")
    tr.add_argument("--method", choices=METHODS, default="fast", help="fast (co-occurrence, default) or baum-welch")
    tr.add_argument("--seed", type=int, default=0, help="seed of the random initialisations (default 0)")
    tr.add_argument("--max-iterations", type=int, default=1000, help="per restart (default 1000)")
    sa = sub.add_parser("sample", help="print N generated sequences of L labels, one per line (a corpus again)")
    sa.add_argument("model")
    sa.add_argument("-n", type=int, required=True, dest="count", help="number of sequences")
    sa.add_argument("--length", type=int, required=True, help="labels per sequence")
    sa.add_argument("--seed", type=int, default=None, help="seed (default: fresh randomness)")
    sa.add_argument("--method", choices=SAMPLERS, default="alias", help="alias (default) or cdf")
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    return parser


def main(argv: Sequence[str]) -> int:
    """``unity-stub-env hmm ...``: 0 on success, 2 (one message) for a bad corpus, model or flag."""
    import sys

    args = build_parser().parse_args(list(argv))
    try:
        if args.command == "train":
            model = train(read_corpus(args.corpus), args.states, args.restarts, args.method, args.seed,
                          args.max_iterations)
            model.save(args.output)
            info = model.training
            print(f"{args.output}: {model.num_states} states, {model.num_labels} labels "
                  f"({', '.join(model.labels)}), {info['method']}, best of {info['restarts']} restarts: "
                  f"log-likelihood {info['log_likelihood']:.4f} after {info['iterations']} iterations"
                  f"{'' if info['converged'] else ' (max iterations reached)'}", file=sys.stderr)
            return 0
        if args.count < 0 or args.length < 1:
            raise HmmError(f"-n must be >= 0 and --length >= 1 (got -n {args.count}, --length {args.length}).")
        model = Hmm.load(args.model)
        sys.stdout.write(format_sequences(model.sample(args.count, args.length, args.seed, args.method)))
        return 0
    except HmmError as error:
        if args.debug:
            raise
        print(f"unity-stub-env hmm: {error}", file=sys.stderr)
        return 2
