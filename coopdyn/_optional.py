"""Lazy imports of the heavier dependencies, with an error that names the install command."""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import MissingDependencyError


def require(module: str, feature: str, pip: str) -> ModuleType:
    """Import ``module`` or raise :class:`MissingDependencyError` naming the ``pip install``;
    ``pip``: a package (``"tqdm"``) or one of coopdyn's extras (``"coopdyn[peers]"``, installed
    from the repository, as coopdyn is not on the package index)."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        if pip.startswith("coopdyn["):
            how = f'pip install -e ".{pip[len("coopdyn") :]}" in the coopdyn repository (bash run.sh test installs every extra)'
        else:
            how = f"pip install {pip}"
        raise MissingDependencyError(f"{feature} needs the package '{pip}': {how}") from exc
