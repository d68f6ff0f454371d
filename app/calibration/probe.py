"""Probe calibration: touch a flat plate at known heights, fit what z-only data can see.

For robots without motion capture, as Klipper's DELTA_CALIBRATE, RepRapFirmware's
auto-calibration and Marlin's G33 do: the arm descends at points (x, y) until a probe on
the platform touches a flat plate whose height z_k in the base frame is known; the joint
values q_k at the touch are recorded. The model of one touch (kinematics/per_leg.py FK):

    FK_z(q_k; p) = z_k + dz                                                     (P1)

with p the free parameters of the per-leg model (kinematics/identification.py groups:
``offsets``, or ``offsets, L, l, R``) and dz an optional error of the plate's stated
height (``plate_z``: a plate is rarely measured to a tenth of a millimetre against the
motor axes). Only z is measured, so only the z row of the identification Jacobian enters:

    d FK_z / dp = e_z^T dP/dp   (identification eq. for dP/dp),   d(P1) / d dz = -1.

What these heights cannot tell is computed, never assumed. The singular values and
condition number are those of the unit-column-scaled Jacobian, as for motion capture
(``kinematics.identification.observability_of``). Whether a direction is pinned depends
on the probe's noise: with columns scaled by a typical error of each parameter
(``TYPICAL``: 1 deg, 1 mm), direction k of singular value s_k is known to a standard
deviation of noise / s_k typical errors; above ``PINNED_SD`` (a tenth: 0.1 deg, 0.1 mm)
it is reported by name. E.g. with the plate's height free, a common offset of the three
joints moves every touch of one plate almost, but not exactly, as the plate's height does
(tests/calibration/test_probe.py works it out): pinned by 40 touches with 20 um of noise,
not with 0.1 mm; a second plate height pins it better. The fit is scipy's
``least_squares`` with a robust loss inside the identification's bounds, plus a tiny
prior pulling every parameter to its nominal value (``PRIOR_M``), so that directions the
data cannot see stay where the nominal model puts them instead of drifting.

``probe_points`` and ``simulate_touches`` make the touches of the twin built wrong on
purpose from its true model (no contact physics: the joint values at which the true
platform's z equals the plate's height, with trigger noise): a probe run's "model" mode.
Its "touch" mode (``PROBE_MODES``; app/calibration/procedure.py) touches a real plate, the
twin's (MuJoCo contact) or the robot's, with the controller's force-guided touch.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from app.calibration.fit import CalibrationError, FitResult, rmse
from kinematics.identification import (
    Identification,
    MeasurementFrame,
    Observability,
    observability_of,
)
from kinematics.per_leg import PerLegRotaryDelta

PROBE_GROUPS: dict[str, tuple[str, ...]] = {
    "offsets": ("offsets",),
    "geometry": ("offsets", "L", "l", "R"),
}
PLATE = "plate_z"
PLATE_BOUND_M = 0.01  # the plate's stated height may be off by up to 1 cm
PINNED_SD = 0.1
"""A combination whose standard deviation from the probe's noise exceeds this many typical
errors (``TYPICAL``) is reported as not pinned by the touches."""
PRIOR_M = 1e-6
"""Weight of the prior: a typical error (``TYPICAL``) away from nominal costs as much as
1 um of touch height, far below any probe's noise, so it only decides directions the
touches do not see."""
TYPICAL = {"offsets": math.radians(1.0), "L": 1e-3, "l": 1e-3, "R": 1e-3, PLATE: 1e-3}
PROBE_NOISE_M = 2e-5
"""Trigger noise of a probe [m] (1 sigma): a typical touch or inductive probe repeats to
about 20 um. The twin's simulated probe has it; the observability assumes it unless told."""
MIN_TOUCHES = 8


@dataclass(frozen=True)
class ProbeModel:
    """The touch model (P1) over the free parameters: robot groups, then ``plate_z``.

    Attributes:
        nominal: the model the parameters start from (what the controller uses).
        parameters: "offsets" (the three joint offsets) or "geometry" (also L, l, R).
        plate_free: whether the plate's height error dz is fitted (else it is 0).

    Raises:
        CalibrationError: for another ``parameters``.
    """

    nominal: PerLegRotaryDelta
    parameters: str = "offsets"
    plate_free: bool = False

    def __post_init__(self) -> None:
        if self.parameters not in PROBE_GROUPS:
            raise CalibrationError(
                f"parameters: {self.parameters!r} is not one of {sorted(PROBE_GROUPS)}"
            )

    @property
    def identification(self) -> Identification:
        """The 3D identification whose z rows this model uses (base frame = measurement)."""
        return Identification(self.nominal, MeasurementFrame(), PROBE_GROUPS[self.parameters])

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in vector order ("offsets[0]", ..., and "plate_z" if free)."""
        return self.identification.names + ((PLATE,) if self.plate_free else ())

    @property
    def initial(self) -> np.ndarray:
        """The nominal vector (plate error 0), shape (P,)."""
        extra = [0.0] if self.plate_free else []
        return np.concatenate([self.identification.initial, extra])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper), (P,) each: the identification's physical bounds, and
        +-``PLATE_BOUND_M`` for the plate's height error."""
        lower, upper = self.identification.bounds()
        if self.plate_free:
            lower = np.append(lower, -PLATE_BOUND_M)
            upper = np.append(upper, PLATE_BOUND_M)
        return lower, upper

    @property
    def typical(self) -> np.ndarray:
        """A typical error of each parameter [rad or m], shape (P,): the prior's scale."""
        return np.array([TYPICAL[name.split("[")[0]] for name in self.names])

    def _split(self, params: Any) -> tuple[np.ndarray, float]:
        p = np.asarray(params, dtype=float)
        if p.shape != (len(self.names),):
            raise CalibrationError(f"params: expected shape ({len(self.names)},), got {p.shape}")
        return (p[:-1], float(p[-1])) if self.plate_free else (p, 0.0)

    def robot(self, params: Any) -> PerLegRotaryDelta:
        """The per-leg model of a parameter vector."""
        robot_params, _ = self._split(params)
        return self.identification.unpack(robot_params)[0]

    def plate_error(self, params: Any) -> float:
        """dz of a parameter vector [m] (0 when the plate is not free)."""
        return self._split(params)[1]

    def residuals(self, params: Any, joints: Any, plate_z: Any) -> np.ndarray:
        """FK_z(q_k) - (z_k + dz) [m], shape (N,), for joints (N, 3) [rad] and plate
        heights (N,) [m]; 1 m where the model has no FK (far off, finite)."""
        robot_params, dz = self._split(params)
        z = self.identification.predict(robot_params, joints)[:, 2]
        diff = z - (np.asarray(plate_z, dtype=float) + dz)
        return np.where(np.isfinite(diff), diff, 1.0)

    def jacobian(self, params: Any, joints: Any) -> np.ndarray:
        """d residuals / d params, shape (N, P) [m per rad or m per m]: the z row of the
        identification's analytic Jacobian, and -1 for dz."""
        robot_params, _ = self._split(params)
        rows = self.identification.jacobian(robot_params, joints)[:, 2, :]
        if self.plate_free:
            rows = np.hstack([rows, -np.ones((len(rows), 1))])
        return rows

    def observability(
        self, params: Any, joints: Any, noise_m: float = PROBE_NOISE_M
    ) -> Observability:
        """What touches at ``joints`` (N, 3) [rad] with a probe noise of ``noise_m`` [m]
        (1 sigma) can tell: singular values and condition number of the unit-scaled
        Jacobian; ``unobservable``/``combinations``: the directions whose standard
        deviation exceeds ``PINNED_SD`` typical errors (module docstring), written in
        typical errors ("+0.58 offsets[0] ... -0.57 plate_z": 1 deg, 1 mm each)."""
        jac = self.jacobian(params, joints)
        jac = jac[np.isfinite(jac).all(axis=1)]
        report = observability_of(jac, self.names, 1e-9)
        typical = self.typical
        _, sigma, vt = np.linalg.svd(jac * typical, full_matrices=True)
        sigma_full = np.zeros(len(typical))
        sigma_full[: len(sigma)] = sigma
        with np.errstate(divide="ignore"):
            sd = np.where(sigma_full > 0.0, noise_m / sigma_full, np.inf)
        involved: set[int] = set()
        combos = []
        for k in np.flatnonzero(sd > PINNED_SD):
            v = vt[k] * np.sign(vt[k][np.argmax(np.abs(vt[k]))])
            big = np.flatnonzero(np.abs(v) >= 0.1 * np.abs(v).max())
            involved.update(big.tolist())
            terms = " ".join(f"{v[j]:+.2f} {self.names[j]}" for j in big)
            combos.append(f"{terms} (sd {sd[k]:.2g} typical errors)")
        return replace(
            report,
            unobservable=tuple(self.names[j] for j in sorted(involved)),
            combinations=tuple(combos),
        )


@dataclass(frozen=True)
class ProbeResult(FitResult):
    """A probe fit (``FitResult``'s fields; residuals (N, 3) with x, y zero, z the touch
    height error [m]) and the plate's fitted height error ``plate_error_m`` [m]."""

    plate_error_m: float = 0.0
    plate_free: bool = False


def _solve(model: ProbeModel, joints: np.ndarray, plate_z: np.ndarray, start: np.ndarray):
    from scipy.optimize import least_squares  # here: the server imports this module at start

    lower, upper = model.bounds()
    x0 = np.clip(start, lower, upper)
    centre, typical = model.initial, model.typical

    def residuals(p: np.ndarray) -> np.ndarray:
        prior = PRIOR_M * (p - centre) / typical
        return np.concatenate([model.residuals(p, joints, plate_z), prior])

    def jacobian(p: np.ndarray) -> np.ndarray:
        return np.vstack([model.jacobian(p, joints), np.diag(PRIOR_M / typical)])

    return least_squares(
        residuals,
        x0,
        jac=jacobian,
        bounds=(lower, upper),
        loss="soft_l1",
        f_scale=2e-4,  # touch errors beyond ~0.2 mm count linearly: a false trigger cannot drag
        x_scale="jac",
    )


def probe_fit(
    nominal: PerLegRotaryDelta,
    joints: Any,
    plate_z: Any,
    holdout: int,
    parameters: str = "offsets",
    plate_free: bool = False,
    noise_m: float = PROBE_NOISE_M,
) -> ProbeResult:
    """Fit ``parameters`` to touches and validate on the last ``holdout`` of them.

    joints (N, 3) [rad] as the controller read them at each touch; plate_z (N,) or a
    scalar [m]: the plate's stated height (base frame, z up, negative) at each touch.
    The current model is ``nominal`` (with only dz fitted when ``plate_free``); the
    result's ``better`` says whether the fit beats it on the held-out touches, and its
    observability what touches with the probe's noise ``noise_m`` [m] cannot pin.

    Raises:
        CalibrationError: for bad shapes, non-finite values, or too few touches.
    """
    q = np.asarray(joints, dtype=float)
    if q.ndim != 2 or q.shape[1:] != (3,):
        raise CalibrationError(f"touches: joints {q.shape} must be (N, 3)")
    z = np.broadcast_to(np.asarray(plate_z, dtype=float), (len(q),)).copy()
    if not (np.isfinite(q).all() and np.isfinite(z).all()):
        raise CalibrationError("touches: every joint angle and plate height must be finite")
    model = ProbeModel(nominal, parameters, plate_free)
    n_fit = len(q) - holdout
    if holdout < 1 or n_fit < max(MIN_TOUCHES, 2 * len(model.names)):
        raise CalibrationError(
            f"touches: {len(q)} touches with {holdout} held out leave too few to fit "
            f"{len(model.names)} parameters"
        )
    fq, fz = q[:n_fit], z[:n_fit]
    before_x = model.initial
    if plate_free:  # the current model: nominal robot, only the plate's height fitted
        dz = _plate_only(nominal, fq, fz)
        before_x = np.concatenate([model.initial[:-1], [dz]])
    after = _solve(model, fq, fz, before_x)
    res_before = model.residuals(before_x, q, z)
    res_after = model.residuals(after.x, q, z)
    return ProbeResult(
        parameters=parameters,
        robot=model.robot(after.x),
        frame=MeasurementFrame(),
        rmse_before_m=rmse(_as_3d(res_before[:n_fit])),
        rmse_after_m=rmse(_as_3d(res_after[:n_fit])),
        holdout_before_m=rmse(_as_3d(res_before[n_fit:])),
        holdout_rmse_m=rmse(_as_3d(res_after[n_fit:])),
        observability=model.observability(after.x, fq, noise_m),
        residuals_before=_as_3d(res_before).reshape(-1, 3),
        residuals_after=_as_3d(res_after).reshape(-1, 3),
        holdout=holdout,
        plate_error_m=model.plate_error(after.x),
        plate_free=plate_free,
    )


def _plate_only(nominal: PerLegRotaryDelta, joints: np.ndarray, plate_z: np.ndarray) -> float:
    """The plate's height error that best fits the nominal robot [m]: the median of its
    touch height errors (robust, as the fit's loss), within the bounds."""
    errors = ProbeModel(nominal).residuals(ProbeModel(nominal).initial, joints, plate_z)
    return float(np.clip(np.median(errors), -PLATE_BOUND_M, PLATE_BOUND_M))


def _as_3d(z_errors: np.ndarray) -> np.ndarray:
    """(N,) height errors as the (3N,) residual vector of ``fit.rmse`` (x, y zero)."""
    out = np.zeros((len(z_errors), 3))
    out[:, 2] = z_errors
    return out.ravel()


# ---- touches on the twin ----
def probe_points(
    nominal: PerLegRotaryDelta, plate_z_m: float, count: int, min_dexterity: float = 0.2
) -> np.ndarray:
    """``count`` points (count, 2) [m] spread over the plate (a sunflower spiral) within
    the largest disc of radius at ``plate_z_m`` where the nominal robot reaches every
    point with dexterity >= ``min_dexterity`` (and 1 cm above and below), less 10 %.

    Raises:
        CalibrationError: when the plate's height is out of reach, or count < 1.
    """
    if count < 1:
        raise CalibrationError(f"poses: {count} touches asked")
    angles = np.linspace(0.0, 2.0 * math.pi, 36, endpoint=False)
    radius = 0.0
    for r in np.arange(0.0, 0.3, 0.002):
        ring = np.stack([r * np.cos(angles), r * np.sin(angles)], axis=1)
        ok = True
        for z in (plate_z_m - 0.01, plate_z_m, plate_z_m + 0.01):
            points = np.column_stack([ring, np.full(len(ring), z)])
            joints, reached = nominal.ik(points)
            dex = np.nan_to_num(nominal.dexterity(joints))
            ok = ok and bool(reached.all() and (dex >= min_dexterity).all())
        if not ok:
            break
        radius = float(r)
    if radius < 0.01:
        raise CalibrationError(
            f"plate_z_m: {plate_z_m} m is not a height the robot reaches over a plate "
            "(the platform hangs below the base: z < 0)"
        )
    k = np.arange(count) + 0.5
    rho = 0.9 * radius * np.sqrt(k / count)
    phi = k * math.pi * (3.0 - math.sqrt(5.0))  # the golden angle
    return np.stack([rho * np.cos(phi), rho * np.sin(phi)], axis=1)


def simulate_touches(
    true_robot: PerLegRotaryDelta,
    nominal: PerLegRotaryDelta,
    xy: Any,
    plate_z: Any,
    noise_m: float = PROBE_NOISE_M,
    seed: int = 0,
) -> np.ndarray:
    """The joint values (N, 3) [rad] the joints report when the probe touches the plate.

    The controller (``nominal``) descends vertically at each (x, y) of ``xy`` (N, 2) [m];
    it touches when the *true* platform's z is the plate's height (``plate_z``, (N,) or a
    scalar [m]) plus the probe's trigger noise (``noise_m``, 1 sigma, Gaussian). The
    reported joints are the ones the controller commanded there (at rest they are what the
    joints report; the true model turns them by its offsets, per_leg.py theta = q + o); the
    height is found by Brent's method on the descent.

    Raises:
        CalibrationError: when a descent never reaches the plate within 3 cm.
    """
    from scipy.optimize import brentq

    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    z_plate = np.broadcast_to(np.asarray(plate_z, dtype=float), (len(xy),))
    trigger = z_plate + np.random.default_rng(seed).normal(0.0, noise_m, len(xy))
    out = np.empty((len(xy), 3))
    for k, ((x, y), target) in enumerate(zip(xy, trigger, strict=True)):

        def gap(z_nom: float, x: float = x, y: float = y, target: float = target) -> float:
            q = nominal.ik([x, y, z_nom]).joints
            return float(true_robot.fk(q).points[2] - target)

        low, high = target - 0.03, target + 0.03
        try:
            z_nom = brentq(gap, low, high, xtol=1e-12)
        except ValueError as exc:
            raise CalibrationError(
                f"plate_z_m: the descent at ({x:.4f}, {y:.4f}) m does not reach the plate: {exc}"
            ) from None
        out[k] = nominal.ik([x, y, z_nom]).joints
    return out


Touch = Callable[[np.ndarray, float, int], np.ndarray]
"""touch(xy (N, 2) [m], plate_z [m], seed) -> the joints (N, 3) [rad] the controller reads
at each touch of the plate."""


def twin_probe(
    truth: PerLegRotaryDelta,
    model: Callable[[], PerLegRotaryDelta],
    offsets_in_use: Callable[[], np.ndarray],
    noise_m: float = PROBE_NOISE_M,
) -> Touch:
    """The twin's probe: touches computed from its true model (``simulate_touches``).

    truth: the twin's true geometry ([hardware.sim], ``SimSettings.true_robot``; the
    drawing's robot for the exact twin). model: the controller's model in use now, which
    it descends in (a geometry calibration's apply changes it). offsets_in_use: the joint
    offsets the controller applies now [rad] (3,): it reads q = raw + a while the
    mechanism turns by raw + o_true, so the true model in the controller's terms has
    offsets o_true - a.
    """

    def touch(xy: np.ndarray, plate_z: float, seed: int) -> np.ndarray:
        applied = np.asarray(offsets_in_use(), dtype=float)
        offsets = np.array(truth.joint_offsets_rad) - applied
        here = truth.with_values(joint_offsets_rad=tuple(float(v) for v in offsets))
        return simulate_touches(here, model(), xy, plate_z, noise_m, seed)

    return touch


# ---- touches of a real plate (the twin's or the robot's) with the force-guided touch ----
PROBE_MODES = ("touch", "model")
"""How a probe run gets its touches: "touch", the arm moved onto the plate with the
controller's touch (app/control/touch.py, a probe without a probe switch); "model", computed
from the twin's true model (``twin_probe``; the arm is not moved)."""
TOUCH_CLEARANCE_M = 0.005
"""A touch starts this far above the plate's stated height [m] (the tool tip), and moves
between points there: more than the model's and the plate's height errors, less than the
1 cm above the plate that ``probe_points`` keeps reachable."""
TOUCH_BEYOND_M = 0.01
"""A touch goes this far below the plate's stated height [m] before it ends "no contact"."""


def plate_under(plates: Any, plate_z_m: float, xy: Any) -> bool:
    """Whether one of ``plates`` (hardware/sim/surfaces.py ``Plate``-s: ``point_m``,
    ``normal``, ``half_size_m``, ``frame()``) faces up (normal within 2.6 deg of +z) with
    its face within ``PLATE_BOUND_M`` of ``plate_z_m`` [m] and under every point of ``xy``
    (N, 2) [m] (base frame): the twin has a plate there to touch."""
    points = np.asarray(xy, dtype=float).reshape(-1, 2)
    for plate in plates:
        frame = np.asarray(plate.frame(), dtype=float)  # columns: face x, face y, normal
        normal, centre = frame[:, 2], np.asarray(plate.point_m, dtype=float)
        if normal[2] < 0.999 or abs(centre[2] - plate_z_m) > PLATE_BOUND_M:
            continue
        offsets = np.column_stack([points - centre[:2], np.zeros(len(points))])
        along = offsets @ frame[:, :2]  # (N, 2): along the face's x and y
        if (np.abs(along) <= np.asarray(plate.half_size_m, dtype=float)).all():
            return True
    return False


def write_touches(path: Any, joints: np.ndarray, plate_z: np.ndarray, holdout: int) -> None:
    """The touches as CSV: q0_rad, q1_rad, q2_rad, plate_z_m, set (fit | holdout, the last
    ``holdout`` rows held out)."""
    import csv

    n = len(joints)
    with open(path, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["q0_rad", "q1_rad", "q2_rad", "plate_z_m", "set"])
        for k in range(n):
            kind = "holdout" if k >= n - holdout else "fit"
            writer.writerow([*map(repr, map(float, joints[k])), repr(float(plate_z[k])), kind])
