"""Named results returned by the kinematics (several arrays at once)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class IKResult(NamedTuple):
    """Joint solution of an inverse-kinematics request.

    joints: joint values [rad for a rotary Delta, m for a linear one], shape (*, 3);
        NaN where ``ok`` is False.
    ok: True where the point is reachable and the input finite, shape (*).
    """

    joints: np.ndarray
    ok: np.ndarray


class FKResult(NamedTuple):
    """Platform position of a forward-kinematics request.

    points: platform centre in the base frame [m], shape (*, 3); NaN where not ok.
    ok: True where the three spheres meet and the input is finite, shape (*).
    """

    points: np.ndarray
    ok: np.ndarray


class LegPoints(NamedTuple):
    """Physical joint centres of the three legs in the base frame [m], each (*, 3 legs, 3).

    hips: actuated joint (rotary) or carriage reference (linear) on the base.
    knees: upper end of the parallelogram (elbow of a rotary leg, carriage of a linear one).
    ankles: lower end of the parallelogram on the platform.
    """

    hips: np.ndarray
    knees: np.ndarray
    ankles: np.ndarray


class Projection(NamedTuple):
    """Nearest reachable point to a goal.

    point: the reachable point [m], shape (3,).
    distance: how far it is from the requested goal [m] (0 when already reachable).
    """

    point: np.ndarray
    distance: float
