"""The publication's experiments as declarative scenes, sweeps and the study runner."""
