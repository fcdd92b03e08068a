"""Thesis 002 (Agrawal 2019, TU Delft: collective decisions of Zebro hexapods): its sessions' food particles and
decision figures (loop functions), its experiments and numerical model.

Sessions in ``hil_configs/zebro/``; the robot is ``bridge/robots/decizebro``.
"""

from __future__ import annotations

from bridge.core.registry import Study
from bridge.studies.zebro.loop_functions import ZebroLoopFunctions
from bridge.studies.zebro.particles import ParticleCfg, check

STUDY = Study(
    "zebro", "Agrawal 2019: silent, immature and mature collective decisions of DeciZebro hexapods",
    loop_functions=ZebroLoopFunctions, configs="hil_configs/zebro", sections=("particles",),
    config={"particles": list[ParticleCfg]}, check=check)
