"""What the shared networks are built from: ``NetworkHyperparams`` and ``SignalNetwork``, views
generated from trainer/config's classes (the fields and how they are filled: trainer/config/views.py).

``NetworkHyperparams`` is one behavior's ``network_settings``, flat (``memory`` as ``memory_size``,
0 without an LSTM, and ``sequence_length``). Every algorithm's view (``PPOHyperparams``,
``SACHyperparams``) extends it, so networks, the acting policy and the reward signals of this
package take any of them and read nothing an algorithm owns. ``SignalNetwork`` is an intrinsic
reward signal's learner: its own keys on top of the network view of its ``network_settings``
(memory left out, as the reference does in these encoders).
"""
from __future__ import annotations

from trainer.config.views import network_view, signal_network_view

NetworkHyperparams = network_view("NetworkHyperparams", __name__)
SignalNetwork = signal_network_view("SignalNetwork", NetworkHyperparams, __name__)

__all__ = ["NetworkHyperparams", "SignalNetwork"]
