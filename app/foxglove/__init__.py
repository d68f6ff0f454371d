"""The station's Foxglove live server (docs/foxglove.md): live.py (the server and its
thread), messages.py (a snapshot to the channels' messages), front.py (the token's door),
layout.py (the shipped layout, docs/foxglove/deltadash.json)."""

from app.foxglove.live import FoxgloveLive, start_foxglove

__all__ = ["FoxgloveLive", "start_foxglove"]
