"""What SAC reads of a behavior's settings: ``SACHyperparams``, generated from trainer/config's classes.

A flat, frozen view of ``SACSettings``, ``max_steps`` and the reward signals on top of the shared
``NetworkHyperparams`` (trainer/config/views.py), so the same networks build from it as from PPO's.
"""
from __future__ import annotations

from trainer.common.hyperparams import NetworkHyperparams, SignalNetwork
from trainer.config.settings import SACSettings
from trainer.config.views import algorithm_view

SACHyperparams = algorithm_view("SACHyperparams", SACSettings, __name__, NetworkHyperparams, SignalNetwork)

__all__ = ["SACHyperparams"]
