"""The engine's parameter declarations and diagnosable effects, as `viscoscope schema` prints them
into engine_schema.json.

The panel's bounds and defaults, the job's search bounds and the grid the cup's hole needs come
from here, never from numbers copied out of the engine; tests/blender/test_contract.py fails when
this file and the engine's declarations differ. Regenerate it with
`build/bin/viscoscope schema > addon/engine_schema.json`.
"""

import json
import os

with open(os.path.join(os.path.dirname(__file__), "engine_schema.json"), encoding="utf-8") as _fh:
    SCHEMA = json.load(_fh)

PARAMETERS = {p["name"]: p for p in SCHEMA["parameters"]}
# The effects `viscoscope diagnose` can add, in the order it fits them: name, description, source.
EFFECTS = SCHEMA["effects"]
MIN_HOLE_CELLS = SCHEMA["min_hole_cells"]


def bounds(name):
    """(lower, upper) of a declared parameter, in its SI unit."""
    p = PARAMETERS[name]
    return p["lower"], p["upper"]


def search_bounds(name):
    """The job's default search bounds of a searchable parameter."""
    search = PARAMETERS[name]["search"]
    return search["lower"], search["upper"]


def default(name, fallback):
    """The declared default, or `fallback` for a parameter the scene must give."""
    value = PARAMETERS[name]["default"]
    return fallback if value is None else value


def float_property_args(name, fallback_default):
    """name/description/default/min/max for a FloatProperty holding a declared parameter."""
    p = PARAMETERS[name]
    return {"name": "%s (%s)" % (p["symbol"], p["unit"]) if p["unit"] != "1" else p["symbol"],
            "description": "%s, %s" % (p["description"], p["unit"]),
            "default": default(name, fallback_default), "min": p["lower"], "max": p["upper"]}
