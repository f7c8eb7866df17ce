"""Operators, one module per section of the panel; each operator does one user action."""

from . import (camera, container, diagnose, fluid, identify, mantaflow_calibration, reference, runner, silhouettes,
               simulate)

modules = (runner, reference, camera, container, silhouettes, identify, diagnose, fluid, mantaflow_calibration,
           simulate)
classes = tuple(cls for module in modules for cls in module.classes)
