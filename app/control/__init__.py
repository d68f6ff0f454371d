"""The control loop: timing, the goal gate, motion sources and the controller that owns them."""
