"""The Zebro's collective decisions (Agrawal 2019, section 3.5): flocking (Algorithm 2), the silent protocol, the
immature gossip algorithm and the mature election, with the link-list gossip that builds an adjacency matrix.

The controllers see only the Zebro's devices (``swarm_logic.robots.decizebro.interfaces``): the UWB radio, the
utility sensor, the IMU and the legs. Where the thesis is ambiguous (digest section 5.3, A-1 ... A-19) each
reading is a parameter; ``docs/zebro-algorithms.md`` lists them.
"""
