#!/usr/bin/env python3
"""Checks that the CLI and the Python extension resolve displace-core
identically, so that Cargo builds the tracer once and both link the same
machine code.

Why: Cargo compiles a crate once per resolved set of features of everything
below it. When the CLI (its GPU stack) and the extension (PyO3) turned on
different features of crates under displace-core (glam's ``bytemuck``,
syn's ``extra-traits``, ...), displace-core was compiled twice and LLVM
inlined its packet tracer differently in each build: the extension traced
the same rays 10-20 % slower than ``displace trace``. The crate
``crates/displace-workspace-hack`` asks for the union of those features in
both programs; this script, run by ``scripts/test.sh``, fails when the two
resolutions drift apart again (a new dependency, a feature turned on), and
names the packages and features to add to that crate's manifest.

How: ``cargo tree -e normal,build --no-dedupe`` of each program, the
subtree under its first ``displace-core`` taken as (package, features)
pairs, the two sets compared. It reads ``Cargo.lock`` only: no build.

Usage (from anywhere in the repository): ``python3 scripts/check_same_core.py``
"""

import os
import re
import subprocess
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PROGRAMS = ("displace-cli", "displace-python")
CORE = "displace-core"
HACK = "crates/displace-workspace-hack/Cargo.toml"
LINE = re.compile(r"^(\d+)(\S+) (v\S+)(?: \([^)]*\))?(?: \(\*\))? ?(.*)$")


def core_subtree(package):
    """The set of (name version, features) below displace-core in
    ``package``'s resolved tree."""
    p = subprocess.run(
        ["cargo", "tree", "--locked", "-p", package, "-e", "normal,build", "--prefix", "depth",
         "-f", "{p} {f}", "--no-dedupe"],
        cwd=REPO, capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"check_same_core: cargo tree -p {package} failed:\n{p.stderr.strip()}")
    inside, found = None, set()
    for n, raw in enumerate(p.stdout.splitlines(), 1):
        m = LINE.match(raw.strip())
        if not m:
            sys.exit(f"check_same_core: cargo tree -p {package}, line {n}: unexpected {raw!r}")
        depth, name, version, features = int(m[1]), m[2], m[3], m[4].strip()
        if inside is None:
            if name == CORE:
                inside = depth
            continue
        if depth <= inside:
            break
        found.add((f"{name} {version}", features))
    if inside is None:
        sys.exit(f"check_same_core: {package} does not depend on {CORE}")
    return found


def main():
    trees = {p: core_subtree(p) for p in PROGRAMS}
    a, b = PROGRAMS
    only = {a: trees[a] - trees[b], b: trees[b] - trees[a]}
    if not only[a] and not only[b]:
        print(f"check_same_core: {a} and {b} resolve {CORE} identically "
              f"({len(trees[a])} packages below it)")
        return 0
    print(f"check_same_core: {a} and {b} resolve {CORE} differently, so Cargo builds it twice "
          f"and the two programs trace with different machine code.", file=sys.stderr)
    for prog in PROGRAMS:
        for pkg, feats in sorted(only[prog]):
            print(f"  only in {prog}: {pkg} [{feats or 'no features'}]", file=sys.stderr)
    print(f"Add the union of those packages' features to {HACK} "
          f"(its comment says why).", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
