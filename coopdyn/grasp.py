"""Grasp geometry: the grasp matrix, the non-squeezing load distribution, internal forces.

Wrenches are ``[force; moment]`` (6,) in world-aligned axes. ``f_i`` is the wrench arm i's
interconnection exerts on the object, with the moment about its grasp point ``p_i``. The
grasp matrix ``G`` (6, 6N) maps the stacked ``f`` to the resultant about the reference point
``c`` (the grasp points' centroid). Its null space holds the internal wrenches — those that
squeeze or twist the object without moving it. The Moore–Penrose solution ``f = G⁺ F`` is the
non-squeezing distribution: it has no component in that null space, and for any grasp
geometry the force differences of every pair of grasps are orthogonal to the line joining
them (tested on random geometries).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pinocchio as pin

from .errors import GraspGeometryError, SceneError


def grasp_matrix(points: np.ndarray, center: np.ndarray | None = None) -> np.ndarray:
    """G (6, 6N) for grasp points (N, 3) [m], moments about ``center`` (default: their centroid)."""
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] < 1:
        raise SceneError(f"grasp points must have shape (N, 3), got {P.shape}")
    c = P.mean(axis=0) if center is None else np.asarray(center, dtype=float)
    blocks = []
    for p in P:
        B = np.eye(6)
        B[3:, :3] = pin.skew(p - c)
        blocks.append(B)
    return np.hstack(blocks)


def distribute(G: np.ndarray, wrench: np.ndarray) -> np.ndarray:
    """Non-squeezing distribution ``G⁺ F`` of a resultant wrench (6,) over the grasps: (N, 6)."""
    return (np.linalg.pinv(G) @ np.asarray(wrench, dtype=float)).reshape(-1, 6)


class WrenchSplit(NamedTuple):
    """Grasp wrenches split into the part that moves the object and the internal part."""

    moving: np.ndarray  #: (N, 6) = G⁺ G f
    internal: np.ndarray  #: (N, 6) = (I − G⁺ G) f: squeezes/twists the object, sums to zero


def split(G: np.ndarray, wrenches: np.ndarray) -> WrenchSplit:
    """Split grasp wrenches (N, 6) into moving and internal parts."""
    f = np.asarray(wrenches, dtype=float).reshape(-1)
    moving = np.linalg.pinv(G) @ (G @ f)
    return WrenchSplit(moving.reshape(-1, 6), (f - moving).reshape(-1, 6))


def squeeze_directions(points: np.ndarray) -> np.ndarray:
    """Unit vectors (N, 3) from each grasp point towards the centroid: the direction of a
    compressive (positive) internal force on the object at that grasp. Points (n, N, 3) give
    (n, N, 3), sample by sample."""
    P = np.asarray(points, dtype=float)
    d = P.mean(axis=-2, keepdims=True) - P
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    if np.any(n < 1e-9):
        raise GraspGeometryError("grasp points coincide with their centroid: no squeeze direction")
    return d / n


def squeeze_force(points: np.ndarray, wrenches: np.ndarray) -> np.ndarray:
    """Internal (squeeze) force at each grasp [N]: the internal part's force along the inward
    squeeze direction (positive = compression)."""
    G = grasp_matrix(points)
    internal = split(G, wrenches).internal
    return np.einsum("ij,ij->i", internal[:, :3], squeeze_directions(points))


def squeeze_forces(points: np.ndarray, wrenches: np.ndarray) -> np.ndarray:
    """:func:`squeeze_force` at many samples at once: points (n, N, 3) [m], wrenches (n, N, 6)
    [N, N·m] → (n, N) [N].

    Closed form of the same projection: with moments about the centroid, ``G Gᵀ = diag(N·I, A)``,
    ``A = Σ (1 + |rᵢ|²) I − rᵢ rᵢᵀ`` (rᵢ = pᵢ − c), so ``G⁺ G f`` needs one 3×3 solve per sample
    instead of an SVD of G (tested equal to the pseudo-inverse)."""
    P = np.asarray(points, dtype=float)
    W = np.asarray(wrenches, dtype=float)
    if P.ndim != 3 or P.shape[2] != 3 or W.shape != (*P.shape[:2], 6):
        raise SceneError(f"need points (n, N, 3) and wrenches (n, N, 6), got {P.shape} and {W.shape}")
    n_grasps = P.shape[1]
    inward = squeeze_directions(P)
    r = P - P.mean(axis=1, keepdims=True)
    f, m = W[..., :3], W[..., 3:]
    resultant_f = f.sum(axis=1)  # G f, about the centroid
    resultant_m = (m + np.cross(r, f)).sum(axis=1)
    A = (n_grasps + np.einsum("sij,sij->s", r, r))[:, None, None] * np.eye(3) - np.einsum("sia,sib->sab", r, r)
    y_f = resultant_f / n_grasps
    y_m = np.linalg.solve(A, resultant_m[..., None])[..., 0]
    moving_f = y_f[:, None, :] - np.cross(r, y_m[:, None, :])  # the force part of G⁺ G f
    return np.einsum("sij,sij->si", f - moving_f, inward)
