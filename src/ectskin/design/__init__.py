"""Designing a skin before making one: scoring layouts and their fabrication variability."""
