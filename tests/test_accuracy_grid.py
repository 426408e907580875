"""The accuracy judgement over a grid of methods × steps × grasp stiffness × damping
(``benchmarks/accuracy_grid.py``): no run whose interconnection forces are wrong by more than
10 % of their peak completes in silence, and at most 5 % of the right runs are warned about.
Minutes of CPU: behind the slow marker (``pytest -m slow``)."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _grid_module() -> ModuleType:
    spec = importlib.util.spec_from_file_location("accuracy_grid", ROOT / "benchmarks" / "accuracy_grid.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
@pytest.mark.parametrize(
    ("beam", "duration", "max_stiffness"),
    [(False, 0.5, 1e7), (True, 0.3, 1e5)],
    ids=["box", "beam"],
)
def test_no_wrong_forces_in_silence_and_few_false_alarms(beam: bool, duration: float, max_stiffness: float) -> None:
    grid = _grid_module()
    verdict = grid.verdict(grid.grid(duration, beam, max_stiffness, log=lambda line: None))
    assert len(verdict["wrong"]) > 20 and len(verdict["right"]) > 20  # the grid holds both kinds
    assert [(r["method"], r["dt"], r["k"], r["beta"], round(r["error"], 3)) for r in verdict["silent"]] == []
    assert len(verdict["false"]) <= 0.05 * len(verdict["right"])
