"""Fuzz harnesses for every parser a byte from outside the simulation reaches (``swarm-sitl fuzz``, ``make fuzz``).

A target is a plain function of one input (``bytes``) that drives a real parser the way outside bytes reach it: a
host's serial bytes into a module's firmware, a device's answers into the robot's driver, a CAN frame against the
DBC, a ground station's MAVLink, a participant's zenoh reply to the world. It returns normally for any input; what
the parser documents as a rejection (a counted, dropped frame; a driver's own error class) is part of normal. Any
other exception is a crash. ``fuzz.targets`` holds the registry; ``python -m fuzz`` runs one target under atheris
(libFuzzer) in its own process; ``fuzz/corpus/<target>/`` keeps each target's corpus (seeds built by the project's
own encoders, and what the fuzzer found that reached new code), which ``tests/fuzz`` replays in ``make test``.
"""
