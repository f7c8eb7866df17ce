#!/usr/bin/python3
r"""Every path into the engine under mutation, this engine against another, side by side.

Runs the mutation corpora of tests/native/cli_fuzz_test.cpp (scene, job, camera, track CSV, clip,
reference, solid mesh, resume state, checkpoint; VISCOSCOPE_FUZZ_MUTANTS mutants each, half as many
for those that simulate) against each engine given, through VISCOSCOPE_FUZZ_ENGINE, and prints per
corpus and engine how the mutants ended: accepted (exit 0 with the result written), refused in one
line (exit 2), and each broken promise: exit 0 without the result file, exit 1, a crash (a signal),
a hang (killed after the corpus's time limit), exit 2 on several lines. A misspelt key the engine
accepted is counted apart: it was silently ignored.

    /usr/bin/python3 tests/bench/hostile_inputs.py --mutants 200 --before /tmp/before_build/bin/viscoscope
"""
import argparse
import collections
import os
import pathlib
import re
import subprocess

ROOT = pathlib.Path(__file__).resolve().parents[2]
FUZZ_TEST = ROOT / "build/tests/native/cli_fuzz_test"
ENGINE = ROOT / "build/bin/viscoscope"

FUZZ_LINE = re.compile(r"^\[ fuzz     \] (\S+):((?: \d+ × exit -?\d+)*)")
OUTCOME = re.compile(r"(\d+) × exit (-?\d+)")
ACCEPTED = re.compile(r"^\[ accepted \] (\S+) with .* misspelt ")
# A broken promise as the test reports it: "FILE with MUTATION: exit N, stderr: …" or "…: exit 0 without …".
FAILURE = re.compile(r"^(\S+) with .*?: exit (-?\d+)(,| without)")


def kind(code, how):
    if how == " without":
        return "exit 0, no result"
    code = int(code)
    if code == 137:
        return "hang"
    if code >= 128 or code < 0:
        return "crash"
    if code == 2:
        return "exit 2, several lines"
    return "exit %d" % code


def run_corpora(engine, mutants):
    env = dict(os.environ, VISCOSCOPE_FUZZ_ENGINE=str(engine), VISCOSCOPE_FUZZ_MUTANTS=str(mutants))
    out = subprocess.run([str(FUZZ_TEST), "--gtest_filter=Fuzz.Mutated*"], env=env, capture_output=True,
                         text=True, errors="replace").stdout
    outcomes, broken, ignored = {}, collections.defaultdict(collections.Counter), collections.Counter()
    for line in out.splitlines():
        if m := FUZZ_LINE.match(line):
            outcomes[m.group(1)] = {int(code): int(count) for count, code in OUTCOME.findall(m.group(2))}
        elif m := ACCEPTED.match(line):
            ignored[pathlib.Path(m.group(1)).name] += 1
        elif m := FAILURE.match(line):
            broken[pathlib.Path(m.group(1)).name][kind(m.group(2), m.group(3))] += 1
    return outcomes, broken, ignored


def corpus_of(name, outcomes):
    """The corpus a failing file belongs to (a reference's manifest or mask is the 'reference' one)."""
    return name if name in outcomes else "reference"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mutants", type=int, default=100)
    parser.add_argument("--before", type=pathlib.Path, help="another engine, run on the same corpora")
    args = parser.parse_args()
    engines = [("now", ENGINE)] + ([("before", args.before)] if args.before else [])
    print("| corpus | engine | mutants | accepted | refused in one line | broken promises | misspelt keys ignored |")
    print("|---|---|---|---|---|---|---|")
    results = {label: run_corpora(engine, args.mutants) for label, engine in engines}
    corpora = sorted(set().union(*(r[0].keys() for r in results.values())))
    for corpus in corpora:
        for label, _ in engines:
            outcomes, broken, ignored = results[label]
            counts = outcomes.get(corpus, {})
            failures = collections.Counter()
            for name, kinds in broken.items():
                if corpus_of(name, outcomes) == corpus:
                    failures.update(kinds)
            accepted = counts.get(0, 0) - failures["exit 0, no result"]
            refused = counts.get(2, 0) - failures["exit 2, several lines"]
            shown = ", ".join("%d %s" % (n, k) for k, n in sorted(failures.items())) or "none"
            misspelt = sum(n for name, n in ignored.items() if corpus_of(name, outcomes) == corpus)
            print("| %s | %s | %d | %d | %d | %s | %d |" % (corpus, label, sum(counts.values()), accepted, refused,
                                                          shown, misspelt))


if __name__ == "__main__":
    main()
