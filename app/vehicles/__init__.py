"""Vehicles: the roster, their assignments and (later) their pings, status and config."""
