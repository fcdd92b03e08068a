"""Khan's PFSM-LJ search with foot-bots (BRAC University; digest 003): its experiment and its numerical model.

The swarm logic is ``swarm_logic.families.pfsm``, the robot's device protocols
``swarm_logic.robots.footbot.interfaces``; the point-robot model of the ARGoS setup is ``numerical``, the 27-scenario
reproduction ``experiments``; the algorithm, its readings and the results are in ``docs/pfsm.md`` and
``docs/results/pfsm-search/``. The foot-bot in the pybullet world and its sessions come later.
"""

from __future__ import annotations

from bridge.core.registry import Study

STUDY = Study("pfsm", "Khan: multi-robot search with a probabilistic state machine and Lennard-Jones spacing",
              experiments=("bridge.studies.pfsm.experiments", "bridge.studies.pfsm.benchmark"))
