"""Policies: trained controller policies stored by sha256 with their manifests."""
