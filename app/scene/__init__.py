"""The operator's 3D scene (viser): robot, workspace, goals, control and test panels.

``Scene`` (scene.py) is started by the app's lifespan after the controller; the pure
geometry it draws lives in geometry.py and volume.py so tests can check it without viser.
"""

from app.scene.scene import Scene, start_scene

__all__ = ["Scene", "start_scene"]
