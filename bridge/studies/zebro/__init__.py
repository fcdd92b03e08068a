"""Thesis 002 (Agrawal 2019, Zebro swarm decisions): the silent, immature and mature algorithms on the thesis'
six setups, in its NetLogo tick semantics (``numerical``), and the statistical reproduction (``experiments``).

The swarm logic is ``swarm_logic.families.zebro``, the robot's device protocols
``swarm_logic.robots.decizebro.interfaces``; the algorithms, their readings and the calibration are in
``docs/zebro-algorithms.md``, the report in ``docs/results/zebro-decisions/``.
"""

from __future__ import annotations

from bridge.core.registry import Study

STUDY = Study(
    "zebro", "Agrawal 2019: collective decisions of a Zebro swarm (silent, immature, mature), numerical",
    experiments=("bridge.studies.zebro.experiments",))
