"""What SAC reads of a behavior's settings: ``SACHyperparams``, generated from trainer/config's classes.

A flat, frozen view of ``SACSettings``, ``max_steps``, ``network_settings`` and the reward signals
(trainer/config/views.py); its network fields are ``PPOHyperparams``' so the same networks build
from either.
"""
from __future__ import annotations

from trainer.config.settings import SACSettings
from trainer.config.views import algorithm_view

SACHyperparams = algorithm_view("SACHyperparams", SACSettings, __name__)
