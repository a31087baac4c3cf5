"""Corridors: the geometry vehicles and tools need (segments, x_m, postmiles, lanes)."""
