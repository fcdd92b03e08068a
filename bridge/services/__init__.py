"""Service kinds (``swarm_sitl.services``): the centralised programs a session may run beside its robots
(``bridge.core.services``): the SonPI swarm's overhead camera and its global controller."""
