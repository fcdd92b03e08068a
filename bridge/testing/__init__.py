"""Testing a swarm against its simulation: a session a test drives in simulated time (``SwarmSession``) and the
pytest plugin that hands one to a test (``swarm_session``)."""

from bridge.testing.session import LogLine, SessionEnded, SimTimeout, SwarmSession

__all__ = ["LogLine", "SessionEnded", "SimTimeout", "SwarmSession"]
