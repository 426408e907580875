"""The exact-Jacobian variant of the Python dynamics, for measurements only (issue 27, item 3).

The linearly implicit methods factor ``S = M + γh (D̃ + Kd) + (γh)² (K̃ + Kp)`` with the
Gauss–Newton ``K̃ = Σ Jrᵀ S_K Jr`` and ``D̃``. :class:`ExactJacobian` gives them ``K̃ = −M ∂q̈/∂q``
and ``D̃ = −M ∂q̈/∂v`` from :meth:`coopdyn.Dynamics.derivatives` (S is then not symmetric: an
inverse instead of Cholesky); :func:`jacobian` swaps it in for the ``"python"`` backend within a
block. ``benchmarks/exact_jacobian.py`` and ``benchmarks/exponential_rosenbrock.py --jacobian
exact`` use it. It is not a method of the package: it does not win (docs/benchmarks.md).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from ..dynamics import dynamics as _dynamics


class ExactJacobian(_dynamics.PythonDynamics):
    """The Python reference with K̃ = −M ∂q̈/∂q and D̃ = −M ∂q̈/∂v from the exact derivatives."""

    def implicit_terms(
        self, q: np.ndarray, v: np.ndarray, tau: np.ndarray, object_wrench: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        f, M, _, _ = super().implicit_terms(q, v, tau, object_wrench)
        d = self.derivatives(q, v, tau, object_wrench)
        return f, M, -(M @ d.da_dq), -(M @ d.da_dv)

    def factor(
        self, M: np.ndarray, K: np.ndarray, D: np.ndarray, gh: Any, kp: np.ndarray, kd: np.ndarray, gh2: Any = None
    ) -> None:
        gh, gh2 = _dynamics.step_coefficients(gh, gh2)
        K_g, D_g = K.copy(), D.copy()
        self.add_joint_gains(K_g, D_g, kp, kd)
        self._step = (np.linalg.inv(M + gh * D_g + gh2 * K_g), K_g, gh)


@contextmanager
def jacobian(kind: str) -> Iterator[None]:
    """Within the block, the "python" backend is the exact-Jacobian variant (``kind="exact"``)."""
    saved = _dynamics.KINDS["python"]
    if kind == "exact":
        _dynamics.KINDS["python"] = ExactJacobian
    try:
        yield
    finally:
        _dynamics.KINDS["python"] = saved
