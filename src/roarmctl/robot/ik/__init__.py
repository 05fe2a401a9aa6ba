"""Inverse kinematics: closed form for the RoArm-M3 and the UR10, damped least squares for the rest.

Entry point: ``solve_ik(robot, position, pitch=..., roll=..., rpy=..., q_ref=..., all_solutions=...)``.
It returns full configuration vectors (``robot.dof``, gripper included), every one within the
joint limits and checked by forward kinematics before it is returned; or it raises
``UnreachableError`` whose ``reason`` is ``"out_of_reach"``, ``"joint_limit"`` or ``"orientation"``.

Which solver runs:

* ``singularity_model == "roarm5"`` (the RoArm-M3 Pro): planar closed form about the base axis,
  target = TCP position + tool pitch (+ roll), or position + full orientation (``rpy``).
* ``singularity_model == "ur6"`` with ``rpy`` (or pitch and roll): the 8-solution analytic IK of the
  UR10 (modified DH); position only (or pitch alone) falls back to damped least squares.
* anything else: damped least squares with seeded random restarts, run as batches of starts
  (position only, position + approach axis for a tool pitch, or full pose).

Modules: ``solve`` (the entry points and the choice of family), ``roarm5`` (the RoArm-M3's closed form),
``line`` (the RoArm's straight-line batch, ``LineIK``), ``roarm3`` (the RoArm-M2-S's position-only closed
form), ``ur6`` (the UR10's analytic IK), ``dls`` (damped least squares), ``pitch`` (the tool pitch: its
measure, the order ``pitch: auto`` tries, which families take one), ``common`` (limit fitting, the Newton
polish, rotation helpers).

Closed forms are exact for the ideal geometry; a few Newton steps on the true FK then remove what the
description's rounding leaves (Waveshare's URDF writes pi/2 as 1.5708, which tilts axes by 3.7 urad
and moves the TCP by about 1 um), so every returned solution meets ``POS_TOL`` on the real model.
"""

from roarmctl.robot.ik.common import ORI_TOL, POS_TOL
from roarmctl.robot.ik.dls import pitch_aim
from roarmctl.robot.ik.line import LineIK
from roarmctl.robot.ik.pitch import PITCH_STEP, accepts_pitch, pitch_candidates, takes_pitch, tool_pitch
from roarmctl.robot.ik.solve import (
    IK_FAMILIES,
    IKCheck,
    check_solution,
    solve_ik,
    solve_ik_auto_pitch,
    solve_ik_frame,
    solve_ik_near,
)
from roarmctl.robot.ik.ur6 import ur6_params

__all__ = [
    "IK_FAMILIES",
    "ORI_TOL",
    "PITCH_STEP",
    "POS_TOL",
    "IKCheck",
    "LineIK",
    "accepts_pitch",
    "check_solution",
    "pitch_aim",
    "pitch_candidates",
    "solve_ik",
    "solve_ik_auto_pitch",
    "solve_ik_frame",
    "solve_ik_near",
    "takes_pitch",
    "tool_pitch",
    "ur6_params",
]
