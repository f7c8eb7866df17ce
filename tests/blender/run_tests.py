"""Runs the add-on's pytest suite inside Blender.

    blender -b --factory-startup --python-exit-code 1 --python tests/blender/run_tests.py -- [pytest args]

Blender's own argument parser stops at "--"; everything after it goes to pytest. The tests
import the add-on as the package "viscoscope" (a link to addon/ in a temporary folder), exactly
as it is named when installed from the zip.
"""

import os
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
# Blender's Python has no writable cache next to the repo in CI; keep pytest's cache out of the tree.
args = ["-p", "no:cacheprovider", "--rootdir", HERE, "-c", os.path.join(HERE, "pytest.ini")] + args
if not any(not a.startswith("-") and os.path.exists(a.split("::")[0]) for a in args):
    args.append(HERE)
raise SystemExit(pytest.main(args))
