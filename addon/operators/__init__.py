"""Operators, one module per section of the panel; each operator does one user action."""

from . import camera, container, diagnose, fluid, identify, reference, runner, silhouettes, simulate

modules = (runner, reference, camera, container, silhouettes, identify, diagnose, fluid, simulate)
classes = tuple(cls for module in modules for cls in module.classes)
