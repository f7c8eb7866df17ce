#!/usr/bin/python3
"""The comment-figure check can fail: planted figures in a temporary tree are each reported and the
check exits 1; ordinary explanations, strings and allow-listed lines pass with exit 0.

    /usr/bin/python3 scripts/test_check_comment_figures.py
"""

import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
CHECK = os.path.join(HERE, "check_comment_figures.py")

PLANTED_CPP = """\
// The coarse grid drained 1.5× too fast.
int a = 0;  // sat 25–35 % above the truth
/* a full-fidelity generation took
   120–135 s at η = 10 */
// the drain by frame 8 was 0.185 / 0.168 / 0.150 at 48³ / 64³ / 96³
int c = 2;
// we measured the flux
// at 0.94 of Dagan's.
"""
PLANTED_PY = '''\
"""A module whose docstring quotes a figure: the bake took 28 s."""
x = 1  # within 5.9 % of the truth
'''
CLEAN_CPP = """\
// The first 2 cells along x, n ≤ 1, a 3 × 3 matrix, Δt of the step, an array of 96×64 pixels.
const char* format = "%d of %d: 50 % off";  // a printf format, and a string that is no comment
const char* url = "http://example.com/48³";
// the measured track is 0 until the liquid shows; η in Pa·s, ν in m²/s, rates in s⁻¹
// (tests/bench/FINDINGS.md, "The coarse phase") on Blender 3.4.1, issue 84.
int b = 1'000;  // a digit separator
// A paper's constant: 0.894 × (ρ g V³ t / 3μ)^(1/8), within 2 % of Huppert's experiments.
"""
CLEAN_PY = '''\
"""Exports the scene; fps 30 frames, resolution 64."""
text = "12 % of the liquid"  # a string, not a comment
'''
ALLOW = """\
# path | line fragment | reason
native/clean.cpp | within 2 % of Huppert's | Huppert 1982's own agreement with experiment, a paper's figure
"""


def run(root, *args):
    return subprocess.run([sys.executable, CHECK, "--root", root, "--allow", os.path.join(root, "allow.txt")]
                          + list(args), capture_output=True, text=True)


def write(root, rel, text):
    path = os.path.join(root, rel)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)


def main():
    failures = []
    with tempfile.TemporaryDirectory() as root:
        write(root, "allow.txt", ALLOW)
        write(root, "native/planted.cpp", PLANTED_CPP)
        write(root, "addon/planted.py", PLANTED_PY)
        write(root, "native/clean.cpp", CLEAN_CPP)
        write(root, "addon/clean.py", CLEAN_PY)

        planted = run(root, "native/planted.cpp", "addon/planted.py")
        if planted.returncode != 1:
            failures.append("planted figures: exit %d, expected 1" % planted.returncode)
        expected = ["native/planted.cpp:1: ratio", "native/planted.cpp:2: percentage",
                    "native/planted.cpp:4: seconds", "native/planted.cpp:5: resolutions",
                    "native/planted.cpp:7: measured", "addon/planted.py:1: seconds",
                    "addon/planted.py:2: percentage"]
        for hit in expected:
            if hit not in planted.stdout:
                failures.append("planted figures: %r not reported in:\n%s" % (hit, planted.stdout))

        clean = run(root, "native/clean.cpp", "addon/clean.py")
        if clean.returncode != 0:
            failures.append("clean files: exit %d, expected 0:\n%s%s" % (clean.returncode, clean.stdout, clean.stderr))

        write(root, "allow.txt", "# empty\n")
        unlisted = run(root, "native/clean.cpp")
        if unlisted.returncode != 1 or "native/clean.cpp:7: percentage" not in unlisted.stdout:
            failures.append("without its allow-list entry, the paper's figure passed: exit %d\n%s"
                            % (unlisted.returncode, unlisted.stdout))

        write(root, "allow.txt", "native/clean.cpp | a fragment without a reason\n")
        bad = run(root, "native/clean.cpp")
        if bad.returncode == 0:
            failures.append("a malformed allow-list entry was accepted")
    for failure in failures:
        print("FAIL:", failure)
    print("%d failure(s)" % len(failures))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
