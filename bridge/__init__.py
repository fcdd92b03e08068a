"""The co-simulation: session launcher, the world and its clock, transports, recording, and the plug-ins
(python-can interface, pyserial URL handler) that make simulated devices look real to the swarm logic."""
