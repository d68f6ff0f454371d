"""deltadash application: command line, and (later) the control server and its scene."""
