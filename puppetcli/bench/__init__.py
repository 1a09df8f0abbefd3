"""Measurements: solver speed against error (bench, skips, stages, peers, precision), the
scripted pose against the bare stepper, live latency, the stress scenes, and the scenes
they share (``scenes``, ``stress_scenes``).
"""
