"""Roy (2022), thesis 001: formation control of swarm robots (digest ``001-roy-formation.md``). Chapter 3: its
numerical model (``numerical``: point double-integrator agents running ``swarm_logic.families.roy``'s ``RoyApf``
through the SonPI's device protocols, ``swarm_logic.robots.sonpi.interfaces``), the experiment ``roy-apf``
(``experiments``: the numerical model, and sessions of SonPIs for chapter 7's hardware cases, ``cosim``), the loop
functions scoring a session's formation (``loop_functions``, a ``[formation]`` section), the benchmark (``bench``)
and the config check that its controllers' target is reachable (``checks``); see ``docs/roy.md``. Chapters 4-6
(virtual regions): their point model (``regions_world``), scenario files (``regions_scenarios``), metrics
(``metrics``) and the experiment ``roy-regions`` (``regions_experiments``); see ``docs/roy-ch4.md``."""

from __future__ import annotations

from bridge.core.registry import Study
from bridge.studies.roy.checks import BEHAVIOURS, check
from bridge.studies.roy.config import FormationCfg

STUDY = Study(
    "roy",
    "Roy: formation control with attraction-repulsion potentials and metaheuristic gain tuning",
    experiments=("bridge.studies.roy.experiments", "bridge.studies.roy.regions_experiments"),
    loop_functions="bridge.studies.roy.loop_functions:RoyLoopFunctions",
    sections=("formation",),
    config={"formation": FormationCfg},
    bench="bridge.studies.roy.bench:bench",
    check=check,
    behaviours=BEHAVIOURS,
)
