#!/usr/bin/env python3
"""Build the installable add-on zip: viscoscope/ (addon/ + blender_manifest.toml + bin/viscoscope +
scripts/, the engine's helper scripts).

    python3 scripts/build_addon_zip.py [--engine build/bin/viscoscope | --no-engine] [--out DIR_OR_ZIP]

The same zip installs as a legacy add-on (Blender 3.4: Preferences > Add-ons > Install) and as an
extension (Blender 4.2+: the manifest sits next to __init__.py in the single top-level folder).
The build fails when bl_info's version and the manifest's version differ.
"""

import argparse
import ast
import os
import re
import sys
import zipfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ADDON = os.path.join(REPO, "addon")
MANIFEST = os.path.join(REPO, "blender_manifest.toml")
PACKAGE = "viscoscope"
# Helper scripts the engine runs (plots, synthetic references). It looks for them in scripts/ of the
# nearest folder above its executable (native/src/cli/scripts.cpp): viscoscope/scripts/ for bin/viscoscope.
ENGINE_SCRIPTS = ("plot_identification.py", "plot_diagnosis.py", "render_reference.py")


def bl_info_version(init_path=os.path.join(ADDON, "__init__.py")):
    tree = ast.parse(open(init_path, encoding="utf-8").read())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "bl_info" for t in node.targets):
            return ".".join(str(v) for v in ast.literal_eval(node.value)["version"])
    raise SystemExit("error: no bl_info in %s" % init_path)


def manifest_version(path=MANIFEST):
    text = open(path, encoding="utf-8").read()
    try:
        import tomllib
        return tomllib.loads(text)["version"]
    except ImportError:
        return re.search(r'^version\s*=\s*"([^"]+)"', text, re.M).group(1)


def build(out, engine=None):
    version = bl_info_version()
    if manifest_version() != version:
        raise SystemExit("error: bl_info version %s != blender_manifest.toml version %s" % (version, manifest_version()))
    if os.path.isdir(out) or not out.endswith(".zip"):
        os.makedirs(out, exist_ok=True)
        out = os.path.join(out, "%s-%s.zip" % (PACKAGE, version))
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    tmp = out + ".part"
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for root, dirs, files in os.walk(ADDON):
            dirs[:] = sorted(d for d in dirs if d not in ("__pycache__", "bin"))
            for name in sorted(files):
                if name.endswith((".pyc", ".pyo")):
                    continue
                path = os.path.join(root, name)
                zf.write(path, os.path.join(PACKAGE, os.path.relpath(path, ADDON)))
        zf.write(MANIFEST, os.path.join(PACKAGE, "blender_manifest.toml"))
        if engine:
            if not (os.path.isfile(engine) and os.access(engine, os.X_OK)):
                raise SystemExit("error: engine is not an executable file: %s" % engine)
            info = zipfile.ZipInfo(os.path.join(PACKAGE, "bin", "viscoscope"))
            info.external_attr = (0o100755 << 16)
            info.compress_type = zipfile.ZIP_DEFLATED
            with open(engine, "rb") as fh:
                zf.writestr(info, fh.read())
            for name in ENGINE_SCRIPTS:
                zf.write(os.path.join(REPO, "scripts", name), os.path.join(PACKAGE, "scripts", name))
    os.replace(tmp, out)
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--engine", default=os.path.join(REPO, "build", "bin", "viscoscope"),
                        help="engine executable to bundle (default: build/bin/viscoscope)")
    parser.add_argument("--no-engine", action="store_true", help="build without the engine binary")
    parser.add_argument("--out", default=os.path.join(REPO, "build"), help="output folder or .zip path")
    args = parser.parse_args(argv)
    out = build(args.out, None if args.no_engine else args.engine)
    print(out)


if __name__ == "__main__":
    sys.exit(main())
