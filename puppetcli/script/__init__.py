"""Manipulation scripts: the file, its actions, and the expectations checked after a run."""
