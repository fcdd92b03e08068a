"""keep_in_touch: an example swarm project built on swarm-sitl (a behaviour, a session config, integration tests)."""
