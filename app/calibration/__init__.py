"""Kinematic calibration (issue 20): the guided procedure over ``kinematics.identification``.

``fit.py`` plans poses and fits (pure: NumPy and scipy), ``pairs.py`` reads and writes
joint/measurement pairs as CSV, ``report.py`` draws the residual plot, ``procedure.py``
runs a calibration on the robot (moves, rests, measures, fits) and keeps the runs.
"""
