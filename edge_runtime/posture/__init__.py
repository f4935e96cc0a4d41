"""Posture: the CAP score of a 3D pose and the GOLA-HRC work-piece optimiser."""
