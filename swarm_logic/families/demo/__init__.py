"""The demo behaviours: a random walk, an RSSI-keeping swarm, the radio survey's walker."""
