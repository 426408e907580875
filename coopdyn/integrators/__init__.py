"""Integrators: one contract (:mod:`.base`), a registry of names, and the methods.

============================  =====  ========  ===========================================
name                          order  adaptive  per step
============================  =====  ========  ===========================================
``symplectic_euler``          1      no        1 RHS
``rk4``                       4      no        4 RHS
``dopri5``                    5(4)   yes       6 RHS (first same as last)
``dop853``                    8(5)   yes       12 RHS (first same as last); tight accuracy
``implicit_euler``            1      no        1 RHS, 1 Jacobian, 1 factorisation
``ros2``                      2      no        2 RHS, 1 Jacobian, 1 factorisation
``ros2_adaptive``             2(1)   yes       as ros2
``trapezoid``                 2      no        as ros2; does not damp oscillations (ρ∞ = 1)
``generalized_alpha``         2      no        2 RHS, 1 Jacobian, 1 factorisation; ρ∞ = 0.9
``exponential``               2*     no        1 matrix–vector product (linear scenes only)
``scipy``                     —      inside    scipy ``solve_ivp`` per step (reference)
============================  =====  ========  ===========================================

(*) exact for a sampled (held) controller with ``Exponential(hold="zoh")``.
"""

from __future__ import annotations

from ..errors import SimulationError, did_you_mean
from .base import AdaptiveIntegrator, Attempt, Integrator, Problem
from .explicit import (
    RK4,
    ButcherTableau,
    DormandPrince,
    DormandPrince853,
    EmbeddedRungeKutta,
    ExplicitRungeKutta,
    SymplecticEuler,
)
from .exponential import Exponential, LinearForm, linear_form
from .implicit import ROS2, AdaptiveROS2, GeneralizedAlpha, LinearlyImplicitEuler, Trapezoid
from .scipy_reference import ScipyReference

#: Name → integrator class. ``simulate(..., integrator=name)`` builds one with default settings.
INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls
    for cls in (
        SymplecticEuler,
        RK4,
        DormandPrince,
        DormandPrince853,
        LinearlyImplicitEuler,
        ROS2,
        AdaptiveROS2,
        Trapezoid,
        GeneralizedAlpha,
        Exponential,
        ScipyReference,
    )
}


def get_integrator(integrator: str | Integrator, also: str = "", extra: tuple[str, ...] = ()) -> Integrator:
    """An integrator instance from a name in :data:`INTEGRATORS` or an instance; ``also`` adds to
    the valid choices an unknown one is told, ``extra`` names the suggestions may add."""
    if isinstance(integrator, Integrator):
        return integrator
    if isinstance(integrator, str) and integrator in INTEGRATORS:
        return INTEGRATORS[integrator]()
    if isinstance(integrator, type) and issubclass(integrator, Integrator):
        name = getattr(integrator, "name", None)
        raise SimulationError(
            f"integrator is the class {integrator.__name__}, not an instance: give {integrator.__name__}() (with its "
            "settings)" + (f", or its name {name!r}" if isinstance(name, str) and name in INTEGRATORS else "")
        )
    hint = ""
    if isinstance(integrator, str):  # a case slip ('RK4') or a near miss ('dopri')
        names = [*INTEGRATORS, *extra]
        folded = [name for name in names if name == integrator.lower()]
        hint = f" Did you mean {folded[0]!r}?" if folded else did_you_mean(integrator, names)
    raise SimulationError(
        f"unknown integrator {integrator!r}; valid: {sorted(INTEGRATORS)} or an Integrator instance{also}.{hint}"
    )


__all__ = [
    "INTEGRATORS",
    "RK4",
    "ROS2",
    "AdaptiveIntegrator",
    "AdaptiveROS2",
    "Attempt",
    "ButcherTableau",
    "DormandPrince",
    "DormandPrince853",
    "EmbeddedRungeKutta",
    "ExplicitRungeKutta",
    "Exponential",
    "GeneralizedAlpha",
    "Integrator",
    "LinearForm",
    "LinearlyImplicitEuler",
    "Problem",
    "ScipyReference",
    "SymplecticEuler",
    "Trapezoid",
    "get_integrator",
    "linear_form",
]
