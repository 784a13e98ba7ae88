"""Articulated people: head, hair, torso, arms, legs and shoes built from 3D primitives.

A `PersonSpec` holds everything random about a person (size, pose, clothes); `build_person` turns it
into primitives in the floor frame plus the exact floor point between the feet (`location_m`), the
ground truth the detector learns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from detector.data.primitives import (
    Material,
    Primitive,
    make_box,
    make_capsule,
    make_ellipsoid,
    yaw_frame,
)

FloatArray = NDArray[np.float64]

POSES = ("standing", "walking", "sitting")
CARRIED = ("none", "bag", "box", "backpack", "phone")
HAIR_STYLES = ("short", "long", "bald", "hat")
ARM_POSES = ("down", "crossed", "hips", "pockets", "pointing")

# Body part ids (Primitive.part), used for shading tweaks and in tests.
HEAD, HAIR, TORSO, ARM, HAND, LEG, SHOE, ITEM = range(1, 9)


@dataclass(frozen=True)
class PersonSpec:
    """A person: floor position of the pelvis `position_m` (2,), facing `heading_rad` (floor frame,
    counter-clockwise from +x), `height_m`, `width_scale` (~0.85-1.2), `pose` (POSES) with walking
    `phase_rad` and `stride_rad`, `lean_rad` forward, `seat_height_m` when sitting, `carried`
    (CARRIED), `hair_style`, the materials of skin, hair, top, bottom and shoes, and for standing
    people an `arm_pose` (ARM_POSES)."""

    position_m: tuple[float, float]
    heading_rad: float
    height_m: float
    width_scale: float
    pose: str
    phase_rad: float
    stride_rad: float
    lean_rad: float
    seat_height_m: float
    carried: str
    hair_style: str
    long_sleeves: bool
    long_legs: bool
    skin: Material
    hair: Material
    top: Material
    bottom: Material
    shoes: Material
    item: Material
    arm_pose: str = "down"


@dataclass
class Person:
    """The primitives of one person and its ground truth floor point `location_m` (2,)."""

    primitives: list[Primitive]
    location_m: FloatArray


def _limb(swing_rad: float, spread_rad: float, side: float) -> FloatArray:
    """Unit direction of a limb hanging down, swung forward by `swing_rad` and out by `spread_rad`
    (local frame: x forward, y left, z up; `side` +1 left, -1 right)."""
    return np.array([np.sin(swing_rad) * np.cos(spread_rad), side * np.sin(spread_rad),
                     -np.cos(swing_rad) * np.cos(spread_rad)])


def _rot_y(angle_rad: float) -> FloatArray:
    """Rotation about the local lateral axis that tips +z towards +x by `angle_rad`."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _sitting_hip_height(spec: PersonSpec) -> float:
    s = spec.height_m / 1.75
    return 0.08 * s + 0.42 * s * np.cos(0.15) + 0.02


def seat_height_for(spec: PersonSpec) -> float:
    """Height (m) of a seat that a sitting person of this spec sits on."""
    return _sitting_hip_height(spec) - 0.08 * spec.height_m / 1.75


def build_person(spec: PersonSpec) -> Person:
    """The primitives of a person in the floor frame (see PersonSpec)."""
    s = spec.height_m / 1.75
    w = spec.width_scale
    local: list[tuple[str, tuple[FloatArray, ...], float, Material, int]] = []
    # ----- legs (local frame, hip centre at the origin of the leg chain)
    if spec.pose == "walking":
        swing = spec.stride_rad * np.sin(spec.phase_rad)
        thighs = (swing, -swing)
        knees = (0.5 * spec.stride_rad * max(0.0, np.cos(spec.phase_rad)),
                 0.5 * spec.stride_rad * max(0.0, -np.cos(spec.phase_rad)))
        hip_z = 0.93 * s
    elif spec.pose == "sitting":
        thighs = (1.45, 1.5)
        knees = (1.45 - 0.15, 1.5 - 0.1)
        hip_z = _sitting_hip_height(spec)
    else:
        thighs = (0.03, -0.02)
        knees = (0.0, 0.02)
        hip_z = 0.93 * s
    shin_mat = spec.bottom if spec.long_legs else spec.skin
    joints = []
    for side, thigh, knee in zip((1.0, -1.0), thighs, knees, strict=True):
        hip = np.array([0.0, side * 0.09 * w * s, hip_z])
        knee_p = hip + 0.43 * s * _limb(thigh, 0.04, side)
        ankle = knee_p + 0.42 * s * _limb(thigh - knee, 0.02, side)
        joints.append((hip, knee_p, ankle))
    # Lift or lower the body so that the lowest ankle sits at ankle height.
    lift = np.array([0.0, 0.0, 0.08 * s - min(j[2][2] for j in joints)])
    ankles = []
    for hip, knee_p, ankle in joints:
        local.append(("capsule", (hip + lift, knee_p + lift), 0.075 * s * w, spec.bottom, LEG))
        local.append(("capsule", (knee_p + lift, ankle + lift), 0.055 * s, shin_mat, LEG))
        local.append(("shoe", (ankle + lift + np.array([0.05, 0.0, -0.04]) * s,), 0.0, spec.shoes, SHOE))
        ankles.append(ankle + lift)
    hip_z += float(lift[2])
    # ----- upper body, built upright about the hip centre, then leaned forward
    upper: list[tuple[str, tuple[FloatArray, ...], float, Material, int]] = []
    pelvis = np.array([0.0, 0.0, 0.03 * s])
    chest = np.array([0.0, 0.0, 0.33 * s])
    shoulder_z = 0.49 * s
    upper.append(("ellipsoid", (pelvis, np.array([0.11 * s, 0.17 * s * w, 0.12 * s])), 0.0,
                  spec.bottom, TORSO))
    upper.append(("ellipsoid", (chest, np.array([0.12 * s, 0.19 * s * w, 0.22 * s])), 0.0, spec.top,
                  TORSO))
    upper.append(("capsule", (np.array([0.0, -0.16 * s * w, shoulder_z]),
                              np.array([0.0, 0.16 * s * w, shoulder_z])), 0.065 * s, spec.top, TORSO))
    upper.append(("capsule", (np.array([0.0, 0.0, shoulder_z]), np.array([0.01, 0.0, 0.6 * s])),
                  0.05 * s, spec.skin, HEAD))
    head = np.array([0.02 * s, 0.0, 0.70 * s])
    upper.append(("ellipsoid", (head, np.array([0.10, 0.08, 0.115]) * s), 0.0, spec.skin, HEAD))
    if spec.hair_style != "bald":
        hair_mat = spec.item if spec.hair_style == "hat" else spec.hair
        hair_c = head + np.array([-0.015, 0.0, 0.03]) * s
        upper.append(("ellipsoid", (hair_c, np.array([0.104, 0.086, 0.1]) * s), 0.0, hair_mat, HAIR))
        if spec.hair_style == "long":
            upper.append(("capsule", (head + np.array([-0.06, 0, 0.0]) * s,
                                      head + np.array([-0.08, 0, -0.2]) * s), 0.07 * s, spec.hair, HAIR))
    # arms
    swing = spec.stride_rad * np.sin(spec.phase_rad) if spec.pose == "walking" else 0.0
    # (upper arm swing, spread, elbow bend, forearm spread) per arm
    arm_poses = {"left": (-0.7 * swing, 0.12, 0.25, 0.06), "right": (0.7 * swing, 0.12, 0.25, 0.06)}
    if spec.pose == "standing":
        arm_poses = {
            "down": arm_poses,
            "crossed": {"left": (0.2, 0.05, 1.35, -1.0), "right": (0.25, 0.05, 1.3, -0.95)},
            "hips": {"left": (-0.1, 0.55, 1.3, -1.1), "right": (-0.1, 0.55, 1.3, -1.1)},
            "pockets": {"left": (-0.08, 0.2, 0.25, 0.0), "right": (-0.08, 0.2, 0.25, 0.0)},
            "pointing": {"left": arm_poses["left"], "right": (1.1, 0.2, 0.2, 0.1)},
        }[spec.arm_pose]
    if spec.pose == "sitting":
        arm_poses = {"left": (0.35, 0.1, 1.1, 0.05), "right": (0.3, 0.1, 1.2, 0.05)}
    item_at: FloatArray | None = None
    if spec.carried == "box":
        arm_poses = {"left": (0.35, 0.05, 1.2, 0.0), "right": (0.35, 0.05, 1.2, 0.0)}
    elif spec.carried == "phone":
        arm_poses["right"] = (0.3, 0.05, 1.9, -0.2)
    elif spec.carried == "bag":
        arm_poses["right"] = (0.0, 0.15, 0.05, 0.08)
    sleeve = spec.top if spec.long_sleeves else spec.skin
    for name, side in (("left", 1.0), ("right", -1.0)):
        upper_swing, spread, bend, fore_spread = arm_poses[name]
        shoulder = np.array([0.0, side * 0.2 * s * w, shoulder_z - 0.02 * s])
        elbow = shoulder + 0.30 * s * _limb(upper_swing, spread, side)
        wrist = elbow + 0.27 * s * _limb(upper_swing + bend, fore_spread, side)
        upper.append(("capsule", (shoulder, elbow), 0.047 * s, spec.top, ARM))
        upper.append(("capsule", (elbow, wrist), 0.038 * s, sleeve, ARM))
        upper.append(("ellipsoid", (wrist + 0.04 * s * _limb(upper_swing + bend, 0.0, side),
                                    np.array([0.045, 0.03, 0.045]) * s), 0.0, spec.skin, HAND))
        if name == "right" and spec.carried == "bag":
            item_at = wrist + np.array([0.0, 0.0, -0.17 * s])
            upper.append(("box", (item_at, np.array([0.15, 0.05, 0.15]) * s), 0.0, spec.item, ITEM))
        if name == "right" and spec.carried == "phone":
            upper.append(("box", (wrist + 0.06 * s * _limb(upper_swing + bend, 0.0, side),
                                  np.array([0.04, 0.02, 0.075]) * s), 0.0, spec.item, ITEM))
    if spec.carried == "box":
        upper.append(("box", (np.array([0.33 * s, 0.0, 0.22 * s]), np.array([0.15, 0.2, 0.14]) * s),
                      0.0, spec.item, ITEM))
    elif spec.carried == "backpack":
        upper.append(("box", (np.array([-0.2 * s, 0.0, 0.35 * s]), np.array([0.08, 0.15, 0.2]) * s),
                      0.0, spec.item, ITEM))
    lean = _rot_y(spec.lean_rad)
    hip_centre = np.array([0.0, 0.0, hip_z])
    for kind, pts, r, mat, part in upper:
        if kind == "capsule":
            pts = tuple(hip_centre + lean @ p for p in pts)
        else:
            pts = (hip_centre + lean @ pts[0], pts[1])
        local.append((kind, pts, r, mat, part))
    # ----- to the floor frame
    frame = yaw_frame(spec.heading_rad)
    origin = np.array([spec.position_m[0], spec.position_m[1], 0.0])
    prims: list[Primitive] = []
    for kind, pts, r, mat, part in local:
        if kind == "capsule":
            prims.append(make_capsule(origin + frame @ pts[0], origin + frame @ pts[1], r, mat, part))
        elif kind == "ellipsoid":
            prims.append(make_ellipsoid(origin + frame @ pts[0], pts[1], frame, mat, part))
        elif kind == "shoe":
            prims.append(make_ellipsoid(origin + frame @ pts[0], np.array([0.13, 0.05, 0.045]) * s,
                                        frame, mat, part))
        else:
            prims.append(make_box(origin + frame @ pts[0], pts[1], spec.heading_rad, mat, part))
    feet = np.array([origin + frame @ a for a in ankles])
    return Person(prims, feet[:, :2].mean(axis=0))
