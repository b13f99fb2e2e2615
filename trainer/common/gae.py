"""Discounted returns and Generalised Advantage Estimation for one trajectory (numpy float32)."""
from __future__ import annotations

import numpy as np


def discounted_returns(rewards: np.ndarray, gamma: float, bootstrap_value: float = 0.0) -> np.ndarray:
    """G_t = r_t + gamma * G_{t+1}, with G_T = bootstrap_value.

    rewards: float [T]. Returns float32 [T].
    """
    rewards = np.asarray(rewards, dtype=np.float32)
    returns = np.zeros_like(rewards)
    running = np.float32(bootstrap_value)
    gamma = np.float32(gamma)
    for t in range(rewards.shape[0] - 1, -1, -1):
        running = rewards[t] + gamma * running
        returns[t] = running
    return returns


def gae(
    rewards: np.ndarray,
    values: np.ndarray,
    bootstrap_value: float,
    gamma: float,
    lambd: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Advantages A_t = sum_k (gamma*lambd)^k delta_{t+k}, delta_t = r_t + gamma*V_{t+1} - V_t.

    rewards, values: float [T] (values are V(obs_t)); bootstrap_value is V_T (0 for a true terminal).
    Returns (advantages float32 [T], returns float32 [T]) with returns = advantages + values.
    """
    rewards = np.asarray(rewards, dtype=np.float32)
    values = np.asarray(values, dtype=np.float32)
    next_values = np.append(values[1:], np.float32(bootstrap_value))
    deltas = rewards + np.float32(gamma) * next_values - values
    advantages = discounted_returns(deltas, gamma * lambd, 0.0)
    return advantages, advantages + values
