"""Our modal machine: the subset of LinuxCNC's G-code in docs/gcode.md, words to segments.

State (LinuxCNC's defaults): G17, G21 (mm), G90, G91.1 (arc centres relative to the
start), G54 (the one work offset), G61 (exact stop), no motion mode and no feed until the
program gives them. Within a line, words act in LinuxCNC's order: feed (F), plane, units,
work offset, path control, distance modes, then dwell (G4) or the motion, then M0/M1/M2/M30.
F is kept as written and read in the units in force when a move uses it.

Programs are in millimetres (inches under G20) in the base frame shifted by the work
offset: base = work_offset_m + program * unit. Out of this module everything is SI.
Every word outside the subset is refused with its line, never ignored.

A is the wrist's angle phi in degrees (a rotary axis, as LinuxCNC's A; the 2012 paper's
fourth axis, theta_4 = phi about the base's z): absolute under G90, added under G91,
unaffected by G20/G21 and by the work offset (A0 is the wrist's zero). It moves with the
line's X, Y, Z, linearly along the segment, and must stay within the wrist's limits.
Without a wrist axis A is refused.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from app.programs.errors import ProgramError
from app.programs.segments import PLANE_AXES, Segment
from app.programs.tokens import Line, Word

MM, INCH = 1e-3, 25.4e-3
RADIUS_TOLERANCE_M = 1e-5  # start and end radius of an arc may differ this much...
RADIUS_TOLERANCE_REL = 1e-3  # ...or this fraction of the radius...
RADIUS_TOLERANCE_MAX_M = 2 * 0.01e-3 * math.sqrt(2)  # ...but never more than LinuxCNC's
# default (CENTER_ARC_RADIUS_TOLERANCE_MM: the end and centre rounded to 0.01 mm), so a
# huge radius's 0.1 % (2.4 m for 2,426 m) never passes an end off its circle
FULL_CIRCLE_TOLERANCE_M = 1e-10  # an arc is a full turn only when its end is its start
# this closely: a tenth of a 6-decimal millimetre post's digit (1e-9 m), far above the
# rounding of the arithmetic (1e-16 m here); a 6 um CAM arc is an arc (grbl#496)
MAX_ARC_RADIUS_M = 1e6  # 1,000 km: the path (centre + radius, each up to 1e6 m) keeps
# its points within ~1e-9 m; a larger radius is refused, with the straight line it nears
_SUPPORTED_G = {
    0: "motion", 10: "motion", 20: "motion", 30: "motion", 40: "dwell",
    170: "plane", 180: "plane", 190: "plane",
    200: "units", 210: "units",
    540: "offset",
    610: "path", 640: "path",
    900: "distance", 910: "distance",
    901: "arc_distance", 911: "arc_distance",
}  # fmt: skip
_SUPPORTED_M = {0, 1, 2, 30}
_VALUE_LETTERS = set("XYZIJKRFP")
_WRIST = "the wrist axis is not configured (A needs [wrist] enabled = true)"


@dataclass
class ModalState:
    """What the machine remembers between lines (SI inside: position in the base frame)."""

    position_m: np.ndarray
    work_offset_m: np.ndarray
    unit_m: float = MM
    absolute: bool = True
    arc_absolute: bool = False
    plane: str = "G17"
    motion: int | None = None
    feed: float | None = None  # as written, units per minute
    blend_m: float | None = None  # None: G61 exact stop
    ended: bool = False
    phi_rad: float = 0.0  # the wrist's angle [rad]
    wrist: tuple[float, float] | None = None  # its limits [rad]; None: no wrist, A refused


@dataclass
class Program:
    """The interpreted program: its segments in order and notes for the report."""

    segments: list[Segment] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    lines: int = 0


def _g_code(word: Word, line: int) -> int:
    code = round(word.value * 10)
    if abs(code - word.value * 10) > 1e-6 or code not in _SUPPORTED_G:
        raise ProgramError(line, word.text, "not supported (the subset is in docs/gcode.md)")
    return code


def _collect(
    line: Line, wrist: bool = False
) -> tuple[dict[str, int], dict[str, Word], Word | None]:
    """Split a line into G codes by modal group, value words by letter and its M word;
    A only with a ``wrist``."""
    groups: dict[str, int] = {}
    values: dict[str, Word] = {}
    m_word: Word | None = None
    seen_n = False
    for word in line.words:
        if word.letter == "A" and not wrist:
            raise ProgramError(line.number, word.text, _WRIST)
        if word.letter == "N":
            if seen_n:
                raise ProgramError(line.number, word.text, "two line numbers on one line")
            seen_n = True
        elif word.letter == "G":
            code = _g_code(word, line.number)
            group = _SUPPORTED_G[code]
            if group in groups or (
                {group, *groups} >= {"motion", "dwell"} and group in ("motion", "dwell")
            ):
                raise ProgramError(
                    line.number, word.text, f"a second {group} code on one line (modal group)"
                )
            groups[group] = code
        elif word.letter == "M":
            if word.value not in _SUPPORTED_M:
                raise ProgramError(
                    line.number, word.text, "not supported (the subset is in docs/gcode.md)"
                )
            if m_word is not None:
                raise ProgramError(line.number, word.text, "a second M code on one line")
            m_word = word
        elif word.letter in _VALUE_LETTERS or word.letter == "A":
            if word.letter in values:
                raise ProgramError(line.number, word.text, f"a second {word.letter} on one line")
            values[word.letter] = word
        else:
            raise ProgramError(line.number, word.text, "not a word of the subset (docs/gcode.md)")
    return groups, values, m_word


def _apply_modes(state: ModalState, groups: dict[str, int], values: dict[str, Word], n: int):
    if "F" in values:
        if not values["F"].value > 0:
            raise ProgramError(n, values["F"].text, "the feed must be > 0")
        state.feed = values["F"].value
    if "plane" in groups:
        state.plane = {170: "G17", 180: "G18", 190: "G19"}[groups["plane"]]
    if "units" in groups:
        state.unit_m = INCH if groups["units"] == 200 else MM
    if "path" in groups:
        if groups["path"] == 610:
            if "P" in values:
                raise ProgramError(n, values["P"].text, "P goes with G64 or G4, not G61")
            state.blend_m = None
        else:
            p = values.get("P")
            if p is not None and p.value < 0:
                raise ProgramError(n, p.text, "the G64 tolerance must be >= 0")
            state.blend_m = p.value * state.unit_m if p is not None else math.inf
    if "distance" in groups:
        state.absolute = groups["distance"] == 900
    if "arc_distance" in groups:
        state.arc_absolute = groups["arc_distance"] == 901


def _target(state: ModalState, values: dict[str, Word]) -> np.ndarray:
    target = state.position_m.copy()
    for axis, letter in enumerate("XYZ"):
        if letter in values:
            value = values[letter].value * state.unit_m
            if state.absolute:
                target[axis] = state.work_offset_m[axis] + value
            else:
                target[axis] += value
    return target


def _target_phi(state: ModalState, values: dict[str, Word], n: int) -> float:
    """The wrist's angle [rad] at the end of the line's move: A [deg] absolute (G90) or
    added (G91); ProgramError naming A when it is outside the wrist's limits."""
    word = values.get("A")
    if word is None or state.wrist is None:
        return state.phi_rad
    value = math.radians(word.value)
    phi = value if state.absolute else state.phi_rad + value
    low, high = state.wrist
    if not low <= phi <= high:
        raise ProgramError(
            n,
            word.text,
            f"the wrist would be at {math.degrees(phi):.2f} deg, outside its limits "
            f"[{math.degrees(low):.1f}, {math.degrees(high):.1f}] deg",
        )
    return phi


def _vec(a: np.ndarray) -> tuple[float, float, float]:
    return (float(a[0]), float(a[1]), float(a[2]))


def _arc(
    state: ModalState,
    values: dict[str, Word],
    code: int,
    end: np.ndarray,
    n: int,
    word: str,
    phi_end: float,
) -> Segment:
    a, b, c = PLANE_AXES[state.plane]
    start = state.position_m
    letters = "IJK"
    allowed = {letters[a], letters[b]}
    for letter in set(letters) - allowed:
        if letter in values:
            raise ProgramError(
                n, values[letter].text, f"{letter} is not an arc offset in the {state.plane} plane"
            )
    given = allowed & values.keys()
    clockwise = code == 20
    if "R" in values and given:
        raise ProgramError(n, values["R"].text, "give R or the centre offsets, not both")
    if "R" in values:
        centre = _centre_from_radius(start, end, values["R"], clockwise, (a, b), state, n)
    elif given:
        centre = start.copy() if not state.arc_absolute else state.work_offset_m.copy()
        for axis in (a, b):
            letter = letters[axis]
            if letter in values:
                centre[axis] += values[letter].value * state.unit_m
        centre[c] = start[c]
    else:
        offsets = "".join(sorted(allowed))
        raise ProgramError(n, word, f"an arc needs R or its centre offsets ({offsets})")
    r0 = math.hypot(start[a] - centre[a], start[b] - centre[b])
    r1 = math.hypot(end[a] - centre[a], end[b] - centre[b])
    if r0 <= RADIUS_TOLERANCE_M:
        raise ProgramError(n, word, "the arc's centre is at its start (zero radius)")
    chord = math.hypot(end[a] - start[a], end[b] - start[b])
    _check_radius(r0, chord, n, word)
    if abs(r1 - r0) > radius_tolerance(r0):
        raise ProgramError(
            n,
            word,
            f"the end is {abs(r1 - r0) * 1e3:.4f} mm {'further from' if r1 > r0 else 'nearer'} "
            f"the centre than the start (radius {r0 * 1e3:.4f} mm; at most "
            f"{radius_tolerance(r0) * 1e3:.4f} mm is closed by a spiral)",
        )
    phi0 = math.atan2(start[b] - centre[b], start[a] - centre[a])
    phi1 = math.atan2(end[b] - centre[b], end[a] - centre[a])
    # a full turn only when the end is the start (or at the start's very angle, as in
    # LinuxCNC); else the arc sweeps what it says, however short its chord
    same = chord <= FULL_CIRCLE_TOLERANCE_M
    if clockwise:
        sweep = -((phi0 - phi1) % (2 * math.pi))
        sweep = -2 * math.pi if same or sweep == 0.0 else sweep
    else:
        sweep = (phi1 - phi0) % (2 * math.pi)
        sweep = 2 * math.pi if same or sweep == 0.0 else sweep
    return Segment(
        n,
        "arc",
        _vec(start),
        _vec(end),
        centre_m=_vec(centre),
        plane=state.plane,
        direction="cw" if clockwise else "ccw",
        sweep_rad=sweep,
        feed_m_s=_feed(state, n, word),
        blend_m=state.blend_m,
        phi_start_rad=state.phi_rad,
        phi_end_rad=phi_end,
    )


def radius_tolerance(radius_m: float) -> float:
    """How much an arc's end radius may differ from its start radius [m] (a spiral closes
    the gap): 0.01 mm, or 0.1 % of ``radius_m`` [m] for a larger radius, at most
    0.0283 mm (LinuxCNC's default tolerance)."""
    relative = min(RADIUS_TOLERANCE_REL * radius_m, RADIUS_TOLERANCE_MAX_M)
    return max(RADIUS_TOLERANCE_M, relative)


def _check_radius(radius_m: float, chord_m: float, n: int, word: str) -> None:
    """ProgramError for an arc radius [m] over MAX_ARC_RADIUS_M, saying how straight the
    arc is over its chord [m] (its sagitta), so the CAM user can write it as G1."""
    if radius_m <= MAX_ARC_RADIUS_M:
        return
    half = min(chord_m / 2, radius_m)
    sagitta = half * half / (radius_m + math.sqrt(radius_m * radius_m - half * half))
    raise ProgramError(
        n,
        word,
        f"the arc's radius is {radius_m / 1e3:,.6g} km, over {MAX_ARC_RADIUS_M / 1e3:,.0f} km "
        f"(a centre that far leaves the path's points imprecise); over its "
        f"{chord_m * 1e3:.4f} mm chord it is {sagitta * 1e3:.3g} mm from a straight line: "
        "write it as G1 to its end (or have the post-processor output such arcs as lines)",
    )


def _centre_from_radius(start, end, r_word: Word, clockwise: bool, axes, state, n: int):
    """Centre of the R-format arc (LinuxCNC): R > 0 the short way, R < 0 the long way."""
    a, b = axes
    radius = r_word.value * state.unit_m
    dx, dy = end[a] - start[a], end[b] - start[b]
    chord = math.hypot(dx, dy)
    if chord <= FULL_CIRCLE_TOLERANCE_M:
        raise ProgramError(n, r_word.text, "an R arc cannot be a full circle: give I, J or K")
    _check_radius(abs(radius), chord, n, r_word.text)
    if abs(radius) < chord / 2 - RADIUS_TOLERANCE_M:
        raise ProgramError(
            n, r_word.text, f"|R| is under half the chord ({chord / 2 * 1e3:.4f} mm)"
        )
    h = math.sqrt(max(radius**2 - (chord / 2) ** 2, 0.0))
    side = (1.0 if not clockwise else -1.0) * (1.0 if radius > 0 else -1.0)
    centre = start.copy()
    centre[a] = start[a] + dx / 2 - side * h * dy / chord
    centre[b] = start[b] + dy / 2 + side * h * dx / chord
    return centre


def _feed(state: ModalState, n: int, word: str) -> float:
    if state.feed is None:
        raise ProgramError(n, word, "a feed move needs a feed rate: give F first")
    return state.feed * state.unit_m / 60.0


def _check_usage(groups: dict[str, int], values: dict[str, Word], motion: int | None, n: int):
    arc = motion in (20, 30)
    for letter in "IJKR":
        if letter in values and not arc:
            raise ProgramError(n, values[letter].text, "arc words need G2 or G3 in force")
    if "P" in values and "dwell" not in groups and groups.get("path") != 640:
        raise ProgramError(n, values["P"].text, "P goes with G4 (dwell) or G64")


def step(state: ModalState, line: Line, program: Program) -> None:
    """Run one line on ``state``, appending its segments to ``program``.

    Raises:
        ProgramError: naming the line and word (see module).
    """
    n = line.number
    groups, values, m_word = _collect(line, state.wrist is not None)
    _apply_modes(state, groups, values, n)
    if "motion" in groups:
        state.motion = groups["motion"]
    axes = [values[k] for k in "XYZA" if k in values]
    _check_usage(groups, values, state.motion if axes or "motion" in groups else None, n)
    if "dwell" in groups:
        if axes:
            raise ProgramError(n, axes[0].text, "G4 takes P (seconds), not axis words")
        if "P" not in values or values["P"].value < 0:
            raise ProgramError(n, "G4", "a dwell needs P, its time in seconds (>= 0)")
        pos, phi = _vec(state.position_m), state.phi_rad
        program.segments.append(
            Segment(
                n, "dwell", pos, pos, dwell_s=values["P"].value, phi_start_rad=phi, phi_end_rad=phi
            )
        )
    elif axes or "motion" in groups:
        if state.motion is None:
            raise ProgramError(n, axes[0].text, "axis words without a motion mode (G0 to G3)")
        if axes or state.motion in (20, 30):
            word = f"G{state.motion // 10}"
            end = _target(state, values)
            phi_end = _target_phi(state, values, n)
            wrist = {"phi_start_rad": state.phi_rad, "phi_end_rad": phi_end}
            segment: Segment | None = None
            travels = np.linalg.norm(end - state.position_m) > 0
            if state.motion in (20, 30):
                segment = _arc(state, values, state.motion, end, n, word, phi_end)
            elif travels or phi_end != state.phi_rad:
                start = _vec(state.position_m)
                if state.motion == 0:
                    segment = Segment(n, "rapid", start, _vec(end), blend_m=state.blend_m, **wrist)
                else:
                    feed = _feed(state, n, word)
                    # the wrist alone: F in degrees per minute (LinuxCNC, a rotary axis alone)
                    turn = None if travels else math.radians(state.feed or 0.0) / 60.0
                    segment = Segment(
                        n,
                        "linear",
                        start,
                        _vec(end),
                        feed_m_s=feed,
                        blend_m=state.blend_m,
                        feed_rad_s=turn,
                        **wrist,
                    )
            if segment is not None:
                program.segments.append(segment)
            state.position_m, state.phi_rad = end, phi_end
    if m_word is not None:
        if m_word.value in (0, 1):
            pos, phi = _vec(state.position_m), state.phi_rad
            optional = m_word.value == 1
            program.segments.append(
                Segment(n, "pause", pos, pos, phi_start_rad=phi, phi_end_rad=phi, optional=optional)
            )
            program.notes.append(
                f"line {n}: M1 pauses the program when the optional stop is on (the check goes on)"
                if optional
                else f"line {n}: M0 pauses the program until Resume (the check goes on)"
            )
        else:
            state.ended = True


def interpret(
    lines: Iterable[Line],
    start_m,
    work_offset_m,
    start_phi_rad: float = 0.0,
    wrist: tuple[float, float] | None = None,
) -> Program:
    """Lines of words -> the program's segments, from the tool at ``start_m`` (3,) [m]
    with the G54 origin at ``work_offset_m`` (3,) [m], both in the base frame, and the
    wrist at ``start_phi_rad`` [rad]; ``wrist``: its limits (min, max) [rad], None when
    there is none (A is refused then).

    ``lines`` are taken one at a time (``tokens.iter_lines`` reads each when asked), so
    the first fault of a file by line is the one raised. Lines after M2 or M30 are read (a
    typo there is still refused) but not run. Percent lines (RS274/NGC): when the first
    line with anything but comments is ``%``, the program ends at the next ``%`` line and
    nothing after it is read; with no closing ``%`` (and no M2/M30 before the file's
    end) the file is refused at its last line. A ``%`` line in a file that does not open
    with one is a delimiter that does nothing. ``Program.lines``: the lines read.

    Raises:
        ProgramError: the first line that cannot be run, naming it and the word.
    """
    state = ModalState(
        np.array(start_m, dtype=np.float64),
        np.array(work_offset_m, dtype=np.float64),
        phi_rad=float(start_phi_rad),
        wrist=wrist,
    )
    program = Program()
    opened_at = 0  # the line of the opening % (0: none)
    content = False  # a line with words met
    closed = False
    for line in lines:
        program.lines = line.number
        if line.percent:
            if opened_at:
                closed = True
                break  # the useful contents stop here; the rest is not read
            if not content:
                opened_at = line.number
            continue
        content = content or bool(line.words)
        if state.ended:
            _collect(line, state.wrist is not None)
            continue
        step(state, line, program)
    # a lone % after nothing but comments, with nothing after it either, opens nothing
    if opened_at and content and not closed and not state.ended:
        raise ProgramError(
            program.lines,
            "",
            f"the file ends without the % line that closes the % on line {opened_at} "
            "(RS274/NGC: a program that opens with % ends with a % line; "
            "add one, or end the program with M2)",
        )
    return program


def work_offset_from_tool(tool_m, program_mm) -> tuple[float, float, float]:
    """The G54 origin [m] that makes the tool at ``tool_m`` (3,) [m] read ``program_mm``
    (3,) [mm] in the program (LinuxCNC's G10 L20 P1, 'set the current position as')."""
    offset = np.asarray(tool_m, dtype=np.float64) - np.asarray(program_mm, dtype=np.float64) * MM
    return _vec(offset)
