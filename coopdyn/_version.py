"""The package version: the same number as pyproject.toml's (tests/test_scene_files.py checks it)."""

__version__ = "0.1.0"
