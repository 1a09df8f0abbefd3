"""Rig files: loading and checking a rig's YAML, and the skeleton it describes."""
