"""MCAP files: device sessions (format, recording from a script, replaying) and run traces."""
