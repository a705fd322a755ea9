"""Niryo One, the 6-DOF desktop arm of the chapter's companion simulation.

Numbers: the manufacturer's robot description (niryo_one_description, "v2" URDF of
NiryoRobotics/niryo_one_ros), as collected in the project's shared/robots/niryo_one.md. Only the
numbers are used; the model is written here. Metres and radians; origin rpy is URDF fixed-axis
roll-pitch-yaw, R = Rz(yaw) Ry(pitch) Rx(roll); every joint axis is +z of its child frame. The
description writes pi as 3.14159265359, kept here so the model matches the file bit for bit.

Frames (fk_all order): ground_link (world), base_link, shoulder_link, arm_link, elbow_link,
forearm_link, wrist_link, hand_link, gripper_link (the tip). Velocity limit 1.0 rad/s per joint.
"""

from __future__ import annotations

from ..model import Robot
from . import register

PI = 3.14159265359  # as written in the manufacturer's description
VELOCITY_LIMIT = 1.0  # rad/s, every joint

_Z = (0.0, 0.0, 1.0)


@register(
    "niryo_one",
    "Niryo One 6-DOF desktop arm (the chapter's simulation robot), URDF-style placements.",
    "niryo_one_description v2 URDF (NiryoRobotics/niryo_one_ros), numbers via "
    "shared/robots/niryo_one.md.",
)
def niryo_one(dtype=None) -> Robot:
    joints = [
        dict(name="ground_joint", type="fixed", parent="ground_link", child="base_link"),
        dict(
            name="joint_1",
            type="revolute",
            child="shoulder_link",
            xyz=(0, 0, 0.103),
            axis=_Z,
            lower=-3.05433,
            upper=3.05433,
        ),
        dict(
            name="joint_2",
            type="revolute",
            child="arm_link",
            xyz=(0, 0, 0.08),
            rpy=(PI / 2, -PI / 2, 0),
            axis=_Z,
            lower=-PI / 2,
            upper=0.628319,
        ),
        dict(
            name="joint_3",
            type="revolute",
            child="elbow_link",
            xyz=(0.21004, 0, 0),
            rpy=(0, 0, -PI / 2),
            axis=_Z,
            lower=-1.401,
            upper=0.994838,
        ),
        dict(
            name="joint_4",
            type="revolute",
            child="forearm_link",
            xyz=(0.037, 0.032, 0),
            rpy=(0, PI / 2, 0),
            axis=_Z,
            lower=-2.61799,
            upper=2.61799,
        ),
        dict(
            name="joint_5",
            type="revolute",
            child="wrist_link",
            xyz=(0, 0, 0.180),
            rpy=(0, -PI / 2, 0),
            axis=_Z,
            lower=-2.26893,
            upper=2.26893,
        ),
        dict(
            name="joint_6",
            type="revolute",
            child="hand_link",
            xyz=(0.018, 0, 0),
            rpy=(0, PI / 2, 0),
            axis=_Z,
            lower=-2.57,
            upper=2.57,
        ),
        dict(
            name="hand_gripper_joint", type="fixed", child="gripper_link", rpy=(-PI / 2, -PI / 2, 0)
        ),
    ]
    robot = Robot.from_joints(joints, root="ground_link", name="niryo_one", dtype=dtype)
    return robot.with_configurations(zero=[0.0] * 6)
