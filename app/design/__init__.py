"""Reports and figures of ``deltadash design`` (kept out of the pure kinematics)."""
