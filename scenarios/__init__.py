"""Scenarios that use the realizer: the virtual conductor, the virtual storyteller, and the speech-sync
measurement (beats on every content word)."""
