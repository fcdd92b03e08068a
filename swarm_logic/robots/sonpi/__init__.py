"""Roy's SonPI robot (digest 001 §3.2) as the swarm layer sees it: its device protocols (``interfaces``)."""
