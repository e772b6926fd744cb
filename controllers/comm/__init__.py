"""Seed 001's communication layer: each agent acts on what it has received.

    config.py      :class:`CommConfig` (radius, delays, loss, clocks) and :class:`CommStats`
    messages.py    message copies as parallel arrays, per-agent clocks
    views.py       per-agent views laid side by side for one law call
    controller.py  :class:`CommunicatingController`: wraps any law (the model, the cost)
"""

from controllers.comm.config import CommConfig, CommStats
from controllers.comm.controller import CommunicatingController

__all__ = ["CommConfig", "CommStats", "CommunicatingController"]
