"""Hold-in-world: drone pose sources and the mode that keeps the tool fixed in the world."""
