"""How the package imports: ``--help`` without JAX, and no module importing its package back."""

import ast
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

import whiskerid as wi
from whiskerid import _choices

# Every command's --help, and the bare command's; each must leave JAX unloaded.
HELP_ARGVS = [
    [],
    ["demo"],
    ["simulate"],
    ["calibrate"],
    ["posterior"],
    ["dataset"],
    ["dataset", "synth"],
    ["train"],
    ["evaluate"],
    ["classify"],
    ["record"],
    ["stream"],
]

_PROBE = """
import contextlib, io, json, sys
import whiskerid
loaded = {"import whiskerid": "jax" in sys.modules}
from whiskerid.cli import main
for argv in json.loads(sys.argv[1]):
    with contextlib.redirect_stdout(io.StringIO()) as out:
        try:
            main([*argv, "--help"])
        except SystemExit:
            pass
    assert "usage: whiskerid" in out.getvalue(), argv
    loaded[" ".join(["whiskerid", *argv, "--help"])] = "jax" in sys.modules
print(json.dumps(loaded))
"""


def test_help_does_not_import_jax():
    # One fresh interpreter for all: once loaded, JAX would stay in sys.modules, so the
    # first command that imports it is the first one reported True.
    proc = subprocess.run(
        [sys.executable, "-c", _PROBE, json.dumps(HELP_ARGVS)],
        capture_output=True,
        text=True,
        check=True,
    )
    loaded = json.loads(proc.stdout)
    assert len(loaded) == 1 + len(HELP_ARGVS)
    assert [name for name, jax in loaded.items() if jax] == []


def _module_files() -> dict[str, Path]:
    """Every module of the installed package by dotted name (``whiskerid.hw`` lives in hw/)."""
    roots = {
        "whiskerid": Path(wi.__file__).parent,
        "whiskerid.hw": Path(importlib.util.find_spec("whiskerid.hw").origin).parent,
    }
    files = {}
    for package, root in roots.items():
        for path in root.rglob("*.py"):
            parts = [*package.split("."), *path.relative_to(root).with_suffix("").parts]
            if parts[-1] == "__init__":
                parts.pop()
            files[".".join(parts)] = path
    return files


def _own_package_imports(name: str, path: Path, modules) -> list[str]:
    """Names ``name`` imports from its own package's ``__init__`` or the top-level one's."""
    is_package = path.name == "__init__.py"
    package = name if is_package else name.rpartition(".")[0]
    wrong = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            wrong += [a.name for a in node.names if a.name == "whiskerid"]
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level:
            base = package.split(".")[: len(package.split(".")) - node.level + 1]
            target = ".".join([*base, *([node.module] if node.module else [])])
        else:
            target = node.module
        if target in (package, "whiskerid"):
            wrong += [
                f"from {target} import {a.name}"
                for a in node.names
                if f"{target}.{a.name}" not in modules
            ]
    return wrong


def test_no_module_imports_its_package_init_back():
    modules = _module_files()
    assert {"whiskerid.cli._main", "whiskerid.hw._stream", "whiskerid.model"} <= set(modules)
    wrong = {
        name: found
        for name, path in sorted(modules.items())
        if (found := _own_package_imports(name, path, modules))
    }
    assert wrong == {}


@pytest.mark.parametrize(
    ("source", "wrong"),
    [
        ("from . import _sibling", []),
        ("from . import helper", ["from whiskerid.model import helper"]),
        ("from .. import __version__", ["from whiskerid import __version__"]),
        ("from .. import _version", []),
        ("import whiskerid", ["whiskerid"]),
        ("from ..fit import calibrate", []),
    ],
)
def test_the_scan_finds_imports_of_a_package_init(tmp_path, source, wrong):
    path = tmp_path / "_mod.py"
    path.write_text(source + "\n")
    modules = {"whiskerid._version", "whiskerid.model._sibling", "whiskerid.model._mod"}
    assert _own_package_imports("whiskerid.model._mod", path, modules) == wrong


def test_choices_agree_with_the_terrain_simulator():
    # The command line lists terrains and speeds from _choices, without importing the simulator.
    assert (wi.TERRAINS, wi.SPEEDS_MPS) == (_choices.TERRAINS, _choices.SPEEDS_MPS)
