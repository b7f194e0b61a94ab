"""MkDocs hook: lay the package out as installed, so the API reference finds ``whiskerid.hw``.

The repository keeps the Raspberry Pi side in ``hw/`` and installs it as ``whiskerid.hw``
(``package-dir`` in pyproject.toml). The API reference reads the sources statically, so it is
given a folder that mirrors the installed layout: links to every entry of ``whiskerid/`` plus
``whiskerid/hw`` pointing at ``hw/``. The folder is under ``build/`` (ignored by git).
"""

import html as html_lib
import logging
import re
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


# --------------------------------------------------------------------------- math
# The math is turned into MathML here, at build time: browsers draw MathML themselves, so
# the site needs no script from the network (it is read offline, from a folder, as often as
# from a server) and shows no raw TeX while a renderer loads.
_MATH = re.compile(
    r'<(?P<tag>span|div) class="arithmatex">\s*(?:\\\((?P<inline>.*?)\\\)|\\\[(?P<block>.*?)\\\])'
    r"\s*</(?P=tag)>",
    re.DOTALL,
)
_LOG = logging.getLogger("mkdocs.plugins.whiskerid.math")


def on_page_content(html: str, page, **kwargs) -> str:
    """Replace every ``arithmatex`` span (inline) and div (display) by MathML."""
    from latex2mathml.converter import convert

    def mathml(m: re.Match) -> str:
        block = m.group("block") is not None
        tex = html_lib.unescape(m.group("block") if block else m.group("inline"))
        try:
            out = convert(tex.strip(), display="block" if block else "inline")
        except Exception as err:  # the converter raises its own kinds; the page names it
            _LOG.warning("%s: cannot render the math %r (%s)", page.file.src_path, tex, err)
            return m.group(0)
        return f'<div class="math">{out}</div>' if block else out

    return _MATH.sub(mathml, html)
