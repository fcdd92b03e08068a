"""Swarm logic: what runs on a robot's companion computer.

It talks only to device interfaces (a python-can bus, a pyserial port, a MAVLink link) and a ``Clock``.
It imports nothing from the simulator, so the same code drives simulated and real robots.
"""
