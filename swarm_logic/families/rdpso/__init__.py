"""Robotic Darwinian PSO (RDPSO, Couceiro 2013): motion law, MANET graph tools, deployment geometry, fuzzy tuning.

The modules here are pure math with no simulator dependencies, so they run unchanged on a robot's companion computer.
"""
