"""Check that every runtime dependency of ``whiskerid[pi]`` has a wheel for a Raspberry Pi.

Asks the package index, as ``pip`` on the Pi would, for binary wheels only, for 64-bit
Raspberry Pi OS (Bookworm: aarch64, glibc 2.36, CPython 3.11), resolving the dependencies of
the dependencies too. Prints one line per wheel found and exits 1 naming what has none (that
package would have to be compiled on the Pi, or cannot be installed at all). Needs network
access to the index; it downloads the wheels into a temporary folder and deletes them.

    python hw/check_pi_wheels.py                  # Raspberry Pi OS 64-bit, Python 3.11
    python hw/check_pi_wheels.py --python 3.12    # another Python
    python hw/check_pi_wheels.py --platform armv7l  # 32-bit Raspberry Pi OS: expect failures
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parent.parent / "pyproject.toml"

#: glibc of the Raspberry Pi OS release, by its newest manylinux tag (Bookworm: 2.36).
GLIBC_MINOR = 36


def runtime_requirements(pyproject: Path = PYPROJECT, extra: str = "pi") -> list[str]:
    """The project's dependencies plus those of ``extra`` (other extras it names included)."""
    project = tomllib.loads(pyproject.read_text())["project"]
    extras = project.get("optional-dependencies", {})
    reqs = list(project["dependencies"])
    todo, seen = [extra], set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        for req in extras.get(name, []):
            m = re.fullmatch(rf"{project['name']}\[(.+)\]", req.replace(" ", ""))
            if m:
                todo.extend(m.group(1).split(","))
            else:
                reqs.append(req)
    return reqs


def platform_tags(arch: str) -> list[str]:
    """pip ``--platform`` tags a Raspberry Pi OS of this architecture accepts."""
    if arch == "aarch64":
        many = [f"manylinux_2_{m}_aarch64" for m in range(GLIBC_MINOR, 16, -1)]
        return [*many, "manylinux2014_aarch64", "linux_aarch64"]
    if arch == "armv7l":
        many = [f"manylinux_2_{m}_armv7l" for m in range(GLIBC_MINOR, 16, -1)]
        return [*many, "manylinux2014_armv7l", "linux_armv7l"]
    raise ValueError(f"unknown architecture {arch!r}; use aarch64 or armv7l")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--python", default="3.11", help="Python version on the Pi (3.11)")
    p.add_argument("--platform", default="aarch64", choices=("aarch64", "armv7l"),
                   help="aarch64: 64-bit Raspberry Pi OS; armv7l: 32-bit")  # fmt: skip
    p.add_argument("--extra", default="pi", help="the extra installed on the Pi (pi)")
    args = p.parse_args(argv)
    reqs = runtime_requirements(extra=args.extra)
    plat = [a for tag in platform_tags(args.platform) for a in ("--platform", tag)]
    print(f"whiskerid[{args.extra}] on {args.platform}, CPython {args.python}: "
          f"{', '.join(reqs)}", flush=True)  # fmt: skip
    with tempfile.TemporaryDirectory() as dest:
        cmd = [sys.executable, "-m", "pip", "download", "--only-binary=:all:", *plat,
               "--python-version", args.python, "--implementation", "cp", "--dest", dest,
               "--progress-bar", "off", *reqs]  # fmt: skip
        done = subprocess.run(cmd, capture_output=True, text=True)
        wheels = sorted(f.name for f in Path(dest).iterdir())
    for name in wheels:
        print(f"  ok  {name}")
    if done.returncode != 0:
        missing = re.findall(r"(?:No matching distribution found for|"
                             r"Could not find a version that satisfies the requirement) (\S+)",
                             done.stderr)  # fmt: skip
        print(f"NO WHEEL: {', '.join(dict.fromkeys(missing)) or '(see pip output below)'}")
        print(done.stderr.strip()[-2000:], file=sys.stderr)
        return 1
    print(f"all {len(wheels)} wheels found: pip install '.[{args.extra}]' needs no compiler")
    return 0


if __name__ == "__main__":
    sys.exit(main())
