"""Run every command block of README.md and docs/*.md as a user would: page by page, in order.

Each page runs in a fresh temporary folder holding a copy of the repository's tracked files
(what a clone has: ``fits/``, ``examples/`` …) and ``.venv``, a link to the environment this
script runs in, with the project already installed (CI installs it in its first step with
the README's own command). The fenced ``bash`` blocks of the page run one after the other
under ``bash -euo pipefail`` (a failing command fails the page), ``whiskerid`` on ``PATH``
as after ``source .venv/bin/activate``. Whatever a block needs must have been made by an
earlier block of the same page, or be in the repository.

The README's first command sets up the environment and runs the demo in one line:
``python3 -m venv .venv && .venv/bin/pip install … && X``. Here the environment exists, so
that set-up prefix is dropped and ``X`` runs (the same install ran in CI's first step).

A block that cannot run here is marked, on the line right before its fence, with
``<!-- ci: skip (why) -->`` (real hardware on an I2C bus, a server that never returns, an
install of the project itself, the whole test suite). Use it sparingly: the reason is
printed with every run.

Usage::

    .venv/bin/python docs/run_blocks.py                 # every page
    .venv/bin/python docs/run_blocks.py docs/cli.md     # some pages
    .venv/bin/python docs/run_blocks.py --list          # the blocks, without running them

Prints one line per block (page, block number, first command, seconds) and exits 1 when a
block failed (its command, exit status and output's tail are printed). The run's files are
kept under ``--keep DIR`` if given (one folder per page), else removed.
"""

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGES = ["README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md"))]

_FENCE = re.compile(r"^```bash[ \t]*\n(.*?)^```[ \t]*$", re.M | re.S)
_SKIP = re.compile(r"<!--\s*ci:\s*skip\s*\((.+?)\)\s*-->\s*$")
# The README's one-line set-up: the environment is made already (see the module's docstring).
_SETUP = re.compile(
    r'^python3 -m venv \.venv && \.venv/bin/pip install -q -e "\.\[\w+\]" && ', re.M
)


@dataclass(frozen=True)
class Block:
    """One fenced ``bash`` block of a page."""

    page: str
    number: int  # 1-based, on its page
    line: int  # of the fence, 1-based
    text: str
    skip: str | None  # why it does not run here, or None

    @property
    def first(self) -> str:
        """The block's first command, for the listing."""
        lines = [s.strip() for s in self.text.splitlines()]
        return next((s for s in lines if s and not s.startswith("#")), "")


def blocks(page: str) -> list[Block]:
    """The ``bash`` blocks of ``page`` (a path relative to the repository), in order."""
    text = (ROOT / page).read_text(encoding="utf-8")
    out = []
    for n, m in enumerate(_FENCE.finditer(text), 1):
        before = text[: m.start()].rstrip("\n").rsplit("\n", 1)[-1]
        skip = _SKIP.search(before)
        line = text.count("\n", 0, m.start()) + 1
        out.append(Block(page, n, line, m.group(1), skip.group(1) if skip else None))
    return out


def _fresh_folder(where: Path) -> None:
    """A copy of the repository's tracked files, with ``.venv`` linked to this environment."""
    try:
        files = subprocess.run(
            ["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True
        ).stdout.decode()
        names = [f for f in files.split("\0") if f]
    except (OSError, subprocess.CalledProcessError):  # not a clone: everything but outputs
        skip = {".git", ".venv", "site", "build"}
        names = [
            str(p.relative_to(ROOT))
            for p in ROOT.rglob("*")
            if p.is_file() and not skip & set(p.relative_to(ROOT).parts)
        ]
    for name in names:
        src = ROOT / name
        if src.is_file():
            (where / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, where / name)
    (where / ".venv").symlink_to(Path(sys.prefix))


def run_page(page: str, keep: Path | None = None, say=print) -> list[tuple[Block, float, str]]:
    """Run the blocks of one page in a fresh folder; returns the failures (block, seconds,
    what went wrong), empty when every block ran."""
    failures = []
    with tempfile.TemporaryDirectory(prefix="whiskerid-docs-") as tmp:
        where = Path(tmp) if keep is None else keep / page.replace("/", "_")
        where.mkdir(parents=True, exist_ok=True)
        _fresh_folder(where)
        env = dict(os.environ)
        env["PATH"] = f"{where / '.venv' / 'bin'}{os.pathsep}{env.get('PATH', '')}"
        env["VIRTUAL_ENV"] = str(where / ".venv")
        env.setdefault("MPLBACKEND", "Agg")
        for b in blocks(page):
            if b.skip:
                say(f"{page} #{b.number} (line {b.line}) skipped: {b.skip}")
                continue
            text = _SETUP.sub("", b.text)
            if "-m venv" in text or "pip install" in text:
                # .venv here is the environment this runs in: never rebuild or reinstall it
                why = "installs into .venv: mark the block <!-- ci: skip (why) -->"
                failures.append((b, 0.0, why))
                say(f"{page} #{b.number} (line {b.line}) FAILED: {why}")
                break
            start = time.perf_counter()
            done = subprocess.run(
                ["bash", "-euo", "pipefail", "-c", text],
                cwd=where,
                env=env,
                capture_output=True,
                text=True,
                stdin=subprocess.DEVNULL,
            )
            took = time.perf_counter() - start
            say(f"{page} #{b.number} (line {b.line}) {took:6.1f} s  {b.first[:70]}")
            if done.returncode != 0:
                tail = (done.stdout + done.stderr)[-2000:]
                failures.append((b, took, f"exit {done.returncode}\n{tail}"))
                say(f"  FAILED (exit {done.returncode}):\n{tail}")
                break  # later blocks of the page build on this one
    return failures


def main(argv: list[str] | None = None) -> int:
    """The command line (see the module's docstring)."""
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("pages", nargs="*", default=PAGES, help="pages to run (default: all)")
    p.add_argument("--list", action="store_true", help="list the blocks, run nothing")
    p.add_argument("--keep", type=Path, help="keep each page's folder under this one")
    args = p.parse_args(argv)
    if args.list:
        for page in args.pages:
            for b in blocks(page):
                why = f"  [skip: {b.skip}]" if b.skip else ""
                print(f"{page} #{b.number} (line {b.line}): {b.first[:70]}{why}")
        return 0
    start = time.perf_counter()
    failed = [f for page in args.pages for f in run_page(page, args.keep)]
    print(f"{len(args.pages)} pages in {time.perf_counter() - start:.0f} s; {len(failed)} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
