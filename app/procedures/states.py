"""The states of a procedure's run (the API's ``state`` strings) and which are running.

A run is ``planned`` when it starts, goes through its procedure's running states in
order, and ends ``done``, ``refused`` (a calibration whose fit is worse than the model in
use: never applied), ``failed`` (its ``error`` says why) or ``aborted`` (the operator's
abort); a done run may become ``applied``. The running states are those an abort stops,
in the order a run goes through them (a progress bar counts them: ``deltadash tune``).
"""

from __future__ import annotations

from enum import StrEnum


class State(StrEnum):
    """A run's state; equal to (and serialised as) its string, e.g. ``"planned"``."""

    PLANNED = "planned"
    MOVING = "moving"
    STEP = "step"  # tuning: recording its step run
    CHIRP = "chirp"  # tuning: recording its chirp run
    FITTING = "fitting"
    CHECKING = "checking"  # tuning: the candidate gains checked on the twin
    DONE = "done"
    REFUSED = "refused"
    FAILED = "failed"
    ABORTED = "aborted"
    APPLIED = "applied"


# each procedure's running states, in order (tuples: compared with ==, so plain strings
# read back from JSON are found too)
CALIBRATION_RUNNING: tuple[State, ...] = (State.PLANNED, State.MOVING, State.FITTING)
TUNING_RUNNING: tuple[State, ...] = (
    State.PLANNED,
    State.MOVING,
    State.STEP,
    State.CHIRP,
    State.FITTING,
    State.CHECKING,
)
ENDED: tuple[State, ...] = (State.DONE, State.REFUSED, State.FAILED, State.ABORTED)
