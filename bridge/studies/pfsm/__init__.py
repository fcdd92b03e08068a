"""Khan's PFSM-LJ search with foot-bots (BRAC University; digest 003): its experiment and its numerical model.

The swarm logic is ``swarm_logic.families.pfsm``, the robot's device protocols
``swarm_logic.robots.footbot.interfaces``; the point-robot model of the ARGoS setup is ``numerical``, the 27-scenario
reproduction ``experiments``; the algorithm, its readings and the results are in ``docs/pfsm.md`` and
``docs/results/pfsm-search/``. Sessions of emulated foot-bots (``bridge/robots/footbot``) are in ``hil_configs/pfsm``;
their loop functions (``loop_functions``) score them as the numerical model does, and ``cosim_experiments`` runs the
25 m^2 arena's scenarios in co-simulation beside the numerical model.
"""

from __future__ import annotations

from bridge.core.registry import Study
from bridge.studies.pfsm.config import SearchCfg

STUDY = Study("pfsm", "Khan: multi-robot search with a probabilistic state machine and Lennard-Jones spacing",
              experiments=("bridge.studies.pfsm.experiments", "bridge.studies.pfsm.cosim_experiments",
                           "bridge.studies.pfsm.benchmark"),
              loop_functions="bridge.studies.pfsm.loop_functions:PfsmLoopFunctions",
              configs="hil_configs/pfsm", sections=("search",),
              config={"search": SearchCfg}, bench="bridge.studies.pfsm.bench:bench")
