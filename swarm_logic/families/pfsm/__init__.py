"""Khan's multi-robot search: a probabilistic finite state machine (SEARCH, RETURN, TIMEOUT) whose searchers keep
Lennard-Jones spacing while heading for the closest target, and the targets that drive home once found.

The controllers see only the foot-bot's devices (``swarm_logic.robots.footbot.interfaces``). Where the document is
ambiguous (digest section 5.3, K-1 ... K-11) each reading is a parameter; ``docs/pfsm.md`` lists them.
"""
