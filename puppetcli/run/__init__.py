"""Running a script on a rig: the runner, the first run's engine choice, the keys a run
takes and what they become on disk, and the run's trace.
"""
