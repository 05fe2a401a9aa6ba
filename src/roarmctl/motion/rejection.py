"""Why the collision checker rejects a configuration: the one verdict (``judge``: valid, or why not and the cause) that
the api's ``Planner.is_valid`` and ``ik``, a plan's IK choice and ``kin ik``'s pitch choice all take.

``rejection_cause(checker, q_arm)`` gives "singularity" or "collision" for a configuration within the joint
limits that ``checker`` does not accept; ``errors.rejection`` counts the causes of a set of candidates into an
``UnreachableError``'s reason and one-line message (the api's ``Planner``, a plan's IK choice and ``kin ik``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    import numpy as np

    from roarmctl.motion.collision import CollisionChecker

Cause = Literal["singularity", "collision"]
RejectionKind = Literal["", "joint_limit", "collision", "singularity"]


@dataclass(frozen=True)
class Validity:
    """A configuration's verdict: ``valid``, and ``reason`` when not ("joint 2 outside its limits", "forearm hits
    obstacle 'wall'", ...), ``kind`` its cause ("joint_limit", "collision" or "singularity"; "" when valid). True
    in an ``if``."""

    valid: bool
    reason: str = ""
    kind: RejectionKind = ""

    def __bool__(self) -> bool:
        return self.valid


def rejection_cause(checker: CollisionChecker, q_arm: np.ndarray) -> Cause:
    """The cause ``checker`` rejects ``q_arm`` ((arm_dof,) rad/m, within the joint limits, not valid) for:
    "singularity" when its margin measure (m/rad) is below the singularity margin, tested first as
    ``CollisionChecker.explain`` does, else "collision"."""
    m = checker.singularity_margin
    return "singularity" if m is not None and float(checker.margin_measure(q_arm)[0]) < m else "collision"


def judge(checker: CollisionChecker, q_arm: np.ndarray) -> Validity:
    """``checker``'s verdict on ``q_arm`` ((arm_dof,) rad/m, within the joint limits): valid, or its reason
    (``CollisionChecker.explain``) and cause (``rejection_cause``)."""
    if checker.is_valid(q_arm):
        return Validity(True)
    return Validity(False, checker.explain(q_arm), rejection_cause(checker, q_arm))
