"""Missions: the mission file and the app cores it configures.

- schema: mission files (TOML, pydantic) and `--set` overrides.
- cores: the helm, pid and sim cores and the in-process mission runner.
"""
