"""G-code programs: parsed, planned into one timed path and verified in joint space
before anything moves (issue 18; the 2012 paper's section 3 runs its Deltas from G-code
under LinuxCNC with the path verified on a virtual robot).

- `errors.ProgramError`: a program that cannot be read (line, word, reason).
- `tokens.iter_lines` / `tokens.tokenize`: text -> lines of words, one at a time / as a
  list (comments, N numbers, whitespace removed; `%` lines marked).
- `modal.interpret`: our modal machine, words -> segments in the base frame [m, s]
  (percent lines: the program ends at the closing `%`).
- `segments.Segment`: one move, dwell or pause, and its geometry by arc length.
- `profile`: the jerk-limited rest-to-rest profile along a segment.
- `planner.plan_program`: segments -> `ProgramPath`, a timed path the run manager can run.
- `verify.verify_path`: every loop sample through the live loop's checks, all violations.
- `check.check_program`: text + settings -> `ProgramReport` (what the API and CLI give).
"""
