"""Why the collision checker rejects a configuration: the cause an IK candidate is counted under.

``rejection_cause(checker, q_arm)`` gives "singularity" or "collision" for a configuration within the joint
limits that ``checker`` does not accept; ``errors.rejection`` counts the causes of a set of candidates into an
``UnreachableError``'s reason and one-line message (the api's ``Planner``, a plan's IK choice and ``kin ik``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    import numpy as np

    from roarmctl.motion.collision import CollisionChecker

Cause = Literal["singularity", "collision"]


def rejection_cause(checker: CollisionChecker, q_arm: np.ndarray) -> Cause:
    """The cause ``checker`` rejects ``q_arm`` ((arm_dof,) rad/m, within the joint limits, not valid) for:
    "singularity" when its margin measure (m/rad) is below the singularity margin, tested first as
    ``CollisionChecker.explain`` does, else "collision"."""
    m = checker.singularity_margin
    return "singularity" if m is not None and float(checker.margin_measure(q_arm)[0]) < m else "collision"
