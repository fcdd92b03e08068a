"""Roy (2022) chapters 4-6 (digest 001 §2.2-2.4): formation control by virtual regions. A global controller fits a
region into the free space the agents' sonars sense and moves it toward the target; each agent's local controller
converges into the region and keeps its place in the formation.

``sensing`` turns range readings into obstacle points, ``ellipse`` is chapter 4's circle/ellipse region (the gap by
k-means, the moving-obstacle test, failure shrink), ``formation`` the formation graphs and spanning-tree shape
matching, ``efa`` and ``packing`` chapter 5's polygonal region and its circles, ``split_merge`` chapter 6's openings,
sub-swarms and merges, ``laws`` the agents' local controllers, ``shapes`` the region value, ``records`` what their
records share.

``planner`` is the contract between a global controller and the agents (an Observation in, a Plan out; the registry
of planners); ``converge``, ``ch4``, ``ch5`` and ``ch6`` are the planners; ``agent`` is the SonPI behaviour that
follows a plan.
"""
