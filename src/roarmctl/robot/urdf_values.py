"""The numbers of a URDF's attributes (``xyz``, ``rpy``, ``effort``, ...), read with messages that name the field."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from roarmctl.errors import DescriptionError
from roarmctl.robot.model import transform


def floats(text: str | None, n: int, where: str) -> np.ndarray:
    """``n`` numbers from a space-separated attribute (zeros when absent); ``where`` names it in errors."""
    if text is None:
        return np.zeros(n)
    try:
        vals = [float(v) for v in text.split()]
    except ValueError:
        raise DescriptionError(f"{where}: not a list of numbers: '{text}'") from None
    if len(vals) != n:
        raise DescriptionError(f"{where}: expected {n} numbers, got '{text}'")
    return np.array(vals)


def fattr(elem: ET.Element | None, key: str, default: float, where: str) -> float:
    """A numeric XML attribute (``default`` when the element or attribute is absent)."""
    if elem is None or elem.get(key) is None:
        return default
    try:
        return float(elem.get(key, ""))
    except ValueError:
        raise DescriptionError(f"{where} {key}: not a number: '{elem.get(key)}'") from None


def origin(elem: ET.Element | None, where: str) -> np.ndarray:
    """The 4x4 transform of an ``<origin xyz rpy>`` element (identity when absent), m and rad."""
    if elem is None:
        return np.eye(4)
    return transform(floats(elem.get("xyz"), 3, f"{where} origin xyz"), floats(elem.get("rpy"), 3, f"{where} origin rpy"))
