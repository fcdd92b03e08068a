"""Roy (2022) chapter 3 (digest 001 §2.1): attraction, repulsion and obstacle avoidance for double-integrator agents,
the four gains of each agent re-tuned every step by a metaheuristic (BAT, PSO, BFO, BGPSO, PSOABG).

``potential`` is the law (eqs. 3.3-3.5, 3.20, 3.21), ``objective`` the gain objective (eq. 3.22, literal and
one-step look-ahead), ``pso``, ``bfo`` and ``bat`` the optimisers, ``controller`` the ``RoyApf`` behaviour.
"""
