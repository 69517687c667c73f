"""Calibration and studies, free of ROS: impacts identified in a recording (``identify``),
scene parameters fitted to it (``fit``) and many runs of a scene with values changed
(``study``). Built on ``physics``."""

# its modules are imported by name: the package itself exports none
__all__: list[str] = []
