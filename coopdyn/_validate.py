"""Input checks shared by the scene builders (internal)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from .errors import SceneError

ArrayLike = Any


def finite_array(value: ArrayLike, name: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """Return ``value`` as a float array, checking its shape and that every entry is finite."""
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{name} must be numeric, got {value!r}") from exc
    if shape is not None and arr.shape != shape:
        raise SceneError(f"{name} must have shape {shape}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise SceneError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def positive(value: Any, name: str, unit: str) -> float:
    """Return ``value`` as a float, checking it is finite and > 0."""
    x = float(finite_array(value, name, ()))
    if x <= 0.0:
        raise SceneError(f"{name} must be > 0 [{unit}], got {x}")
    return x


def non_negative(value: Any, name: str, unit: str) -> float:
    """Return ``value`` as a float, checking it is finite and >= 0."""
    x = float(finite_array(value, name, ()))
    if x < 0.0:
        raise SceneError(f"{name} must be >= 0 [{unit}], got {x}")
    return x


def se3(value: Any, name: str) -> pin.SE3:
    """Accept a ``pin.SE3``, a 4x4 homogeneous matrix or a 3-vector (pure translation)."""
    if isinstance(value, pin.SE3):
        pose = pin.SE3(value)
    else:
        arr = finite_array(value, name)
        if arr.shape == (3,):
            pose = pin.SE3(np.eye(3), arr)
        elif arr.shape == (4, 4):
            if not np.allclose(arr[3], [0.0, 0.0, 0.0, 1.0]):
                raise SceneError(f"{name}: the last row of a homogeneous matrix must be [0, 0, 0, 1]")
            pose = pin.SE3(arr[:3, :3].copy(), arr[:3, 3].copy())
        else:
            raise SceneError(
                f"{name} must be a pinocchio.SE3, a 4x4 homogeneous matrix or a 3-vector (translation [m]), got shape {arr.shape}"
            )
    if not (np.all(np.isfinite(pose.homogeneous))):
        raise SceneError(f"{name} must be finite")
    R = pose.rotation
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0.0:
        raise SceneError(f"{name}: the rotation part is not a proper rotation matrix (RᵀR = I, det R = 1)")
    return pose


def spd6(value: Any, name: str, unit: str) -> np.ndarray:
    """A symmetric positive semi-definite 6x6 matrix from a 6x6 array or a 6-vector diagonal."""
    arr = finite_array(value, name)
    if arr.shape == (6,):
        arr = np.diag(arr)
    if arr.shape != (6, 6):
        raise SceneError(
            f"{name} must be a 6x6 matrix or a 6-vector diagonal [{unit}] "
            f"(order: linear x, y, z, then angular x, y, z), got shape {arr.shape}"
        )
    return symmetric_psd(arr, name)


def symmetric_psd(arr: np.ndarray, name: str) -> np.ndarray:
    """``arr`` (square, finite) checked symmetric and positive semi-definite to 1e-9 relative, and
    returned exactly symmetric. The checks work on ``arr / max|arr|``, so that nothing overflows up
    to the float limit."""
    scale = max(float(np.max(np.abs(arr))), 1e-300)
    unit = arr / scale
    asym = float(np.max(np.abs(unit - unit.T)))
    if asym > 1e-9:
        raise SceneError(f"{name} must be symmetric; max |{name} − {name}ᵀ| = {asym * scale:.3g}")
    unit = 0.5 * (unit + unit.T)
    smallest = float(np.linalg.eigvalsh(unit)[0])
    if smallest < -1e-9:
        raise SceneError(
            f"{name} must be positive semi-definite (an elastic energy ½ eᵀ K e ≥ 0); "
            f"its smallest eigenvalue is {smallest * scale:.6g}"
        )
    return 0.5 * arr + 0.5 * arr.T  # halves first: no overflow, and exact for a symmetric arr
