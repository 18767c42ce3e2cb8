"""A griffe extension for the API reference (docs/mkdocs.yml): Sphinx roles become links,
and every object is documented once, in the module that defines it.

* ``:func:`x```, ``:class:``, ``:mod:``, ``:data:``, ``:meth:``, ``:attr:``, ``:obj:``,
  ``:exc:`` and ``:const:`` (optionally ``:py:``-prefixed, ``~`` for the last name only)
  are rewritten in every docstring of ``ntq_jax`` at build time. ``x`` is resolved as
  Python would from where the docstring sits (the object's own members, its class,
  its module and the module's imports, then as an absolute path); a name found is an
  optional autorefs cross-reference to the object's defining path (a link when that
  object is rendered on the site, else code), a name not found is code. The docstrings
  themselves are left as they are.
* A re-export (an alias of an ``ntq_jax`` object in another ``ntq_jax`` module, such as
  ``ntq_jax.Env``) is not rendered a second time: it is dropped from the module's
  members and the module's docstring ends with a list of links to the originals.
* In a Google-style ``Raises:`` section, a line at an item's indentation that names
  no exception (``Panda, or a padding other than 0.``) continues the item above it
  (griffe would warn and drop it).
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(
    r":(?:py:)?(?:func|class|mod|data|meth|attr|obj|exc|const)"
    r":`(?P<tilde>~?)(?P<target>[^`<>]+?)(?:\(\))?`"
)
ROOT = "ntq_jax"


def _lookup(pkg: griffe.Module, path: str) -> griffe.Object | griffe.Alias | None:
    if path == ROOT:
        return pkg
    if not path.startswith(ROOT + "."):
        return None
    try:
        return pkg.get_member(path[len(ROOT) + 1 :])
    except (KeyError, ValueError, griffe.AliasResolutionError, griffe.CyclicAliasError):
        return None


def _final_path(obj: griffe.Object | griffe.Alias) -> str | None:
    """The defining path of ``obj`` (aliases followed) if it lies in the package."""
    try:
        path = obj.final_target.path if obj.is_alias else obj.path
    except (griffe.AliasResolutionError, griffe.CyclicAliasError):
        return None
    return path if path == ROOT or path.startswith(ROOT + ".") else None


def resolve(pkg: griffe.Module, where: griffe.Object, name: str) -> str | None:
    """The defining path of ``name`` as written in a docstring of ``where``, or None."""
    head, _, rest = name.partition(".")
    candidates = []
    scope: Any = where
    while scope is not None:  # the object, its class, its module, its package...
        if scope.is_module or scope.is_class or scope is where:
            candidates.append(f"{scope.path}.{name}")
            imports = getattr(scope, "imports", {}) if scope.is_module else {}
            if head in imports:
                candidates.append(imports[head] + (f".{rest}" if rest else ""))
        scope = scope.parent
    candidates.append(name)
    for path in candidates:
        obj = _lookup(pkg, path)
        if obj is not None and (final := _final_path(obj)):
            return final
    return None


def rewrite(text: str, pkg: griffe.Module, where: griffe.Object) -> str:
    """``text`` with every Sphinx role replaced (see the module's docstring)."""

    def sub(m: re.Match) -> str:
        target = m["target"].strip()
        shown = target.rsplit(".", 1)[-1] if m["tilde"] else target
        path = resolve(pkg, where, target)
        if path is None:
            return f"`{shown}`"
        return f'<autoref identifier="{path}" optional>`{shown}`</autoref>'

    return ROLE.sub(sub, text)


RAISES_ITEM = re.compile(r"[A-Za-z_][\w.]*(?:, [A-Za-z_][\w.]*)*:(?:\s|$)")


def fix_raises(text: str) -> str:
    """``text`` with stray continuation lines of ``Raises:`` items indented under them."""
    lines, out, indent = text.split("\n"), [], None
    for line in lines:
        stripped = line.lstrip()
        depth = len(line) - len(stripped)
        if stripped == "Raises:":
            indent = -1
        elif indent == -1 and stripped:
            indent = depth
        elif indent is not None and indent >= 0 and stripped:
            if depth < indent:
                indent = None
            elif depth == indent and not RAISES_ITEM.match(stripped):
                line = " " * (indent + 4) + stripped
        out.append(line)
    return "\n".join(out)


def comment_docstring(obj: griffe.Object) -> str | None:
    """The ``#:`` comment lines right above an attribute without a docstring (the Sphinx
    convention the package's constants are documented with), or None."""
    if not obj.is_attribute or obj.docstring is not None or not obj.lineno:
        return None
    lines = obj.module.lines
    i, found = obj.lineno - 2, []
    while 0 <= i < len(lines) and lines[i].lstrip().startswith("#:"):
        found.append(lines[i].lstrip()[2:].strip())
        i -= 1
    return "\n".join(reversed(found)) or None


def _walk(obj: griffe.Object):
    yield obj
    for member in list(obj.members.values()):
        if not member.is_alias:
            yield from _walk(member)


class SphinxRoles(griffe.Extension):
    """Rewrites the roles and drops re-exports once the whole package is loaded."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        if pkg.name != ROOT:
            return
        objects = list(_walk(pkg))
        for obj in objects:
            text = comment_docstring(obj)
            if text is not None:
                obj.docstring = griffe.Docstring(text, parent=obj)
        for obj in objects:
            if obj.docstring is not None and ":" in obj.docstring.value:
                obj.docstring.value = fix_raises(rewrite(obj.docstring.value, pkg, obj))
        for mod in (o for o in objects if o.is_module):
            self._drop_reexports(mod)

    @staticmethod
    def _drop_reexports(mod: griffe.Module) -> None:
        if mod.exports is None:  # without __all__ an import is not rendered
            return
        exported = {getattr(e, "name", e) for e in mod.exports}
        links = []
        for name, member in list(mod.members.items()):
            if not member.is_alias or name not in exported:
                continue
            path = _final_path(member)
            if path is None or path == f"{mod.path}.{name}":
                continue
            del mod.members[name]
            links.append(f'<autoref identifier="{path}" optional>`{name}`</autoref> (`{path}`)')
        if links and mod.docstring is not None:
            mod.docstring.value += (
                "\n\nRe-exported here, documented where they are defined: " + ", ".join(links) + "."
            )
