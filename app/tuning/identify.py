"""Identification of each joint's response from a step run's and a chirp run's logs.

The model, per joint, from the commanded joint angle u (what the loop wrote, the log's
``commanded_q<j>_rad``) to the measured one y (``measured_q<j>_rad``): a second-order
position loop with a dead time,

    G(s) = K wn^2 / (s^2 + 2 zeta wn s + wn^2) * exp(-s T)

K the static gain (1 for a loop that reaches its goal), wn [rad/s] and zeta the closed
loop's natural frequency and damping, T [s] the delay (the bus, the loop's half tick, the
firmware period). It is the XM430's physics to first order: with P only, the firmware's
PWM k (u - y) (hardware/sim/xm430.py) drives a DC motor whose back-EMF damps it, so
J y'' + b y' = k (u - y) with k the loop's stiffness (app/control/gravity.py, 13.8 N m/rad
at P 800), b = Kt Ke / R and J the joint's inertia with the arm's share; hence
wn^2 = k / J and 2 zeta wn = b / J (`JointModel.inertia_kgm2`). Gravity's constant sag
and the runs' starting point drop out: each record's constant offset is left free.

The fit (`fit_joint`) is scipy.optimize.least_squares on the time-domain error of the
simulated response (scipy.signal.lsim, the input delayed by linear interpolation) over all
records together; its figure of merit is the RMSE [rad]. The measured frequency response
(`empirical_response`) is a lock-in on the chirp's own phase, window by window (an FFT
would need even sampling, which a loaded loop's ticks are not); `bode_figure` draws it
against the fitted model.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: no display on a server

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import optimize, signal  # noqa: E402

JOINTS = (1, 2, 3)
PHASES = ("timed", "hold")  # the run's own part: the approach and the stop are left out
GRID_S = 0.001  # the simulation's step: the XM430 firmware's period [s]


class IdentificationError(ValueError):
    """A record that cannot identify anything (too short, no motion, gaps, NaNs)."""


@dataclass(frozen=True)
class Record:
    """One run's signals for one joint: times t_s [s] (N,), increasing (the clock the
    servos ran on); commanded u_rad and measured y_rad [rad] (N,); loop_t_s [s] (N,): the
    loop's run time of each sample, the clock the run's path was computed on (None: t_s).
    """

    t_s: np.ndarray
    u_rad: np.ndarray
    y_rad: np.ndarray
    loop_t_s: np.ndarray | None = None

    def __post_init__(self) -> None:
        loop = self.t_s if self.loop_t_s is None else np.asarray(self.loop_t_s, dtype=float)
        if np.shape(loop) != np.shape(self.t_s):
            raise IdentificationError("loop_t_s must have one time per sample")
        object.__setattr__(self, "loop_t_s", loop)
        t, u, y = (np.asarray(a, dtype=float) for a in (self.t_s, self.u_rad, self.y_rad))
        if not (t.ndim == 1 and t.shape == u.shape == y.shape):
            raise IdentificationError(
                f"t, u, y must be 1-D of one length: {t.shape, u.shape, y.shape}"
            )
        if t.size < 20:
            raise IdentificationError(f"{t.size} samples: a record needs at least 20")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
            raise IdentificationError("the record holds NaN or infinite values")
        if not np.all(np.diff(t) > 0):
            raise IdentificationError("the record's times must increase")
        if np.ptp(u) <= 0:
            raise IdentificationError("the commanded angle never moves: nothing to identify")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "u_rad", u)
        object.__setattr__(self, "y_rad", y)

    @property
    def sample_hz(self) -> float:
        """The mean sample rate [Hz]."""
        return float((self.t_s.size - 1) / (self.t_s[-1] - self.t_s[0]))


@dataclass(frozen=True)
class JointModel:
    """K wn^2 / (s^2 + 2 zeta wn s + wn^2) exp(-s T): gain K, wn_rad_s [rad/s], zeta,
    delay_s T [s]."""

    gain: float
    wn_rad_s: float
    zeta: float
    delay_s: float

    def frequency_response(self, freqs_hz: np.ndarray, hold_s: float = 0.0) -> np.ndarray:
        """G(j 2 pi f), complex, shape of `freqs_hz` [Hz]; with `hold_s` [s] > 0, times the
        zero-order hold (1 - e^{-s h}) / (s h) of commands held that long, as a response
        measured against the sampled commands sees it (a lag of about h / 2)."""
        s = 2j * math.pi * np.asarray(freqs_hz, dtype=float)
        wn = self.wn_rad_s
        rational = self.gain * wn**2 / (s * s + 2 * self.zeta * wn * s + wn**2)
        response = rational * np.exp(-s * self.delay_s)
        if hold_s > 0:
            sh = s * hold_s
            with np.errstate(invalid="ignore", divide="ignore"):
                hold = np.where(sh == 0, 1.0, (1 - np.exp(-sh)) / np.where(sh == 0, 1, sh))
            response = response * hold
        return response

    def simulate(self, t_s: np.ndarray, u_rad: np.ndarray, step_s: float = GRID_S) -> np.ndarray:
        """The response [rad] (N,) at times `t_s` [s] (N,) to commands `u_rad` (N,), each
        held from its time until the next (as a servo holds its Goal Position; uneven
        ticks and gaps are fine), from rest at u_rad[0].

        Simulated on an even grid of `step_s` [s]: the delayed held input averaged over
        each grid step (exactly, from its running integral, so the result is continuous in
        the delay), the model discretized with a zero-order hold
        (`_discrete`), filtered (scipy.signal.lfilter), and read at `t_s` by linear
        interpolation."""
        t = np.asarray(t_s, dtype=float) - t_s[0]
        u = np.asarray(u_rad, dtype=float) - u_rad[0]
        grid = np.arange(0.0, t[-1] + step_s, step_s)
        # running integral of the held input at its switching times, then at grid +- T
        integral = np.concatenate(([0.0], np.cumsum(u[:-1] * np.diff(t))))

        def held_integral(at: np.ndarray) -> np.ndarray:
            inside = np.interp(at, t, integral)
            return np.where(at > t[-1], integral[-1] + u[-1] * (at - t[-1]), inside) * (at > 0)

        shifted = grid - self.delay_s
        averaged = (held_integral(shifted + step_s) - held_integral(shifted)) / step_s
        b, a = self._discrete(step_s)
        y = signal.lfilter(b, a, averaged)
        # the discretized output at grid step j is the state after input j-1
        return np.interp(t, grid[1:], y[:-1], left=0.0) + self.gain * u_rad[0]

    def _discrete(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The model without its delay discretized with a zero-order hold over `dt` [s]:
        lfilter's (b, a). State x = (y, y'), x' = A x + B u, A = [[0, 1], [-wn^2,
        -2 zeta wn]], B = (0, K wn^2); Phi = exp(A dt) in closed form (a 2x2 matrix with
        eigenvalues m +- d: exp(m dt) (cosh(d dt) I + sinh(d dt) / d (A - m I))), Gamma =
        A^-1 (Phi - I) B; then y / u = C adj(z I - Phi) Gamma / det(z I - Phi), C = (1, 0).
        (scipy.signal.cont2discrete gives the same, ~50x slower through expm's Pade.)"""
        wn, zeta = self.wn_rad_s, self.zeta
        A = np.array([[0.0, 1.0], [-(wn**2), -2.0 * zeta * wn]])
        m = -zeta * wn
        d = complex(wn * wn * (zeta * zeta - 1.0)) ** 0.5
        sinh_over_d = np.sinh(d * dt) / d if abs(d) > 1e-9 else dt
        phi = np.real(
            np.exp(m * dt) * (np.cosh(d * dt) * np.eye(2) + sinh_over_d * (A - m * np.eye(2)))
        )
        gamma = np.linalg.solve(A, (phi - np.eye(2)) @ np.array([0.0, self.gain * wn**2]))
        b = np.array([0.0, gamma[0], phi[0, 1] * gamma[1] - phi[1, 1] * gamma[0]])
        a = np.array([1.0, -(phi[0, 0] + phi[1, 1]), phi[0, 0] * phi[1, 1] - phi[0, 1] * phi[1, 0]])
        return b, a

    def bandwidth_hz(self) -> float:
        """The -3 dB frequency [Hz]: |G(j w)| = |K| / sqrt(2) (delay has no effect on it)."""

        def excess(f: float) -> float:
            return abs(self.frequency_response(np.array([f]))[0]) - abs(self.gain) / math.sqrt(2)

        high = self.wn_rad_s / (2 * math.pi)
        while excess(high) > 0:
            high *= 2
        return float(optimize.brentq(excess, 1e-9, high))

    def inertia_kgm2(self, stiffness_nm_rad: float) -> float:
        """The joint inertia J [kg m^2] the fit implies for a P loop of stiffness k
        [N m/rad]: wn^2 = k / J."""
        return stiffness_nm_rad / self.wn_rad_s**2

    def damping_nms_rad(self, stiffness_nm_rad: float) -> float:
        """The damping b [N m s/rad] it implies: 2 zeta wn = b / J (the motor's back-EMF,
        Kt Ke / R, in the twin)."""
        return 2.0 * self.zeta * self.wn_rad_s * self.inertia_kgm2(stiffness_nm_rad)

    def as_dict(self) -> dict[str, float]:
        return {
            "gain": self.gain,
            "wn_rad_s": self.wn_rad_s,
            "zeta": self.zeta,
            "delay_s": self.delay_s,
            "bandwidth_hz": self.bandwidth_hz(),
        }


@dataclass(frozen=True)
class JointFit:
    """A joint's fitted model: rmse_rad [rad] of the simulated against the measured angle
    over every record, nrmse (that over the measured motion's standard deviation), and the
    samples it used."""

    joint: int
    model: JointModel
    rmse_rad: float
    nrmse: float
    samples: int


@dataclass(frozen=True)
class Bode:
    """A measured frequency response: freqs_hz [Hz] (F,), response (F,) complex (y over
    u), coherence (F,): the lower R^2 of the sinusoid fits of u and y at each frequency;
    hold_s [s]: the mean period the commands were held (compare a model with
    ``frequency_response(f, hold_s)``)."""

    freqs_hz: np.ndarray
    response: np.ndarray
    coherence: np.ndarray
    hold_s: float = 0.0


def record_of(rows: Sequence[dict[str, Any]], joint: int, phases: Sequence[str] = PHASES) -> Record:
    """Joint `joint`'s (1..3) record from a run log's rows (app/runs/logs.py: read_csv_rows
    or read_messages), the rows of `phases` only. Raises IdentificationError.

    Time base: the simulator's own time (``sim_time_s``) where every row has one (the
    twin), else the loop's run time ``t_s`` (real servos). A twin starved of CPU falls
    behind the wall clock, and its time is then the one its servos saw. Rows that read a
    state the twin had not yet advanced from (the same simulated time) keep only the last
    one: its command replaced the earlier ones before the twin stepped."""
    if joint not in JOINTS:
        raise IdentificationError(f"joint {joint}: the legs are {JOINTS}")
    cmd, meas = f"commanded_q{joint}_rad", f"measured_q{joint}_rad"
    kept = [
        r
        for r in rows
        if r.get("phase") in phases and None not in (r.get("t_s"), r.get(cmd), r.get(meas))
    ]
    if not kept:
        raise IdentificationError(f"no rows of phases {list(phases)} with joint {joint}'s angles")
    clock = "sim_time_s" if all(r.get("sim_time_s") is not None for r in kept) else "t_s"
    t = np.array([r[clock] for r in kept], dtype=float)
    u = np.array([r[cmd] for r in kept], dtype=float)
    y = np.array([r[meas] for r in kept], dtype=float)
    last = np.append(np.diff(t) > 0, True)  # the last row of each time
    loop = np.array([r["t_s"] for r in kept], dtype=float)
    return Record(t[last], u[last], y[last], loop[last])


def _residuals(model: JointModel, records: Sequence[Record]) -> np.ndarray:
    parts = []
    for rec in records:
        error = model.simulate(rec.t_s, rec.u_rad) - rec.y_rad
        # each record's constant offset is not the model's: the sag under gravity, and
        # where within its tick the encoder happened to rest at the start
        parts.append(error - error.mean())
    return np.concatenate(parts)


def fit_joint(records: Sequence[Record], joint: int = 1) -> JointFit:
    """Fit `JointModel` to `records` by least squares on the time-domain error (each
    record's constant offset left free), from three starting bandwidths; the best fit
    wins. Bounds: K 0.7..1.3 (a position loop reaches about its goal), wn 1..3000 rad/s,
    zeta 0.05..5, T 0..0.1 s. Raises IdentificationError without records."""
    if not records:
        raise IdentificationError("no records to fit")

    def model_of(x: np.ndarray) -> JointModel:
        return JointModel(float(x[0]), float(x[1]), float(x[2]), float(x[3]))

    lower, upper = [0.7, 1.0, 0.05, 0.0], [1.3, 3000.0, 5.0, 0.1]
    best = None
    for wn0 in (15.0, 60.0, 250.0):
        result = optimize.least_squares(
            lambda x: _residuals(model_of(x), records),
            x0=[1.0, wn0, 0.7, 0.005],
            bounds=(lower, upper),
            x_scale=[0.1, wn0, 0.3, 0.005],
        )
        if best is None or result.cost < best.cost:
            best = result
    assert best is not None
    model = model_of(best.x)
    error = _residuals(model, records)
    motion = np.concatenate([r.y_rad - r.y_rad.mean() for r in records])
    rmse = float(np.sqrt(np.mean(error**2)))
    return JointFit(joint, model, rmse, rmse / float(np.std(motion)), int(error.size))


def empirical_response(
    record: Record,
    f0_hz: float,
    f1_hz: float,
    duration_s: float,
    points: int = 24,
    cycles: float = 2.0,
) -> Bode:
    """The measured frequency response of a linear chirp record (app/runs/paths.py
    ChirpParams: phase 2 pi (f0 tau + (f1 - f0) tau^2 / (2 T)), tau from the record's first
    sample), at `points` frequencies spaced evenly in log between f0 and f1 [Hz].

    At each frequency f, over the `cycles` periods around the time tau_c where the sweep
    passes f, u and y are fitted by least squares (numpy.linalg.lstsq) to
    a + b dt + (c + e dt) sin(phase) + (d + g dt) cos(phase), dt = tau - tau_c: a sinusoid
    on the sweep's phase whose amplitude and phase may drift linearly across the window
    (the sweep changes frequency within it); the response is y's complex amplitude at
    tau_c over u's, (c_y + j d_y) / (c_u + j d_u). A lock-in on the sweep's own phase:
    unlike an FFT (scipy.signal.csd / welch) it needs no even sampling, so a loop's late
    ticks and gaps, and a starved twin's stale reads, cost samples, not bias. `coherence`
    is the lower R^2 of u's and y's fits in each window (1: all their motion is at the
    sweep). Windows with fewer than 8 samples, or a gap over a tenth of the period, are
    left out. Raises
    IdentificationError on a band or duration that is not positive."""
    if not (0 < f0_hz < f1_hz and duration_s > 0):
        raise IdentificationError(f"chirp band {f0_hz}..{f1_hz} Hz over {duration_s} s")
    # the sweep's phase on the loop's clock (the one the path was computed on), the fit's
    # windows on the servos' (a starved twin's falls behind the loop's)
    assert record.loop_t_s is not None
    loop = record.loop_t_s - record.loop_t_s[0]
    rate = (f1_hz - f0_hz) / duration_s
    phase = 2 * math.pi * (f0_hz * loop + 0.5 * rate * loop * loop)
    tau = loop
    freqs, response, quality = [], [], []
    for f in np.geomspace(f0_hz, f1_hz, points):
        centre = (f - f0_hz) / rate
        window = np.abs(tau - centre) <= 0.5 * cycles / f
        # a window with a gap over a tenth of a period (a starved loop) cannot be fitted
        if window.sum() < 8 or np.max(np.diff(record.t_s[window])) > 0.1 / f:
            continue
        sin, cos, dt = np.sin(phase[window]), np.cos(phase[window]), tau[window] - centre
        basis = np.column_stack([np.ones(dt.size), dt, sin, cos, dt * sin, dt * cos])
        cu, *_ = np.linalg.lstsq(basis, record.u_rad[window], rcond=None)
        cy, *_ = np.linalg.lstsq(basis, record.y_rad[window], rcond=None)
        # a sin(p) + b cos(p) = Im((a + j b) e^{jp}): complex amplitude a + j b
        amplitude_u, amplitude_y = complex(cu[2], cu[3]), complex(cy[2], cy[3])
        if abs(amplitude_u) == 0:
            continue
        freqs.append(f)
        response.append(amplitude_y / amplitude_u)
        fits = ((basis @ cu, record.u_rad[window]), (basis @ cy, record.y_rad[window]))
        quality.append(min(_r_squared(fitted, seen) for fitted, seen in fits))
    return Bode(np.array(freqs), np.array(response), np.array(quality), 1.0 / record.sample_hz)


def _r_squared(fitted: np.ndarray, seen: np.ndarray) -> float:
    centred = seen - seen.mean()
    total = float(centred @ centred)
    return 1.0 - float(np.sum((fitted - seen) ** 2)) / total if total > 0 else 0.0


def identify(
    step_rows: Sequence[dict[str, Any]],
    chirp_rows: Sequence[dict[str, Any]],
    chirp: tuple[float, float, float],
    joints: Sequence[int] = JOINTS,
) -> tuple[list[JointFit], list[Bode]]:
    """Per joint, the model fitted to both runs together and the chirp's measured
    frequency response; `chirp` is its (f0_hz, f1_hz, duration_s). Raises
    IdentificationError."""
    fits, bodes = [], []
    for joint in joints:
        step, chirp_record = record_of(step_rows, joint), record_of(chirp_rows, joint)
        fits.append(fit_joint([step, chirp_record], joint))
        bodes.append(empirical_response(chirp_record, *chirp))
    return fits, bodes


def bode_figure(fits: Sequence[JointFit], bodes: Sequence[Bode], path: Path) -> Path:
    """A PNG at `path`: per joint, magnitude [dB] and phase [deg] of the measured response
    (points) against the fitted model (line, with the commands' hold as measured), the
    fit's parameters in the title."""
    n = len(fits)
    figure, axes = plt.subplots(2, n, figsize=(4.2 * n, 5.6), squeeze=False, sharex="col")
    for k, (fit, bode) in enumerate(zip(fits, bodes, strict=True)):
        m = fit.model
        top = max(float(bode.freqs_hz.max()) if bode.freqs_hz.size else 1.0, m.bandwidth_hz())
        freqs = np.geomspace(0.1, 2 * top, 400)
        model = m.frequency_response(freqs, bode.hold_s)
        magnitude, phase = axes[0, k], axes[1, k]
        magnitude.semilogx(freqs, 20 * np.log10(np.abs(model)), color="tab:red", label="fitted")
        magnitude.semilogx(
            bode.freqs_hz, 20 * np.log10(np.abs(bode.response)), "o", ms=3, label="measured"
        )
        magnitude.axhline(20 * math.log10(abs(m.gain)) - 3.0, color="grey", lw=0.6, ls=":")
        phase.semilogx(freqs, np.degrees(np.unwrap(np.angle(model))), color="tab:red")
        phase.semilogx(bode.freqs_hz, np.degrees(np.unwrap(np.angle(bode.response))), "o", ms=3)
        magnitude.set_title(
            f"joint {fit.joint}: K {m.gain:.3f}, wn {m.wn_rad_s:.0f} rad/s, zeta {m.zeta:.2f},\n"
            f"T {m.delay_s * 1e3:.1f} ms, -3 dB {m.bandwidth_hz():.1f} Hz, "
            f"RMSE {fit.rmse_rad * 1e3:.2f} mrad",
            fontsize=8,
        )
        magnitude.set_ylabel("magnitude [dB]")
        phase.set_ylabel("phase [deg]")
        phase.set_xlabel("frequency [Hz]")
        magnitude.grid(True, which="both", alpha=0.3)
        phase.grid(True, which="both", alpha=0.3)
        magnitude.legend(fontsize=7)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
