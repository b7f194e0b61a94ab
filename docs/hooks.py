"""MkDocs hook: lay the package out as installed, so the API reference finds ``whiskerid.hw``.

The repository keeps the Raspberry Pi side in ``hw/`` and installs it as ``whiskerid.hw``
(``package-dir`` in pyproject.toml). The API reference reads the sources statically, so it is
given a folder that mirrors the installed layout: links to every entry of ``whiskerid/`` plus
``whiskerid/hw`` pointing at ``hw/``. The folder is under ``build/`` (ignored by git).
"""

import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LAYOUT = ROOT / "build" / "api-src"


def on_startup(**kwargs) -> None:
    """Rebuild the installed-layout folder of links before anything reads the sources."""
    shutil.rmtree(LAYOUT, ignore_errors=True)
    pkg = LAYOUT / "whiskerid"
    pkg.mkdir(parents=True)
    for entry in (ROOT / "whiskerid").iterdir():
        if entry.name != "__pycache__":
            (pkg / entry.name).symlink_to(entry)
    (pkg / "hw").symlink_to(ROOT / "hw")
