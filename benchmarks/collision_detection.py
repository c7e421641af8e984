"""Detection cost per step of the collision runtime against the number of elements (1e2 to 1e5
triangles and as many points), at SOFA's default tree depth 6 and at depths 12 and 17.

    python benchmarks/collision_detection.py

Compiles benchmarks/collision_detection.cpp against runtime/sofac with the scenes' flags (-O2,
-ffp-contract=off) and prints one line per size and depth: time per step (leaf boxes + refit of
both trees, traversal, element tests), element tests run, contacts found.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from sofac.build.compiler import eigen_include
from sofac.resources import resource_dir

HERE = Path(__file__).resolve().parent


def main() -> int:
    compiler = shutil.which("g++")
    if compiler is None:
        print("g++ is not installed", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as folder:
        binary = Path(folder) / "collision_detection"
        command = [compiler, "-std=c++17", "-O2", "-ffp-contract=off", f"-I{resource_dir('runtime')}"]
        command += [f"-I{eigen_include()}", str(HERE / "collision_detection.cpp"), "-o", str(binary)]
        subprocess.run(command, check=True)
        subprocess.run([str(binary)], check=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
