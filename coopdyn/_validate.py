"""Input checks shared by the scene builders (internal)."""

from __future__ import annotations

import decimal
import math
import numbers
import os
import reprlib
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .errors import CoopdynError, SceneError, SceneWarning

ArrayLike = Any


def finite_array(
    value: ArrayLike, name: str, shape: tuple[int, ...] | None = None, error: type[CoopdynError] = SceneError
) -> np.ndarray:
    """Return ``value`` as a float array, checking its shape and that every entry is finite.

    Refused with ``error``: text, booleans, complex and object (non-numeric) entries — nothing is
    silently converted (a complex value would lose its imaginary part) —, ragged or over-deep
    nesting, and numbers beyond the float range."""
    if type(value) is np.ndarray and value.dtype == np.float64:  # the common case, checked in a few µs less
        if shape is not None and value.shape != shape:
            raise error(f"{name} must have shape {shape}, got shape {value.shape}")
        if not np.isfinite(value).all():
            raise error(f"{name} must be finite, got {_short(value.tolist())}")
        return value.copy()
    if isinstance(value, np.ma.MaskedArray):
        raise error(f"{name} must be a plain array; a masked array's masked entries have no value")
    if isinstance(value, str | bytes | bool | np.bool_) or value is None:
        raise error(f"{name} must be numeric, got {_short(value)}")
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError, OverflowError, RecursionError) as exc:
        raise error(f"{name} must be a number or a (nested) list of numbers of one shape, got {_short(value)}") from exc
    if raw.dtype.kind == "c":
        raise error(f"{name} must be real, got a complex value {_short(value)}")
    if raw.dtype.kind not in "iuf":
        if raw.dtype.kind == "O" and all(
            isinstance(x, numbers.Real | decimal.Decimal) and not isinstance(x, bool) for x in raw.flat
        ):
            pass  # Python integers beyond int64, Fractions, Decimals: converted (and range-checked) below
        else:
            raise error(f"{name} must be numeric, got {_short(value)}")
    try:
        arr = raw.astype(float)
    except (TypeError, ValueError, OverflowError) as exc:
        raise error(f"{name} must be within the float range (|x| < 1.8e308), got {_short(value)}") from exc
    if shape is not None and arr.shape != shape:
        raise error(f"{name} must have shape {shape}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise error(f"{name} must be finite, got {_short(arr.tolist())}")
    return arr


def number(value: Any, name: str, unit: str, error: type[CoopdynError] = SceneError) -> float:
    """``value`` as a finite float (a real number: not text, bool, complex or an array)."""
    if type(value) is float and math.isfinite(value):  # the common case, without the general checks (25 µs a run)
        return value
    return float(finite_array(value, f"{name} [{unit}]", (), error))


def gain(
    value: Any,
    name: str,
    n: int,
    unit: str,
    error: type[CoopdynError] = SceneError,
    *,
    per: str = "actuated joint",
    signed: bool = False,
) -> np.ndarray:
    """A scalar or one value per ``per`` (n of them), returned as (n,); non-negative unless ``signed``."""
    if (
        type(value) is np.ndarray
        and value.dtype == np.float64
        and value.shape == (n,)
        and np.isfinite(value).all()
        and (signed or not (value < 0.0).any())
    ):
        return value.copy()  # the common case, in a few µs less (a controller's gains() at every run)
    arr = finite_array(value, f"{name} [{unit}]", None, error)
    if arr.shape not in ((), (1,), (n,)):
        raise error(f"{name} must be a scalar or one value per {per} ({n}) [{unit}], got shape {arr.shape}")
    if not signed and np.any(arr < 0.0):
        raise error(f"{name} must be >= 0 [{unit}], got {_short(arr.tolist())}")
    return np.broadcast_to(arr.reshape(-1) if arr.shape == (1,) else arr, (n,)).copy()


def warn_if_degrees(angles: Any, name: str, stacklevel: int = 3) -> None:
    """Warn (SceneWarning) about each angle [rad] beyond ±2π: degrees given for radians (90 for a
    right angle turns 90 rad, 14 turns and 2.0 rad, without an error)."""
    for a in np.ravel(np.asarray(angles, dtype=float)):
        if abs(a) > 2 * np.pi:
            warnings.warn(
                f"{name} has {a:g} rad ({np.degrees(a):.0f}°): angles are in radians; if {a:g} is in degrees, "
                f"give {np.radians(a):.6g}",
                SceneWarning,
                stacklevel=stacklevel,
            )


def integral(value: Any) -> bool:
    """Whether ``value`` is an integer: a Python or numpy one, not a bool and not a numpy
    timedelta (a numpy signed integer that is a duration)."""
    return isinstance(value, int | np.integer) and not isinstance(value, bool | np.timedelta64)


#: the largest count taken: every integer up to it is a double's, and a C long's (the compiled
#: loop's counters) by far
MAX_COUNT = 2**53


def count(value: Any, name: str, error: type[CoopdynError] = SceneError, *, none: str | None = None) -> int:
    """An integer in [1, :data:`MAX_COUNT`] (not a bool, not a float); ``none`` names what
    ``None`` means, if allowed."""
    if not (integral(value) and value >= 1):
        also = f" or None ({none})" if none else ""
        raise error(f"{name} must be an integer >= 1{also}, got {_short(value)}")
    if value > MAX_COUNT:
        also = f" or None ({none})" if none else ""
        raise error(f"{name} must be at most 2**53 = {MAX_COUNT}{also}, got {_short(value)}")
    return int(value)


def flag(value: Any, name: str, error: type[CoopdynError] = SceneError) -> bool:
    """``value`` as a bool: only True or False (an array or a number is not taken for one)."""
    if not isinstance(value, bool | np.bool_):
        raise error(f"{name} must be True or False, got {_short(value)}")
    return bool(value)


PATH_MAX = 4096  #: [bytes] the longest path Linux takes
NAME_MAX = 255  #: [bytes] the longest file name
MAX_DEPTH = 256  #: the most folders a path may nest (creating deeper ones recurses once a level)


def path(value: Any, name: str, error: type[CoopdynError] = SceneError) -> Path:
    """A file-system path from a non-empty ``str`` or ``os.PathLike`` without NUL bytes, of a
    length and depth a file system takes."""
    if not isinstance(value, str | os.PathLike) or not isinstance(os.fspath(value), str) or not str(value) or "\0" in str(value):
        raise error(f"{name} must be a path, got {_short(value)}")
    result = Path(value)
    try:
        longest = max((len(os.fsencode(part)) for part in result.parts), default=0)
    except UnicodeError:
        raise error(f"{name} must be a path this file system can name, got {_short(str(result))}") from None
    if len(os.fsencode(str(result))) > PATH_MAX or longest > NAME_MAX or len(result.parts) > MAX_DEPTH:
        raise error(
            f"{name} is too long a path ({len(str(result))} characters, {len(result.parts)} levels, a name of {longest} "
            f"bytes; at most {PATH_MAX}, {MAX_DEPTH} and {NAME_MAX}): {_short(str(result))}"
        )
    return result


_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxtuple, _REPR.maxdict, _REPR.maxstring, _REPR.maxother = 4, 8, 8, 8, 100, 100


def _short(value: Any, limit: int = 120) -> str:
    """``repr(value)`` cut to ``limit`` characters and four levels of nesting (an error message
    must stay readable, and a list nested thousands deep must not recurse)."""
    try:
        text = _REPR.repr(value)
    except Exception:
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[: limit - 5] + " …" + text[-3:]


def positive(value: Any, name: str, unit: str, error: type[CoopdynError] = SceneError) -> float:
    """Return ``value`` as a float, checking it is finite and > 0."""
    x = float(finite_array(value, name, (), error))
    if x <= 0.0:
        raise error(f"{name} must be > 0 [{unit}], got {x}")
    return x


def non_negative(value: Any, name: str, unit: str) -> float:
    """Return ``value`` as a float, checking it is finite and >= 0."""
    x = float(finite_array(value, name, ()))
    if x < 0.0:
        raise SceneError(f"{name} must be >= 0 [{unit}], got {x}")
    return x


#: [m] how far from the world origin a pose may be: at 1e6 m a double still resolves 1e-10 m,
#: while at 1e154 m Pinocchio's inertias (squares of positions) overflow to NaN
MAX_DISTANCE = 1e6


def se3(value: Any, name: str) -> pin.SE3:
    """Accept a ``pin.SE3``, a 4x4 homogeneous matrix or a 3-vector (pure translation), within
    :data:`MAX_DISTANCE` of the origin."""
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
    far = float(np.max(np.abs(pose.translation)))  # (its norm can overflow)
    if far > MAX_DISTANCE:
        raise SceneError(
            f"{name}: the translation {far:.3g} m is farther than {MAX_DISTANCE:g} m from the origin "
            "(a scene's poses are in metres; that far, the dynamics lose their precision and overflow)"
        )
    R = pose.rotation
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0.0:
        raise SceneError(f"{name}: the rotation part is not a proper rotation matrix (RᵀR = I, det R = 1)")
    return pose


def spd6(value: Any, name: str, unit: str) -> np.ndarray:
    """A symmetric positive semi-definite 6x6 matrix from a 6x6 array, a 6-vector diagonal or a
    scalar (the same value on all six axes)."""
    arr = finite_array(value, name)
    if arr.shape == ():
        arr = float(arr) * np.eye(6)
    if arr.shape == (6,):
        arr = np.diag(arr)
    if arr.shape != (6, 6):
        raise SceneError(
            f"{name} must be a 6x6 matrix, a 6-vector diagonal or a scalar [{unit}] "
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
        raise SceneError(f"{name} must be symmetric; its largest asymmetry max |M − Mᵀ| is {asym * scale:.3g}")
    unit = 0.5 * (unit + unit.T)
    smallest = float(np.linalg.eigvalsh(unit)[0])
    if smallest < -1e-9:
        raise SceneError(
            f"{name} must be positive semi-definite (an elastic energy ½ eᵀ K e ≥ 0); "
            f"its smallest eigenvalue is {smallest * scale:.6g}"
        )
    return 0.5 * arr + 0.5 * arr.T  # halves first: no overflow, and exact for a symmetric arr
