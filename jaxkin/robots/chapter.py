"""The robots of the differential-kinematics chapter (after Spong, Hutchinson & Vidyasagar 2006).

The textbook gives these robots' dimensions as symbols; here they are keyword parameters (metres)
with illustrative defaults. Joint variables: radians for revolute, metres for prismatic joints.
The prismatic travel limits are illustrative (the chapter gives none).
"""

from __future__ import annotations

import math

from ..model import Robot
from . import register

_HALF_PI = math.pi / 2


@register(
    "two_link_planar",
    "Two-link planar RR arm (practice question 1): x = a1 c1 + a2 c12, y = a1 s1 + a2 s12.",
    "Spong 2006, Example 3.1; the chapter's practice question 1.",
)
def two_link_planar(a1: float = 1.0, a2: float = 1.0, dtype=None) -> Robot:
    rows = [
        dict(a=a1, alpha=0.0, d=0.0, theta=0.0, joint="revolute", lower=-math.pi, upper=math.pi),
        dict(a=a2, alpha=0.0, d=0.0, theta=0.0, joint="revolute", lower=-math.pi, upper=math.pi),
    ]
    robot = Robot.from_dh(rows, convention="standard", name="two_link_planar", dtype=dtype)
    return robot.with_configurations(
        zero=[0.0, 0.0],  # stretched along x: singular (elbow at 0)
        folded=[0.0, math.pi],  # singular
        elbow_up=[math.pi / 4, math.pi / 2],
    )


def _cylindrical_rows(d1: float) -> list[dict]:
    return [
        dict(a=0.0, alpha=0.0, d=d1, theta=0.0, joint="revolute", lower=-math.pi, upper=math.pi),
        dict(a=0.0, alpha=-_HALF_PI, d=0.0, theta=0.0, joint="prismatic", lower=0.0, upper=1.0),
        dict(a=0.0, alpha=0.0, d=0.0, theta=0.0, joint="prismatic", lower=0.0, upper=1.0),
    ]


@register(
    "cylindrical",
    "Three-link cylindrical RPP robot (Example 4.1.1): joints theta1, d2, d3; d1 is constant.",
    "Spong 2006, Example 3.2 (DH table 3.2); the chapter's Example 4.1.1.",
)
def cylindrical(d1: float = 0.5, dtype=None) -> Robot:
    robot = Robot.from_dh(_cylindrical_rows(d1), name="cylindrical", dtype=dtype)
    return robot.with_configurations(zero=[0.0, 0.0, 0.0], reference=[0.3, 0.4, 0.5])


@register(
    "cylindrical_spherical_wrist",
    "Cylindrical RPP arm with a spherical RRR wrist (practice question 2), 6 joints.",
    "Spong 2006, Example 3.5 (Figure 3.9, DH tables 3.2 and 3.3); practice question 2.",
)
def cylindrical_spherical_wrist(d1: float = 0.5, d6: float = 0.1, dtype=None) -> Robot:
    wrist = [
        dict(
            a=0.0,
            alpha=-_HALF_PI,
            d=0.0,
            theta=0.0,
            joint="revolute",
            lower=-math.pi,
            upper=math.pi,
        ),
        dict(
            a=0.0, alpha=_HALF_PI, d=0.0, theta=0.0, joint="revolute", lower=-math.pi, upper=math.pi
        ),
        dict(a=0.0, alpha=0.0, d=d6, theta=0.0, joint="revolute", lower=-math.pi, upper=math.pi),
    ]
    robot = Robot.from_dh(
        _cylindrical_rows(d1) + wrist, name="cylindrical_spherical_wrist", dtype=dtype
    )
    return robot.with_configurations(
        zero=[0.0] * 6,  # wrist singular (theta5 = 0)
        reference=[0.3, 0.4, 0.5, 0.2, 0.7, -0.4],
    )


@register(
    "rp_arm",
    "Revolute-prismatic arm of practice question 4, as far as the chapter defines it: joint 1 "
    "revolutes about the world z axis at the world origin, joint 2 is prismatic (here "
    "perpendicular to z1 via alpha1 = +90 deg, a polar arm).",
    "The chapter's practice question 4 (its figure, from chapter 2 example 6, is not in the "
    "chapter text: the perpendicular prismatic axis is this model's assumption).",
)
def rp_arm(d1: float = 0.0, dtype=None) -> Robot:
    rows = [
        dict(
            a=0.0, alpha=_HALF_PI, d=d1, theta=0.0, joint="revolute", lower=-math.pi, upper=math.pi
        ),
        dict(a=0.0, alpha=0.0, d=0.0, theta=0.0, joint="prismatic", lower=0.0, upper=1.0),
    ]
    robot = Robot.from_dh(rows, name="rp_arm", dtype=dtype)
    return robot.with_configurations(zero=[0.0, 0.0], reference=[0.5, 0.4])
