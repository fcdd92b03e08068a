"""Swarm behaviours, by name; a config may also name any ``module:Class`` controller."""

from __future__ import annotations

import importlib

from swarm_logic.baselines.afs import Afs
from swarm_logic.baselines.epso import Epso
from swarm_logic.baselines.gso import Gso
from swarm_logic.baselines.ppso import Ppso
from swarm_logic.behaviours.radio_survey import RadioSurvey
from swarm_logic.behaviours.random_walk import RandomWalk
from swarm_logic.behaviours.rssi_keeper import RssiKeeper
from swarm_logic.controller import Controller
from swarm_logic.rdpso.controller import Rdpso
from swarm_logic.rdpso.est import EstRanger

BEHAVIOURS: dict[str, type[Controller]] = {"random_walk": RandomWalk, "radio_survey": RadioSurvey,
                                           "rssi_keeper": RssiKeeper, "rdpso": Rdpso, "est_ranger": EstRanger,
                                           # the thesis' chapter 8 baselines (swarm_logic/baselines)
                                           "epso": Epso, "ppso": Ppso, "gso": Gso, "afs": Afs}


def load_behaviour(name: str) -> type[Controller]:
    if name in BEHAVIOURS:
        return BEHAVIOURS[name]
    if ":" in name:
        module, _, attr = name.partition(":")
        cls = getattr(importlib.import_module(module), attr)
        if isinstance(cls, type) and issubclass(cls, Controller):
            return cls
        raise TypeError(f"{name} is not a swarm_logic.controller.Controller subclass")
    raise ValueError(f"unknown behaviour {name!r}; known: {', '.join(sorted(BEHAVIOURS))} or module:Class")
