"""What PPO reads of a behavior's settings: ``PPOHyperparams``, generated from trainer/config's classes.

A flat, frozen view of ``PPOSettings``, ``max_steps`` and the reward signals on top of the shared
``NetworkHyperparams`` (the fields and how they are filled: trainer/config/views.py). MA-POCA uses
it too: its settings are PPO's without ``shared_critic``, which then keeps its default.
"""
from __future__ import annotations

from trainer.common.hyperparams import NetworkHyperparams, SignalNetwork
from trainer.config.settings import PPOSettings
from trainer.config.views import algorithm_view

PPOHyperparams = algorithm_view("PPOHyperparams", PPOSettings, __name__, NetworkHyperparams, SignalNetwork)

__all__ = ["PPOHyperparams"]
