"""The rigid limit of a scene: every interconnection stiffened to a rigid grasp.

:func:`rigid_limit` is the reference the elastic model converges to as its stiffness grows
(docs/physics.md, "Three models"): the same arms, object, grasp frames and world fixtures, with
each SE(3) spring replaced by a rigid 6-D grasp and each ball spring by a rigid point grasp
(:mod:`coopdyn.model.elements.rigid`).
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import numpy as np
import pinocchio as pin

from .. import _validate
from ..errors import SceneError
from .elements import ELEMENTS
from .elements.rigid import BAUMGARTE_KD, BAUMGARTE_KP
from .scene import Scene


def rigid_limit(scene: Scene, baumgarte: Any = (BAUMGARTE_KP, BAUMGARTE_KD)) -> Scene:
    """The same scene with every interconnection a rigid grasp (and the object rigid).

    An elastic object (a :class:`~coopdyn.model.beam.Beam`) is first made one rigid body with
    its mass and inertia (:func:`quasi_static`): the rigid model of the whole system (welding
    the grasps of a beam whose own elements stay elastic would keep their kHz modes, which no
    explicit step resolves). The arms, the object and the fixture frames T are kept; each grasp frame G is placed where
    its T is at ``scene.q0``, so every rigid grasp starts satisfied. A grasp the elastic scene
    preloads (T ≠ G at ``q0``: a grasp error) cannot be represented — a rigid model carries no
    preload; that is the force uncertainty — and is dropped with a warning giving its size.
    ``coopdyn.simulate`` runs the result with the same controllers (explicit integrators); its
    ``Result.wrench(i)`` is then the constraint wrench on the object, in the elastic model's
    convention, and ``Result.deformation(i)`` the drift.

    Args:
        scene: the elastic scene.
        baumgarte: ``(Kp [1/s²], Kd [1/s])``, the drift correction of every grasp; default a
            critically damped ω = 50 rad/s.

    Raises:
        SceneError: an interconnection element without a rigid counterpart, or bad gains.
    """
    if not isinstance(scene, Scene):
        raise SceneError(f"rigid_limit takes a coopdyn.Scene, got {type(scene).__name__}")
    gains = _validate.finite_array(baumgarte, "baumgarte (Kp [1/s²], Kd [1/s])", (2,))
    if gains.min() < 0.0:
        raise SceneError(f"baumgarte gains must be >= 0, got Kp = {gains[0]:g} 1/s², Kd = {gains[1]:g} 1/s")
    if scene.object.condensed(scene) is not None:  # an elastic object: rigid too
        scene = quasi_static(scene)
    model = scene.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, scene.q0)
    specs, dropped = [], []
    for ic, lk in zip(scene.interconnection_specs, scene.links, strict=True):
        rigid = lk.element.rigid
        if rigid is None:
            known = sorted(kind for kind, t in ELEMENTS.items() if t.python.rigid is not None)
            raise SceneError(
                f"interconnection {lk.name!r} has element {lk.element.kind!r}, which has no rigid counterpart (known: {known})"
            )
        fixture = None if ic.arm is not None else model.frames[lk.tip_frame].placement
        oMT, oMG = data.oMf[lk.tip_frame], data.oMf[lk.grasp_frame]
        preload = np.linalg.norm(pin.log6(oMT.actInv(oMG)).vector)
        if preload > 1e-9:
            dropped.append(f"{lk.name} ({preload:.3g})")
        grasp = data.oMf[scene.object_frame].actInv(oMT)  # Scene reads a grasp in the object frame (a beam's reference node)
        specs.append(
            dataclasses.replace(
                ic,
                element=rigid,
                parameters=None,  # the spring's own; the rigid element has Baumgarte's gains only
                stiffness=float(gains[0]),
                damping=float(gains[1]),
                grasp=grasp,
                fixture=fixture,
                name=lk.name,
            )
        )
    if dropped:
        warnings.warn(
            "rigid_limit: these interconnections start deformed (|log6| in m and rad, a grasp error or preload): "
            f"{', '.join(dropped)}. Their rigid grasps close on the start pose; a rigid model carries no preload",
            stacklevel=2,
        )
    return Scene(list(scene.arm_specs), scene.object, specs, gravity=scene.gravity)


__all__ = ["quasi_static", "rigid_limit"]


def quasi_static(scene: Scene) -> Scene:
    """The scene with its elastic object condensed: the book's quasi-static elastic system.

    The object's own elasticity is condensed into the interconnections that hold it
    (:meth:`~coopdyn.model.objects.SceneObject.condensed`): a :class:`~coopdyn.model.beam.Beam`'s
    nodes other than the reference one are taken as massless and eliminated by static
    condensation, the whole beam becomes one rigid body (its mass and inertia, on the reference
    node's frame), and each grasp's SE(3) spring is replaced by the series stiffness of that
    spring and the beam between its node and the reference node, in the spring's own axes; the
    dampers are kept. A scene with a rigid object is returned unchanged (its interconnections
    are already massless).

    Raises:
        SceneError: two grasps on the same side of the reference node (their condensed
            stiffnesses couple, which pairwise springs cannot represent), or an interconnection
            that is not an SE(3) spring.
    """
    if not isinstance(scene, Scene):
        raise SceneError(f"quasi_static takes a coopdyn.Scene, got {type(scene).__name__}")
    condensed = scene.object.condensed(scene)
    if condensed is None:
        return scene
    body, specs = condensed
    return Scene(list(scene.arm_specs), body, specs, gravity=scene.gravity)
