"""Servo identification and gain tuning (issue 21): models of each joint's response fitted to
the project's step and chirp runs (`identify`)."""
