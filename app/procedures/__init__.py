"""The guided procedures' one lifecycle (calibration, tuning, and whatever comes next).

``states.py`` names the states a procedure's run goes through and which of them are
running, per procedure (light: the command line reads it); ``lifecycle.py`` runs one
procedure at a time on the robot: the claim, the thread, start, abort, the ending, close.
A procedure supplies only its steps (app/calibration/procedure.py, app/tuning/procedure.py).
"""
