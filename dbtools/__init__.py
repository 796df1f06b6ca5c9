"""Onboard DB tools: build, validate, diff, release, and the GIS grid tools."""
