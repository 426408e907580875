"""Paths of the files coopdyn ships (URDFs)."""

from __future__ import annotations

from pathlib import Path

from .errors import ModelLoadError

_PACKAGE = Path(__file__).resolve().parent


def urdf_path(name: str) -> Path:
    """Path of a URDF shipped with coopdyn, e.g. ``urdf_path("slider_z.urdf")``.

    Installed wheels carry the files in ``coopdyn/urdf``; a source checkout keeps them in the
    repository's ``urdf/`` folder.
    """
    for folder in (_PACKAGE / "urdf", _PACKAGE.parent / "urdf"):
        path = folder / name
        if path.is_file():
            return path
    raise ModelLoadError(f"coopdyn ships no URDF named {name!r} (looked in {_PACKAGE / 'urdf'} and {_PACKAGE.parent / 'urdf'})")
