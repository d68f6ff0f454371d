"""Test runs: trajectories as goal sources, feasibility checks, logs, statistics, reports."""
