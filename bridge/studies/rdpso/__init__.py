"""Thesis 000 (Couceiro 2013, RDPSO): its experiments, metrics, numerical models and loop functions.

Sessions in ``hil_configs/rdpso/``; the swarm logic is ``swarm_logic.families.rdpso`` (and the chapter 8 baselines,
``swarm_logic.families.baselines``); reports in ``docs/results/`` and ``docs/rdpso.md``.
"""

from __future__ import annotations

from bridge.core.registry import Study
from bridge.studies.rdpso.config import ObjectiveCfg

STUDY = Study(
    "rdpso", "Couceiro 2013: RDPSO search, marsupial deployment, routing and mapping with eSwarBots and TraxBots",
    experiments=("bridge.studies.rdpso.experiments", "bridge.studies.rdpso.field_experiments",
                 "bridge.studies.rdpso.benchmark_experiments", "bridge.studies.rdpso.comm_experiments"),
    loop_functions="bridge.studies.rdpso.loop_functions:RdpsoLoopFunctions",
    configs="hil_configs/rdpso", sections=("deployment", "comm", "mapping"),
    config={"objective": ObjectiveCfg}, bench="bridge.studies.rdpso.bench:bench")
