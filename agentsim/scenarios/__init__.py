"""Scenarios: the virtual conductor and the virtual storyteller."""
