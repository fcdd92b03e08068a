"""Thesis 002 (Agrawal 2019, TU Delft: collective decisions of Zebro hexapods): its sessions' food particles and
decision figures (loop functions), its experiments and its numerical model.

Sessions in ``hil_configs/zebro/``; the robot is ``bridge/robots/decizebro``. The swarm logic is
``swarm_logic.families.zebro``, the robot's device protocols ``swarm_logic.robots.decizebro.interfaces``; the
numerical model of the thesis' NetLogo ticks is ``numerical``, the statistical reproduction ``experiments``; the
algorithms, their readings and the calibration are in ``docs/zebro-algorithms.md``, the reports in
``docs/results/zebro-decisions/`` and ``docs/results/zebro-sensitivity/``.
"""

from __future__ import annotations

from bridge.core.registry import Study
from bridge.studies.zebro.decision import DecisionCfg
from bridge.studies.zebro.particles import ParticleCfg, check

STUDY = Study(
    "zebro", "Agrawal 2019: silent, immature and mature collective decisions of DeciZebro hexapods",
    experiments=("bridge.studies.zebro.experiments", "bridge.studies.zebro.cosim_experiments"),
    loop_functions="bridge.studies.zebro.loop_functions:ZebroLoopFunctions",
    configs="hil_configs/zebro", sections=("particles", "decision"),
    config={"particles": list[ParticleCfg], "decision": DecisionCfg}, check=check,
    bench="bridge.studies.zebro.bench:bench")
