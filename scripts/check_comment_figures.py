#!/usr/bin/python3
"""Fails when a comment in native/ or addon/ quotes a measured figure (issue 84).

A comment says what the code does and why; a measurement lives in tests/bench/FINDINGS.md (or
docs/verification.md) and the comment names its heading. This reads C++ `//` and `/* */` comments
and Python `#` comments and docstrings, and reports each line where one of RULES matches, unless
the allow-list (scripts/comment_figures_allow.txt) lists it: a constant that genuinely is a
figure from a paper.

    /usr/bin/python3 scripts/check_comment_figures.py [--root DIR] [--allow FILE] [PATH ...]

PATHs (files or folders, relative to the root) default to native/ and addon/. Exit 0 when
nothing is found, 1 when something is (one `path:line: rule: text` line each), 2 on bad input.
"""

import argparse
import ast
import io
import os
import re
import sys
import tokenize

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_PATHS = ("native", "addon")
DEFAULT_ALLOW = os.path.join(HERE, "comment_figures_allow.txt")
CPP_SUFFIXES = (".h", ".hpp", ".cpp", ".cc", ".cxx", ".c")

# A number as a figure is written: 3, 0.8, 1e-3, 2,000 (not a digit inside a name such as x2 or 3D).
NUMBER = r"(?<![\w./])\d+(?:[.,]\d+)*(?:e[-+]?\d+)?"
# What a figure's number is most often written next to, for "measured … 2.4" within a few words.
WORDS_APART = 6
MEASURED = r"measur(?:ed|es|ing|ements?)"
# Beside "measured", a figure is a decimal or has two digits or more ("the measured track is 0" is none).
FIGURE = r"(?<![\w./])(?:\d+\.\d+|\d{2,})(?![\w³])"

# (name, pattern, what it catches). Each is searched in a comment block's text (lines joined with
# spaces), so a figure split over two lines is found; the hit is reported at the line it starts on.
RULES = [
    ("percentage", re.compile(NUMBER + r"\s?%(?![a-z{(])"),
     "a share such as 5.9 % or 25–35 % (not a printf format such as %d)"),
    ("ratio", re.compile(r"(?:(?<![\w.])\d+\.\d+\s?×|" + NUMBER + r"×(?!\s?\d))"),
     "a ratio such as 2.4× or 1.5 × (not a product 2 × the jitter or a size 96×64)"),
    ("seconds", re.compile(NUMBER + r"\s?(?:s|ms|min|minutes|seconds|hours|h)\b(?![-/·²³⁻(])"),
     "a timing such as 28 s, 17 ms or 2 hours (not a unit such as m/s or Pa·s)"),
    ("measured", re.compile(r"\b{m}\b(?:\W+\w+){{0,{k}}}?\W+{n}|{n}(?:\W+\w+){{0,{k}}}?\W+{m}\b".format(
        m=MEASURED, n=FIGURE, k=WORDS_APART), re.IGNORECASE),
     "'measured' within a few words of a number"),
    ("resolutions", "resolution_table",
     "a per-resolution table: two grid sizes such as 48³ … 64³ with figures beside them"),
]

RESOLUTION = re.compile(r"(?<![\w.])\d{2,3}³")
OTHER_NUMBER = re.compile(r"(?<![\w.])\d+(?:\.\d+)?(?![\d³])")


def resolution_table(text):
    """Where two grid sizes stand within 60 characters of each other with another number within 80."""
    sizes = list(RESOLUTION.finditer(text))
    for first, second in zip(sizes, sizes[1:]):
        if second.start() - first.end() <= 60:
            window = text[max(0, first.start() - 80):second.end() + 80]
            if OTHER_NUMBER.search(window):
                yield first.start()


# Numbers that are not figures: versions (Blender 3.4.1), issue and section numbers, years.
NOT_A_FIGURE = re.compile(r"(?<![\w.])\d+\.\d+\.\d+|\b(?:issue|issues|§|PR|#)\s?\d+|\b(?:19|20)\d\d\b")


def comment_lines_cpp(text):
    """(line, comment text) of every C++ comment line, skipping string and character literals."""
    out = []
    i, n, line = 0, len(text), 1
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            i += 1
        elif text.startswith("//", i):
            end = text.find("\n", i)
            end = n if end < 0 else end
            out.append((line, text[i + 2:end]))
            i = end
        elif text.startswith("/*", i):
            end = text.find("*/", i + 2)
            end = n if end < 0 else end
            for k, part in enumerate(text[i + 2:end].split("\n")):
                out.append((line + k, part.strip().lstrip("*")))
            line += text.count("\n", i, end)
            i = end + 2
        elif c == "R" and text.startswith('R"', i) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            open_paren = text.find("(", i)
            delimiter = text[i + 2:open_paren]
            end = text.find(")" + delimiter + '"', open_paren)
            end = n if end < 0 else end + len(delimiter) + 2
            line += text.count("\n", i, end)
            i = end
        elif c in "\"'":
            if c == "'" and i > 0 and text[i - 1].isalnum():  # a digit separator: 1'000'000
                i += 1
                continue
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            i = j + 1
        else:
            i += 1
    return out


def comment_lines_python(text, path):
    """(line, comment text) of every Python comment line and docstring line."""
    out = []
    try:
        for tok in tokenize.generate_tokens(io.StringIO(text).readline):
            if tok.type == tokenize.COMMENT:
                out.append((tok.start[0], tok.string[1:]))
        tree = ast.parse(text, path)
    except (SyntaxError, tokenize.TokenError) as exc:
        raise SystemExit("%s: cannot read it as Python: %s" % (path, exc))
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                    and isinstance(first.value.value, str)):
                for k, part in enumerate(first.value.value.split("\n")):
                    out.append((first.lineno + k, part))
    return sorted(out)


def blocks(lines):
    """Consecutive comment lines as one block each: [(line, text), ...]."""
    block = []
    for line, text in lines:
        if block and line != block[-1][0] + 1:
            yield block
            block = []
        if text.strip():
            block.append((line, text.strip()))
        elif block:
            yield block
            block = []
    if block:
        yield block


def hits_in(lines):
    """(line, rule, text) for each comment line where a rule matches."""
    found = {}
    for block in blocks(lines):
        joined, starts = "", []
        for line, text in block:
            starts.append((len(joined), line, text))
            joined += text + " "
        masked = NOT_A_FIGURE.sub(lambda m: "#" * len(m.group(0)), joined)
        for name, pattern, _ in RULES:
            found_at = (m.start() for m in pattern.finditer(masked)) if hasattr(pattern, "finditer") else \
                globals()[pattern](masked)
            for at in found_at:
                offset, line, text = max(s for s in starts if s[0] <= at)
                found.setdefault((line, name), text)
    return sorted((line, name, text) for (line, name), text in found.items())


def read_allow_list(path):
    """[(path, fragment, reason)] from `path | fragment | reason` lines (# starts a comment line)."""
    entries = []
    if not os.path.exists(path):
        return entries
    with open(path, encoding="utf-8") as fh:
        for number, raw in enumerate(fh, 1):
            if not raw.strip() or raw.lstrip().startswith("#"):
                continue
            parts = [p.strip() for p in raw.rstrip("\n").split(" | ")]
            if len(parts) != 3 or not all(parts):
                raise SystemExit("%s:%d: expected `path | line fragment | reason`" % (path, number))
            entries.append(tuple(parts))
    return entries


def source_files(root, paths):
    for rel in paths:
        full = os.path.join(root, rel)
        if os.path.isfile(full):
            yield full
            continue
        if not os.path.isdir(full):
            raise SystemExit("%s: no such file or folder" % full)
        for folder, dirs, files in os.walk(full):
            dirs[:] = sorted(d for d in dirs if d not in ("__pycache__", "build"))
            for name in sorted(files):
                if name.endswith(CPP_SUFFIXES + (".py",)):
                    yield os.path.join(folder, name)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("paths", nargs="*", default=list(DEFAULT_PATHS))
    parser.add_argument("--root", default=os.path.dirname(HERE))
    parser.add_argument("--allow", default=DEFAULT_ALLOW)
    args = parser.parse_args(argv)
    allow = read_allow_list(args.allow)
    used = set()
    reported = 0
    for path in source_files(args.root, args.paths):
        rel = os.path.relpath(path, args.root).replace(os.sep, "/")
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
        lines = comment_lines_python(text, rel) if path.endswith(".py") else comment_lines_cpp(text)
        for line, rule, comment in hits_in(lines):
            allowed = [k for k, (p, fragment, _) in enumerate(allow) if p == rel and fragment in comment]
            if allowed:
                used.update(allowed)
                continue
            print("%s:%d: %s: %s" % (rel, line, rule, comment))
            reported += 1
    for k, (p, fragment, _) in enumerate(allow):
        if k not in used and os.path.exists(os.path.join(args.root, p)) and any(
                os.path.join(args.root, p).startswith(os.path.join(args.root, q)) for q in args.paths):
            print("note: the allow-list entry %s | %s matches no comment" % (p, fragment), file=sys.stderr)
    if reported:
        print("%d comment line(s) quote a measured figure: say what the code does and why, and name the "
              "tests/bench/FINDINGS.md heading that holds the measurement (or list a paper's constant in %s)"
              % (reported, os.path.relpath(args.allow, args.root)), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
