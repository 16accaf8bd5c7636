"""Panorama geometry, features, matching, the belief over rooms and the disambiguation policy."""
