"""The four swarm-search algorithms the thesis benchmarks RDPSO against (Couceiro 2013, chapter 8, Table 8.1):

- ``epso.Epso``: Extended PSO (Pugh & Martinoli 2006/2007), neighbourhood best from the robots in range;
- ``ppso.Ppso``: Physically-embedded PSO (Hereford & Siebold 2008/2010), Algorithm 8.2;
- ``gso.Gso``: Glowworm Swarm Optimization (Krishnanand & Ghose 2009a/b);
- ``afs.Afs``: Aggregations of Foraging Swarms (Gazi & Passino 2003/2004), Algorithm 8.4.

Each is a ``Controller`` that, like ``swarm_logic.families.rdpso``,
knows only the robot's devices (``swarm_logic.hal``):
the light sensor and sonar through the LLC, one XBee broadcast per robot per iteration, rotate-then-go moves.
``common`` holds the iteration clock, the radio and move plumbing and the update rules two of them share.
"""
