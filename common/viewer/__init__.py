"""What the browser map and Foxglove draw, and the page (static/, shipped as package data).

- scene: the viewer's scene model, computed from a mission and the messages of a run.
- foxglove: the same run as Foxglove channels.
"""
