"""Griffe extensions for the API reference.

* :class:`RedundantAliasIsPublic`: a name re-exported as ``from ._mod import X as X`` is
  public. Each sub-package's ``__init__.py`` lists its public names that way (the convention
  of optimistix and equinox, and what type checkers read as an explicit re-export); the API
  reference documents exactly those names.
* :class:`SphinxRolesToLinks`: the docstrings cross-reference with Sphinx roles
  (``:func:`name```); Markdown has no such syntax, so each becomes a link to the object where
  the name resolves, or plain code where it does not.
"""

import ast
import re

import griffe

ROLE = re.compile(r":(?:func|class|meth|mod|data|attr|exc|obj):`~?\.?([^`]+)`")


class RedundantAliasIsPublic(griffe.Extension):
    """Mark ``from m import x as x`` (and ``import m as m``) names public."""

    def on_module_members(self, *, node: ast.AST | griffe.ObjectNode, mod: griffe.Module, **kwargs):
        """After a module's members are known, flag its redundant-alias re-exports."""
        if not isinstance(node, ast.Module):
            return
        for stmt in ast.walk(node):
            if not isinstance(stmt, ast.ImportFrom | ast.Import):
                continue
            for alias in stmt.names:
                name = alias.name.rsplit(".", 1)[-1]
                if alias.asname == name and not name.startswith("_") and name in mod.members:
                    mod.members[name].public = True


def _resolve(obj: griffe.Object, name: str) -> str | None:
    """The full path ``name`` means in ``obj``'s scope, or None."""
    if name.startswith("whiskerid."):
        return name
    scopes = [obj, obj.parent, obj.module] if obj.parent else [obj]
    for scope in scopes:
        try:
            return scope.resolve(name)
        except (griffe.NameResolutionError, AttributeError, KeyError):
            continue
    return None


def _linked(obj: griffe.Object, match: re.Match) -> str:
    name = match.group(1)
    short = name.rsplit(".", 1)[-1] if name.startswith("whiskerid.") else name
    path = _resolve(obj, name)
    if path is None:
        return f"`{short}`"
    # An optional cross-reference: a link where the target is documented, plain code elsewhere.
    return f'<autoref identifier="{path}" optional><code>{short}</code></autoref>'


class SphinxRolesToLinks(griffe.Extension):
    """Turn ``:role:`name``` in docstrings into links (or code)."""

    def on_package(self, *, pkg: griffe.Module, **kwargs) -> None:
        """Rewrite every docstring of the loaded package."""
        self._walk(pkg, set())

    def _walk(self, obj: griffe.Object, seen: set[str]) -> None:
        if obj.path in seen:
            return
        seen.add(obj.path)
        if obj.docstring is not None:
            obj.docstring.value = ROLE.sub(lambda m: _linked(obj, m), obj.docstring.value)
        for member in obj.members.values():
            if not member.is_alias:
                self._walk(member, seen)
