"""Industrial arms from their published Denavit-Hartenberg tables.

Units: metres for lengths and prismatic joint values, radians for angles. Every entry states the
DH convention it uses (standard, Spong: ``A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)``, or
modified, Craig: ``A_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)``), where each number comes
from, its joint limits and its named configurations (``robot.configurations``).

Every entry has the configuration ``"zero"`` (all joint variables 0: the DH table's reference
pose). For two robots it lies outside the mechanical travel and is kept only as that reference:
the Panda's joint 4 (travel -3.0718 .. -0.0698 rad) and the Stanford arm's prismatic joint 3
(travel 0.3048 .. 1.27 m). Every other named configuration lies within the joint limits.

The numbers are typed from the cited sources; the test suite checks them at run time against the
independent models of the Robotics Toolbox for Python (``roboticstoolbox.models.DH``), where the
two differ in two documented places (UR5 ``d1``; the Panda hand's TCP offset, see those entries).
"""

from __future__ import annotations

import math

import numpy as np

from ..model import Robot
from . import register

PI = math.pi
HALF_PI = math.pi / 2
DEG = math.pi / 180  # radians per degree
INCH = 0.0254  # metres per inch


def _revolute(a: float, alpha: float, d: float, lower: float, upper: float, theta: float = 0.0):
    return dict(a=a, alpha=alpha, d=d, theta=theta, joint="revolute", lower=lower, upper=upper)


def _prismatic(a: float, alpha: float, theta: float, lower: float, upper: float, d: float = 0.0):
    return dict(a=a, alpha=alpha, d=d, theta=theta, joint="prismatic", lower=lower, upper=upper)


# ---------------------------------------------------------------------------------------------
@register(
    "scara",
    "Adept (Omron) Cobra 600 SCARA, RRPR: shoulder, elbow, vertical quill, tool roll; standard DH.",
    "Link lengths 325 + 275 mm (the 600 mm reach the model is named for), shoulder height "
    "387 mm, quill stroke 210 mm and limits as in P. Corke, Robotics Toolbox for Python, "
    "roboticstoolbox.models.DH.Cobra600 (Omron/Adept Cobra 600); the structure is Spong, "
    "Hutchinson & Vidyasagar 2006, Section 3.3, Table 3.5 (SCARA manipulator).",
)
def scara(dtype=None) -> Robot:
    """Adept Cobra 600 SCARA (4 DOF: R R P R), standard DH.

    DH table (standard convention; joint variable added to theta for R, to d for P):

    ====  =========  ========  =========  ==================  =========================
    i     a_i [m]    alpha_i   d_i [m]    theta_i             limits
    ====  =========  ========  =========  ==================  =========================
    1     0.325      0         0.387      q1                  +-50 deg
    2     0.275      pi        0          q2                  +-88 deg
    3     0          0         q3         0                   0 .. 0.210 m (quill)
    4     0          0         0          q4                  unlimited
    ====  =========  ========  =========  ==================  =========================

    Source: the Cobra 600 model of P. Corke's Robotics Toolbox for Python
    (``roboticstoolbox.models.DH.Cobra600``): a1 = 0.325 m, a2 = 0.275 m (a1 + a2 = 600 mm
    reach), d1 = 0.387 m, alpha2 = pi (the quill points down), quill stroke 0 .. 0.210 m, joint
    limits +-50 deg and +-88 deg; joint 4 has no limit there, nor here. The kinematic structure
    (RRPR, alpha2 = pi) is Spong, Hutchinson & Vidyasagar, *Robot Modeling and Control* (2006),
    Section 3.3, Table 3.5, which gives the lengths as symbols (and a tool offset d4, 0 here).
    These limits are the toolbox's; the manufacturer's datasheet was not used.

    Named configurations:

    * ``"zero"``, ``"qz"``: all zero; the arm stretched out along x (elbow singular).
    * ``"elbow_bent"``: (0, pi/3, 0.1, 0), elbow at 60 deg, quill 0.1 m down: non-singular.
    """
    rows = [
        _revolute(a=0.325, alpha=0.0, d=0.387, lower=-50 * DEG, upper=50 * DEG),
        _revolute(a=0.275, alpha=PI, d=0.0, lower=-88 * DEG, upper=88 * DEG),
        _prismatic(a=0.0, alpha=0.0, theta=0.0, lower=0.0, upper=0.210),
        _revolute(a=0.0, alpha=0.0, d=0.0, lower=-math.inf, upper=math.inf),
    ]
    robot = Robot.from_dh(rows, convention="standard", name="scara", dtype=dtype)
    return robot.with_configurations(
        zero=[0.0] * 4,
        qz=[0.0] * 4,
        elbow_bent=[0.0, PI / 3, 0.1, 0.0],
    )


# ---------------------------------------------------------------------------------------------
@register(
    "stanford",
    "Stanford arm (Scheinman), RRPRRR with a spherical wrist; standard DH.",
    "d1 = 0.412 m, d2 = 0.154 m, theta3, a3, the 12..50 inch boom travel and the joint limits as "
    "in P. Corke, Robotics Toolbox for Python, roboticstoolbox.models.DH.Stanford (which cites "
    "Stanford AIM-177, Fig. 2.3, for the kinematics); structure as Spong, Hutchinson "
    "& Vidyasagar 2006, Section 3.3, Table 3.4 (Stanford manipulator).",
)
def stanford(dtype=None) -> Robot:
    """Stanford arm (6 DOF: R R P R R R), standard DH.

    DH table (standard convention; joint variable added to theta for R, to d for P):

    ====  =========  ========  =========  ==================  =========================
    i     a_i [m]    alpha_i   d_i [m]    theta_i             limits
    ====  =========  ========  =========  ==================  =========================
    1     0          -pi/2     0.412      q1                  +-170 deg
    2     0          pi/2      0.154      q2                  +-170 deg
    3     0.0203     0         q3         -pi/2               12 .. 50 in (boom travel)
    4     0          -pi/2     0          q4                  +-170 deg
    5     0          pi/2      0          q5                  +-90 deg
    6     0          0         0          q6                  +-170 deg
    ====  =========  ========  =========  ==================  =========================

    Source: the numbers of P. Corke's Robotics Toolbox (``roboticstoolbox.models.DH.Stanford``,
    whose kinematic data are credited to "Modelling, trajectory calculation and servoing of a
    computer controlled arm", Stanford AIM-177, Fig. 2.3; its dynamic data, not used here, to
    R. P. Paul, *Robot Manipulators* (1981), Tables 6.5-6.6). The link structure is that of
    Spong, Hutchinson & Vidyasagar (2006), Section 3.3, Table 3.4 (which has theta3 = 0 and
    a3 = 0 with symbolic lengths; the toolbox's theta3 = -pi/2 and a3 = 0.0203 m are kept so that
    the two models coincide). The tool frame is the wrist centre (d6 = 0).

    Named configurations:

    * ``"zero"``: all zero, the DH reference pose; q3 = 0 is *outside* the boom's travel.
    * ``"retracted"``: revolute joints 0, boom at its 12 in (0.3048 m) lower stop.
    * ``"extended"``: revolute joints 0, boom at its 50 in (1.27 m) upper stop.
    """
    rows = [
        _revolute(a=0.0, alpha=-HALF_PI, d=0.412, lower=-170 * DEG, upper=170 * DEG),
        _revolute(a=0.0, alpha=HALF_PI, d=0.154, lower=-170 * DEG, upper=170 * DEG),
        _prismatic(a=0.0203, alpha=0.0, theta=-HALF_PI, lower=12 * INCH, upper=50 * INCH),
        _revolute(a=0.0, alpha=-HALF_PI, d=0.0, lower=-170 * DEG, upper=170 * DEG),
        _revolute(a=0.0, alpha=HALF_PI, d=0.0, lower=-90 * DEG, upper=90 * DEG),
        _revolute(a=0.0, alpha=0.0, d=0.0, lower=-170 * DEG, upper=170 * DEG),
    ]
    robot = Robot.from_dh(rows, convention="standard", name="stanford", dtype=dtype)
    return robot.with_configurations(
        zero=[0.0] * 6,
        retracted=[0.0, 0.0, 12 * INCH, 0.0, 0.0, 0.0],
        extended=[0.0, 0.0, 50 * INCH, 0.0, 0.0, 0.0],
    )


# ---------------------------------------------------------------------------------------------
@register(
    "puma560",
    "Unimation PUMA 560, 6R with a spherical wrist; standard DH (Paul's twist signs), shoulder "
    "height above the mounting surface included.",
    "Corke & Armstrong-Helouvry, 'A search for consensus among model parameters reported for "
    "the PUMA 560 robot', IEEE ICRA 1994, pp. 1608-1613 (a2, a3, d3, d4); pedestal height "
    "26.45 in and limits (Wang & Chen, IEEE Trans. RA 7(4), 1991) as in P. Corke, Robotics "
    "Toolbox for Python, roboticstoolbox.models.DH.Puma560.",
)
def puma560(dtype=None) -> Robot:
    """Unimation PUMA 560 (6 DOF, 6R), standard DH.

    DH table (standard convention, theta_i = q_i):

    ====  =========  ========  ==================  ================
    i     a_i [m]    alpha_i   d_i [m]             limits [deg]
    ====  =========  ========  ==================  ================
    1     0          pi/2      26.45 in = 0.67183  -160 .. 160
    2     0.4318     0         0                   -45 .. 225
    3     0.0203     -pi/2     0.15005             -225 .. 45
    4     0          pi/2      0.4318              -110 .. 170
    5     0          -pi/2     0                   -100 .. 100
    6     0          0         0                   -266 .. 266
    ====  =========  ========  ==================  ================

    Sources: a2, a3, d3 (150.05 mm, Corke's 1995 revision closer to Lee and Tarn) and d4 from
    P. Corke and B. Armstrong-Helouvry, "A search for consensus among model parameters reported
    for the PUMA 560 robot", Proc. IEEE ICRA 1994, pp. 1608-1613; the twist signs are Paul's (the
    zero pose is "righty"). d1 = 26.45 in is the height of the shoulder axis above the mounting
    surface (the pedestal), as in the Robotics Toolbox for Python's ``Puma560`` (the MATLAB
    toolbox used d1 = 0). Joint limits: Wang & Chen, "A combined optimization method for solving
    the inverse kinematics problem", IEEE Trans. Robotics and Automation 7(4), 1991, as collected
    in that toolbox model. The tool frame is the wrist centre (d6 = 0).

    Named configurations (the toolbox's):

    * ``"zero"``, ``"qz"``: all zero, the "L" shaped pose (arm horizontal, forearm up).
    * ``"qr"``: (0, pi/2, -pi/2, 0, 0, 0), the vertical "READY" pose.
    * ``"qs"``: (0, 0, -pi/2, 0, 0, 0), arm stretched out horizontally along x.
    * ``"qn"``: (0, pi/4, -pi, 0, pi/4, 0), a nominal non-singular table-top picking pose.
    """
    rows = [
        _revolute(a=0.0, alpha=HALF_PI, d=26.45 * INCH, lower=-160 * DEG, upper=160 * DEG),
        _revolute(a=0.4318, alpha=0.0, d=0.0, lower=-45 * DEG, upper=225 * DEG),
        _revolute(a=0.0203, alpha=-HALF_PI, d=0.15005, lower=-225 * DEG, upper=45 * DEG),
        _revolute(a=0.0, alpha=HALF_PI, d=0.4318, lower=-110 * DEG, upper=170 * DEG),
        _revolute(a=0.0, alpha=-HALF_PI, d=0.0, lower=-100 * DEG, upper=100 * DEG),
        _revolute(a=0.0, alpha=0.0, d=0.0, lower=-266 * DEG, upper=266 * DEG),
    ]
    robot = Robot.from_dh(rows, convention="standard", name="puma560", dtype=dtype)
    return robot.with_configurations(
        zero=[0.0] * 6,
        qz=[0.0] * 6,
        qr=[0.0, HALF_PI, -HALF_PI, 0.0, 0.0, 0.0],
        qs=[0.0, 0.0, -HALF_PI, 0.0, 0.0, 0.0],
        qn=[0.0, PI / 4, -PI, 0.0, PI / 4, 0.0],
    )


# ---------------------------------------------------------------------------------------------
@register(
    "ur5",
    "Universal Robots UR5 (CB3), 6R; standard DH as published by Universal Robots.",
    "Universal Robots, 'DH parameters for calculations of kinematics and dynamics' "
    "(universal-robots.com support article; same as the CB3 manual's UR5 'serie 3' table): "
    "d1 = 0.089159, a2 = -0.425, a3 = -0.39225, d4 = 0.10915, d5 = 0.09465, d6 = 0.0823 m; "
    "joint range +-360 deg (UR5 user manual, technical specifications).",
)
def ur5(dtype=None) -> Robot:
    """Universal Robots UR5 (CB3 series, 6 DOF, 6R), standard DH.

    DH table (standard convention, theta_i = q_i), all joints limited to +-2 pi (+-360 deg):

    ====  ==========  ========  =========
    i     a_i [m]     alpha_i   d_i [m]
    ====  ==========  ========  =========
    1     0           pi/2      0.089159
    2     -0.42500    0         0
    3     -0.39225    0         0
    4     0           pi/2      0.10915
    5     0           -pi/2     0.09465
    6     0           0         0.0823
    ====  ==========  ========  =========

    Source: Universal Robots' support article "DH parameters for calculations of kinematics and
    dynamics" (UR5 table), identical to the UR5 "serie 3" table of the CB3 manual. The tool frame
    is the tool flange. The Robotics Toolbox for Python's ``UR5`` has d1 = 0.089459 m, 0.3 mm off
    the published 0.089159 m; this model follows Universal Robots.

    Named configurations:

    * ``"zero"``, ``"qz"``: all zero: arm stretched out horizontally along -x (singular).
    * ``"home"``: (0, -pi/2, 0, -pi/2, 0, 0), PolyScope's default home: upper arm and forearm
      pointing straight up.
    * ``"qr"``: (pi, 0, 0, 0, pi/2, 0), the Robotics Toolbox's "arm horizontal along x".
    """
    lim = 2 * PI
    rows = [
        _revolute(a=0.0, alpha=HALF_PI, d=0.089159, lower=-lim, upper=lim),
        _revolute(a=-0.42500, alpha=0.0, d=0.0, lower=-lim, upper=lim),
        _revolute(a=-0.39225, alpha=0.0, d=0.0, lower=-lim, upper=lim),
        _revolute(a=0.0, alpha=HALF_PI, d=0.10915, lower=-lim, upper=lim),
        _revolute(a=0.0, alpha=-HALF_PI, d=0.09465, lower=-lim, upper=lim),
        _revolute(a=0.0, alpha=0.0, d=0.0823, lower=-lim, upper=lim),
    ]
    robot = Robot.from_dh(rows, convention="standard", name="ur5", dtype=dtype)
    return robot.with_configurations(
        zero=[0.0] * 6,
        qz=[0.0] * 6,
        home=[0.0, -HALF_PI, 0.0, -HALF_PI, 0.0, 0.0],
        qr=[PI, 0.0, 0.0, 0.0, HALF_PI, 0.0],
    )


# ---------------------------------------------------------------------------------------------
PANDA_FLANGE_D = 0.107  # m, Franka's "Flange" row: Tz(0.107) after joint 7
PANDA_TCP_D = 0.1034  # m, Franka Hand TCP along the flange z axis
PANDA_HAND_YAW = -PI / 4  # rad, Franka Hand mounted rotated -45 deg about the flange z axis


def _panda_tool() -> np.ndarray:
    c, s = math.cos(PANDA_HAND_YAW), math.sin(PANDA_HAND_YAW)
    return np.array(
        [
            [c, -s, 0.0, 0.0],
            [s, c, 0.0, 0.0],
            [0.0, 0.0, 1.0, PANDA_TCP_D],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


@register(
    "panda",
    "Franka Emika Panda, 7R; modified (Craig) DH as documented by Franka, flange folded into "
    "joint 7, Franka Hand TCP as the tool.",
    "Franka Emika, FCI documentation, 'Robot and interface specifications' / 'Control "
    "parameters' (frankaemika.github.io/docs/control_parameters.html): Denavit-Hartenberg "
    "table, flange d = 0.107 m and joint limits; Franka Hand TCP Tz(0.1034 m) Rz(-45 deg) from "
    "franka_description (panda_hand_joint, panda_hand_tcp_joint) and libfranka's default F_T_EE.",
)
def panda(dtype=None) -> Robot:
    """Franka Emika Panda (7 DOF, 7R), modified (Craig) DH, with the Franka Hand TCP as tool.

    DH table (modified convention, theta_i = q_i; a and alpha are those of the previous link):

    ====  ==========  ========  =========  =========================
    i     a_{i-1}     alpha     d_i [m]    limits [rad]
    ====  ==========  ========  =========  =========================
    1     0           0         0.333      -2.8973 .. 2.8973
    2     0           -pi/2     0          -1.7628 .. 1.7628
    3     0           pi/2      0.316      -2.8973 .. 2.8973
    4     0.0825      pi/2      0          -3.0718 .. -0.0698
    5     -0.0825     -pi/2     0.384      -2.8973 .. 2.8973
    6     0           pi/2      0          -0.0175 .. 3.7525
    7     0.088       pi/2      0.107      -2.8973 .. 2.8973
    ====  ==========  ========  =========  =========================

    Source: Franka Emika's FCI documentation ("Control parameters": Denavit-Hartenberg
    parameters and joint limits q_min/q_max). Franka lists the flange as an extra row
    (a = 0, d = 0.107 m, alpha = 0, theta = 0); since ``Tz(d)`` commutes with the joint-7 rotation
    it is folded into row 7 (d7 = 0.107 m), so the frame ``"link7"`` *is the flange*, as in the
    Robotics Toolbox's ``models.DH.Panda``.

    Tool (``T_flange_tool``, frame ``"tool"``, the default tip): the Franka Hand's TCP,
    ``Tz(0.1034) Rz(-pi/4)``: 0.1034 m along the flange z axis, rotated -45 deg about it
    (franka_description: ``panda_hand_joint`` rpy (0, 0, -pi/4), ``panda_hand_tcp_joint``
    xyz (0, 0, 0.1034); libfranka's default ``F_T_EE``). The Robotics Toolbox's ``Panda`` uses
    0.103 m instead of 0.1034 m for this offset.

    Named configurations:

    * ``"zero"``, ``"qz"``: all zero, the DH reference pose; q4 = 0 is *outside* joint 4's travel
      (-3.0718 .. -0.0698), so the real arm cannot reach it.
    * ``"qr"``: (0, -0.3, 0, -2.2, 0, 2.0, pi/4), the Robotics Toolbox's ready pose (hand down).
    """
    rows = [
        _revolute(a=0.0, alpha=0.0, d=0.333, lower=-2.8973, upper=2.8973),
        _revolute(a=0.0, alpha=-HALF_PI, d=0.0, lower=-1.7628, upper=1.7628),
        _revolute(a=0.0, alpha=HALF_PI, d=0.316, lower=-2.8973, upper=2.8973),
        _revolute(a=0.0825, alpha=HALF_PI, d=0.0, lower=-3.0718, upper=-0.0698),
        _revolute(a=-0.0825, alpha=-HALF_PI, d=0.384, lower=-2.8973, upper=2.8973),
        _revolute(a=0.0, alpha=HALF_PI, d=0.0, lower=-0.0175, upper=3.7525),
        _revolute(a=0.088, alpha=HALF_PI, d=PANDA_FLANGE_D, lower=-2.8973, upper=2.8973),
    ]
    robot = Robot.from_dh(
        rows, convention="modified", tool=_panda_tool(), name="panda", dtype=dtype
    )
    return robot.with_configurations(
        zero=[0.0] * 7,
        qz=[0.0] * 7,
        qr=[0.0, -0.3, 0.0, -2.2, 0.0, 2.0, PI / 4],
    )
