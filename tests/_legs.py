"""A small free-floating legged robot shared by the whole-body tests: a free root, two ball hips,
two bounded knees and two fixed feet, with masses (so centre-of-mass targets work)."""

import numpy as np

import jaxkin as jk

LEGS = jk.Robot.from_joints(
    [
        dict(name="root", type="free", child="pelvis", inertial=dict(mass=10.0, xyz=[0, 0, 0.1])),
        dict(
            name="l_hip",
            type="ball",
            parent="pelvis",
            child="l_thigh",
            xyz=[0, 0.1, 0],
            inertial=dict(mass=3.0, xyz=[0, 0, -0.2]),
        ),
        dict(
            name="l_knee",
            type="revolute",
            child="l_shin",
            xyz=[0, 0, -0.4],
            axis=[0, 1, 0],
            lower=0.0,
            upper=2.5,
            inertial=dict(mass=2.0, xyz=[0, 0, -0.2]),
        ),
        dict(name="l_foot", type="fixed", child="l_foot", xyz=[0.05, 0, -0.4]),
        dict(
            name="r_hip",
            type="ball",
            parent="pelvis",
            child="r_thigh",
            xyz=[0, -0.1, 0],
            inertial=dict(mass=3.0, xyz=[0, 0, -0.2]),
        ),
        dict(
            name="r_knee",
            type="revolute",
            child="r_shin",
            xyz=[0, 0, -0.4],
            axis=[0, 1, 0],
            lower=0.0,
            upper=2.5,
            inertial=dict(mass=2.0, xyz=[0, 0, -0.2]),
        ),
        dict(name="r_foot", type="fixed", child="r_foot", xyz=[0.05, 0, -0.4]),
    ],
    name="legs",
    dtype=np.float64,
)
FEET = ["l_foot", "r_foot"]
