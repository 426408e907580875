"""The 3-D beam element (Euler–Bernoulli, or Timoshenko with a shear factor) between two frames.

A straight prismatic beam of length L runs along the x axis of T; at rest its far end sits at
G, and T is placed at that rest position of the far end on the near node (the model builder does
this: :class:`coopdyn.model.beam.Beam`). The element is then the SE(3) law of
:mod:`.se3_spring` — ``U = ½ eᵀ K e``, ``e = log6(T_M_G)`` — with K the beam's tip stiffness
with the near end clamped (:func:`tip_stiffness`): the direct stiffness method's element matrix
is ``Bᵀ K B`` for the rigid-body map B of the two ends, so the energy is the beam's exactly for
small deformations and stays frame-invariant (no spurious forces under large rigid motions)
for large ones. Damping is stiffness-proportional, ``D = β K`` [β in s]. Its C++ twin is the
SE(3) spring's, given this K and D.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ... import _validate
from ...errors import SceneError
from .se3_spring import SE3Spring


@dataclass(frozen=True)
class Section:
    """A beam's material and cross-section (beam axes: x along the beam, y and z across).

    Attributes:
        E: Young's modulus [Pa]. G: shear modulus [Pa]. rho: density [kg/m³].
        A: area [m²]. Iy, Iz: second moments about y and z [m⁴] (Iy resists bending in the x–z
        plane). J: torsion constant [m⁴].
        shear_factor: κ for Timoshenko shear deformation (5/6 for a rectangle, 6/7 for a disc);
            ``None`` (default): Euler–Bernoulli, no shear deformation.
    """

    E: float
    G: float
    rho: float
    A: float
    Iy: float
    Iz: float
    J: float
    shear_factor: float | None = None

    def __post_init__(self) -> None:
        units = {"E": "Pa", "G": "Pa", "rho": "kg/m³", "A": "m²", "Iy": "m⁴", "Iz": "m⁴", "J": "m⁴"}
        for name, unit in units.items():
            object.__setattr__(self, name, _validate.positive(getattr(self, name), f"Section: {name}", unit))
        if self.shear_factor is not None:
            object.__setattr__(self, "shear_factor", _validate.positive(self.shear_factor, "Section: shear_factor", "1"))

    @classmethod
    def rectangle(cls, width: float, height: float, E: float, rho: float, nu: float = 0.3, timoshenko: bool = False) -> Section:
        """A solid ``width`` (along y) × ``height`` (along z) rectangle [m] of an isotropic
        material: E [Pa], density [kg/m³], Poisson's ratio ``nu``; J by Roark's series-fitted
        formula (0.1 % accurate)."""
        timoshenko = _validate.flag(timoshenko, "Section.rectangle: timoshenko")
        b = _validate.positive(width, "Section.rectangle: width", "m")
        h = _validate.positive(height, "Section.rectangle: height", "m")
        nu = _validate.number(nu, "Section.rectangle: nu", "1")
        if not -1.0 < nu < 0.5:
            raise SceneError(f"Section.rectangle: Poisson's ratio must be in (-1, 0.5), got {nu}")
        E = _validate.positive(E, "Section.rectangle: E", "Pa")
        with _representable(f"Section.rectangle({b:g} m × {h:g} m)"):
            a, c = max(b, h) / 2, min(b, h) / 2
            J = a * c**3 * (16 / 3 - 3.36 * c / a * (1 - c**4 / (12 * a**4)))
            return cls(E, E / (2 * (1 + nu)), rho, b * h, b * h**3 / 12, h * b**3 / 12, J, 5 / 6 if timoshenko else None)

    @classmethod
    def circle(cls, diameter: float, E: float, rho: float, nu: float = 0.3, timoshenko: bool = False) -> Section:
        """A solid round bar of ``diameter`` [m] (see :meth:`rectangle` for the rest)."""
        timoshenko = _validate.flag(timoshenko, "Section.circle: timoshenko")
        d = _validate.positive(diameter, "Section.circle: diameter", "m")
        nu = _validate.number(nu, "Section.circle: nu", "1")
        if not -1.0 < nu < 0.5:
            raise SceneError(f"Section.circle: Poisson's ratio must be in (-1, 0.5), got {nu}")
        E = _validate.positive(E, "Section.circle: E", "Pa")
        with _representable(f"Section.circle({d:g} m)"):
            I = np.pi * d**4 / 64
            return cls(E, E / (2 * (1 + nu)), rho, np.pi * d**2 / 4, I, I, 2 * I, 6 / 7 if timoshenko else None)


@contextmanager
def _representable(what: str) -> Iterator[None]:
    """Turn a float overflow, underflow to zero or division by zero inside the block into a
    SceneError naming ``what``: sizes and materials far outside any real beam."""
    try:
        yield
    except (OverflowError, ZeroDivisionError) as exc:
        raise SceneError(
            f"{what}: its stiffness or mass is not representable in floating point ({exc}); give lengths in metres, "
            "moduli in pascals and densities in kg/m³ of a real beam"
        ) from None
    except SceneError as exc:
        raise SceneError(f"{what}: {exc} (an overflow or underflow of its properties?)") from None


@dataclass(frozen=True)
class BeamSegment:
    """A straight beam of ``length`` [m] and ``section``: the stiffness of a :class:`BeamElement`."""

    section: Section
    length: float

    def __post_init__(self) -> None:
        if not isinstance(self.section, Section):
            raise SceneError(f"BeamSegment: section must be a coopdyn Section, got {type(self.section).__name__}")
        object.__setattr__(self, "length", _validate.positive(self.length, "BeamSegment: length", "m"))


def tip_stiffness(section: Section, length: float) -> np.ndarray:
    """The 6×6 stiffness of the far end of a beam clamped at its near end [N/m, N, N·m/rad],
    order (u, v, w, θx, θy, θz) in beam axes: axial EA/L, torsion GJ/L, and per bending plane
    the Euler–Bernoulli (or, with a shear factor, Timoshenko) block — e.g. in x–y
    ``EIz/(L³(1+Φ)) [[12, −6L], [−6L, (4+Φ)L²]]`` on (v, θz), Φ = 12 EIz / (κ G A L²)."""
    s, L = section, _validate.positive(length, "tip_stiffness: length", "m")
    K = np.zeros((6, 6))
    with _representable(f"a beam element of {L:g} m"), np.errstate(all="ignore"):
        K[0, 0] = s.E * s.A / L
        K[3, 3] = s.G * s.J / L
        for I, (d, r, sign) in ((s.Iz, (1, 5, -1.0)), (s.Iy, (2, 4, 1.0))):
            phi = 0.0 if s.shear_factor is None else 12 * s.E * I / (s.shear_factor * s.G * s.A * L**2)
            c = s.E * I / (L**3 * (1 + phi))
            K[d, d] = 12 * c
            K[d, r] = K[r, d] = sign * 6 * L * c
            K[r, r] = (4 + phi) * L**2 * c
        if not np.all(np.isfinite(K)) or not np.all(np.diag(K) > 0):
            raise ZeroDivisionError("a stiffness overflowed or vanished")
    return K


class BeamElement(SE3Spring):
    """A beam between T and G (see the module docstring).

    Args:
        stiffness: a :class:`BeamSegment` (section and length).
        damping: β [s], the stiffness-proportional damping ``D = β K``; default none.
        name: what messages call it.
    """

    kind: ClassVar[str] = "beam"
    rigid: ClassVar[str | None] = None  # a beam's own joints: the rigid limit keeps the beam

    def __init__(self, stiffness: Any, damping: Any = None, name: str = "beam") -> None:
        if not isinstance(stiffness, BeamSegment):
            raise SceneError(f"{name}: a beam element's stiffness is a coopdyn BeamSegment(section, length), got {stiffness!r}")
        self.segment = stiffness
        K = tip_stiffness(stiffness.section, stiffness.length)
        beta = 0.0 if damping is None else _validate.non_negative(damping, f"{name}: damping β", "s")
        self._keep(K, beta * K, name)
        self.beta = beta

    def __repr__(self) -> str:
        return f"BeamElement(L = {self.segment.length:g} m, β = {self.beta:g} s)"
