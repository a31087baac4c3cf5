"""Simulation on real I-24 trajectories: vehicle models, energy model, scenarios, KPIs."""
