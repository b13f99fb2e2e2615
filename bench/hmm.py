"""HMM training and sampling speed (the runner thesis, docs/stub-tasks.md): co-occurrence ("fast")
training against Baum-Welch, and alias against CDF + binary-search sampling. Prints markdown tables,
writes bench/out/hmm.json.

    .venv/bin/python bench/hmm.py                      # T = 1e3..1e6, N = 2..40, K = 3..1000
    .venv/bin/python bench/hmm.py --quick              # smaller sizes, for a smoke run

Corpus: one sequence of T labels drawn from a fixed random generating model (N0 = 5 states,
M = 6 labels, seed 0). Both trainers start from the same kind of random initialisation, one
restart each, tolerance 1e-6 (unity_stub_env.hmm's stop rule).

Table 1, as T grows (N = 5): fast = counting time (the O(T) pass) + iterations × time per
iteration (the O(M²N) part); Baum-Welch = time per iteration (O(N²T)). Baum-Welch runs to
convergence (at most --bw-iterations) only up to --bw-full-max-t; above it only --bw-timed
iterations are timed and no final log-likelihood is given. The final log-likelihood of both is
the corpus' forward log-likelihood per label under the trained model (computed once, untimed).
Table 2, as N grows (T = 1e4): time per iteration of both. Table 3: draws per second of a
batch of 1e6 draws from random rows of a [16, K] table, alias vs CDF (min of repeats).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from unity_stub_env import hmm  # noqa: E402

M_LABELS, N_TRUE = 6, 5


def generating_model(seed: int = 0) -> hmm.Hmm:
    rng = np.random.default_rng(seed)
    a = rng.dirichlet(np.full(N_TRUE, 0.3), N_TRUE) * 0.5 + np.eye(N_TRUE) * 0.5
    b = rng.dirichlet(np.full(M_LABELS, 0.3), N_TRUE)
    return hmm.Hmm([f"l{k}" for k in range(M_LABELS)], a, b, np.full(N_TRUE, 1 / N_TRUE))


def corpus(t_len: int) -> list[np.ndarray]:
    return [generating_model().sample_codes(1, t_len, np.random.default_rng(t_len))[0]]


def time_fast(encoded, states: int, seed: int = 1) -> dict:
    start = time.perf_counter()
    counts = hmm.cooccurrence(encoded, M_LABELS)
    count_s = time.perf_counter() - start
    start = time.perf_counter()
    fit = hmm.fit_fast(counts, states, np.random.default_rng(seed))
    fit_s = time.perf_counter() - start
    model = hmm.Hmm([f"l{k}" for k in range(M_LABELS)], fit.transition, fit.emission, fit.initial)
    return {"count_s": count_s, "iterations": fit.iterations, "per_iteration_s": fit_s / fit.iterations,
            "total_s": count_s + fit_s, "converged": fit.converged, "model": model}


def time_baum_welch(encoded, states: int, iterations: int, seed: int = 1) -> dict:
    start = time.perf_counter()
    fit = hmm.fit_baum_welch(encoded, M_LABELS, states, np.random.default_rng(seed), max_iterations=iterations)
    total = time.perf_counter() - start
    done = fit.iterations - 1  # history holds one extra entry: the final forward pass
    # the final forward pass costs about a third of an iteration; count it in
    per_iteration = total / (done + 1 / 3)
    model = hmm.Hmm([f"l{k}" for k in range(M_LABELS)], fit.transition, fit.emission, fit.initial)
    return {"iterations": done, "per_iteration_s": per_iteration, "total_s": total, "converged": fit.converged,
            "model": model}


def sampling_rates(widths, draws: int, repeats: int) -> list[dict]:
    rows = []
    rng = np.random.default_rng(0)
    for width in widths:
        p = rng.dirichlet(np.ones(width), 16)
        tables = {"alias": hmm.AliasTable(p), "cdf": hmm.CdfTable(p)}
        which = rng.integers(0, 16, draws)
        u = rng.random(draws)
        row = {"K": width}
        for name, table in tables.items():
            best = min(_timed(lambda: table.draw(which, u)) for _ in range(repeats))
            row[name] = draws / best
        build = {name: min(_timed(lambda cls=cls: cls(p)) for _ in range(3))
                 for name, cls in (("alias", hmm.AliasTable), ("cdf", hmm.CdfTable))}
        row["build_alias_s"], row["build_cdf_s"] = build["alias"], build["cdf"]
        # single draws, one Python call each (what a game loop asking for one label pays)
        one_row, one_u = np.array([3]), np.array([0.5])
        for name, table in tables.items():
            best = min(_timed(lambda: [table.draw(one_row, one_u) for _ in range(2000)]) for _ in range(repeats))
            row[f"{name}_single"] = 2000 / best
        rows.append(row)
    return rows


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--bw-full-max-t", type=int, default=10_000)
    parser.add_argument("--bw-iterations", type=int, default=300)
    parser.add_argument("--bw-timed", type=int, default=2)
    args = parser.parse_args()
    lengths = [1_000, 10_000] if args.quick else [1_000, 10_000, 100_000, 1_000_000]
    state_counts = [2, 5, 10] if args.quick else [2, 5, 10, 20, 40]
    widths = [3, 10, 100] if args.quick else [3, 10, 100, 1000]
    record = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "machine": platform.node(),
              "cpus": os.cpu_count(), "by_length": [], "by_states": [], "sampling": []}

    print("| T | fast: count s | fast: iterations | fast: s/iteration | fast: total s | fast: LL/label | "
          "BW: iterations | BW: s/iteration | BW: total s | BW: LL/label | true model LL/label |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for t_len in lengths:
        encoded = corpus(t_len)
        truth = generating_model().log_likelihood(encoded) / t_len
        fast = time_fast(encoded, N_TRUE)
        fast_ll = fast.pop("model").log_likelihood(encoded) / t_len
        full = t_len <= args.bw_full_max_t
        bw = time_baum_welch(encoded, N_TRUE, args.bw_iterations if full else args.bw_timed)
        bw_model = bw.pop("model")
        bw_ll = bw_model.log_likelihood(encoded) / t_len if full else None
        record["by_length"].append({"T": t_len, "fast": fast, "fast_ll": fast_ll, "bw": bw, "bw_ll": bw_ll,
                                    "true_ll": truth})
        print(f"| {t_len:.0e} | {fast['count_s']:.4f} | {fast['iterations']} | {fast['per_iteration_s']*1e6:.0f} µs | "
              f"{fast['total_s']:.3f} | {fast_ll:.4f} | {bw['iterations']}{'' if full else ' (timed only)'} | "
              f"{bw['per_iteration_s']:.3f} | {bw['total_s']:.2f} | "
              f"{'—' if bw_ll is None else f'{bw_ll:.4f}'} | {truth:.4f} |", flush=True)

    print("\n| N (states) | fast: s/iteration | fast: iterations | BW: s/iteration (T = 1e4) | ratio BW/fast per iteration |")
    print("|---:|---:|---:|---:|---:|")
    encoded = corpus(10_000)
    for states in state_counts:
        fast = time_fast(encoded, states)
        fast.pop("model")
        bw = time_baum_welch(encoded, states, args.bw_timed + 1)
        bw.pop("model")
        record["by_states"].append({"N": states, "fast": fast, "bw": bw})
        print(f"| {states} | {fast['per_iteration_s']*1e6:.0f} µs | {fast['iterations']} | "
              f"{bw['per_iteration_s']:.3f} s | {bw['per_iteration_s'] / fast['per_iteration_s']:.0f} |", flush=True)

    print("\n| K (labels per row) | alias draws/s (batch 1e6) | CDF draws/s (batch 1e6) | alias/CDF | "
          "alias single draws/s | CDF single draws/s | build alias [16, K] | build CDF [16, K] |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|")
    for row in sampling_rates(widths, 200_000 if args.quick else 1_000_000, 5):
        record["sampling"].append(row)
        print(f"| {row['K']} | {row['alias']:.3g} | {row['cdf']:.3g} | {row['alias'] / row['cdf']:.2f} | "
              f"{row['alias_single']:.3g} | {row['cdf_single']:.3g} | {row['build_alias_s']*1e3:.2f} ms | "
              f"{row['build_cdf_s']*1e3:.3f} ms |", flush=True)

    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "out")
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "hmm.json"), "w") as handle:
        json.dump(record, handle, indent=1, default=float)
    return 0


if __name__ == "__main__":
    sys.exit(main())
