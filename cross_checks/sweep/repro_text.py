"""The code of a standalone reproducer (cross_checks/sweep/repro.py; docs/repro.md, "Length"): rbcheck's own
modules (the engine's world, the measurement) placed in the script line for line, with four things left
out so that it is short enough to paste into an issue:

* docstrings and comments (tokenize: the code lines themselves are the module's, unchanged);
* every definition the script never reaches: a top-level function, class, method or constant is kept when
  its name is reached from the script's ``main`` (a name, or an attribute: ``w.step()`` reaches every
  ``step``), transitively; a definition a later module redefines is shadowed, so it goes too;
* the modules' imports, gathered once at the top, a line for the standard library's ``import x`` and one for
  the others' (a relative import of a sibling world embedded above it goes: its names are the sibling's,
  defined in the script);
* what the script's own numbers never reach (:mod:`cross_checks.sweep.repro_slice`: an ``if`` or ``for``
  they decide, its kept branch one indentation level out), then the definitions only that reached.

What is left runs exactly as the modules do (tests/cross_checks/engines/worlds/test_worlds.py runs the
compacted text of every world against its adapter, bit for bit; tests/cross_checks/sweep/test_repro_slice.py
runs scripts sliced and unsliced and compares what they print).
"""
from __future__ import annotations

import ast
import io
import sys
import tokenize

from cross_checks.sweep import repro_slice

__all__ = ["compact"]


def _stripped_lines(text: str, tree: ast.Module) -> list:
    """The module's lines (1-based list: index 0 unused) with comments cut off and docstrings blanked;
    ``None`` marks a line to leave out (a comment or docstring line, a blank line outside a string)."""
    lines = [""] + text.splitlines()
    keep = [True] * len(lines)
    in_string, fstrings = set(), []
    f_start, f_end = getattr(tokenize, "FSTRING_START", None), getattr(tokenize, "FSTRING_END", None)
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT:
            row, col = tok.start
            lines[row] = lines[row][:col].rstrip()
        elif tok.type == tokenize.STRING and tok.end[0] > tok.start[0]:
            in_string.update(range(tok.start[0] + 1, tok.end[0] + 1))   # lines inside a multi-line string
        elif f_start is not None and tok.type == f_start:   # Python ≥ 3.12 splits an f-string in tokens
            fstrings.append(tok.start[0])
        elif f_end is not None and tok.type == f_end and fstrings:
            in_string.update(range(fstrings.pop() + 1, tok.end[0] + 1))
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if (len(body) > 1 and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                    and isinstance(body[0].value.value, str)):
                for row in range(body[0].lineno, body[0].end_lineno + 1):
                    keep[row] = False
                    in_string.discard(row)
    return [line if k and (line.strip() or row in in_string) else None
            for row, (line, k) in enumerate(zip(lines, keep))]


def _names(node) -> set:
    """Every name and attribute name ``node`` uses."""
    out = set()
    for n in ast.walk(node):
        if isinstance(n, ast.Name):
            out.add(n.id)
        elif isinstance(n, ast.Attribute):
            out.add(n.attr)
    return out


def _defines(node) -> set:
    if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
        return {node.name}
    if isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign):
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        return {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}
    return set()


def _span(node) -> tuple:
    start = min([node.lineno] + [d.lineno for d in getattr(node, "decorator_list", ())])
    return start, node.end_lineno


def _is_import(node) -> bool:
    return isinstance(node, ast.Import | ast.ImportFrom)


def _import_line(node) -> str:
    names = ", ".join(a.name + (f" as {a.asname}" if a.asname else "") for a in node.names)
    return f"import {names}" if isinstance(node, ast.Import) else f"from {node.module} import {names}"


def _bound(node) -> set:
    return {(a.asname or a.name).split(".")[0] for a in node.names}


def compact(texts, tail: str, prune: bool = True) -> str:
    """The code of modules ``texts`` compacted (:func:`_compact`), then (``prune``) sliced to what the
    script's numbers reach (cross_checks/sweep/repro_slice.py) and compacted again: a definition reached only
    from what the slice removed goes too."""
    text = _compact(texts, tail)
    if not prune:
        return text
    cut = repro_slice.prune(text)
    if cut == text or not cut.endswith(tail):
        return text
    return _compact([cut[:len(cut) - len(tail)]], tail)


def _compact(texts, tail: str) -> str:
    """The code of modules ``texts`` (in order, as one script) followed by ``tail`` (the script's own code:
    its numbers and ``main``), compacted as the module docstring says: the imports the kept code uses
    (standard library first, then the others: :func:`_import_group`), a blank line, the kept definitions in
    the modules' order, a blank line, then ``tail``."""
    units = []          # (node, its stripped lines, defines)
    imports = {}        # import line -> (bound names, is stdlib)
    for text in texts:
        tree = ast.parse(text)
        lines = _stripped_lines(text, tree)
        for node in tree.body:
            if _is_import(node):
                if not (isinstance(node, ast.ImportFrom) and node.level):
                    for alias in node.names:   # one entry per name: a line keeps only the names used
                        one = type(node)(names=[alias], **({"module": node.module, "level": 0}
                                                           if isinstance(node, ast.ImportFrom) else {}))
                        top = (alias.name if isinstance(node, ast.Import) else node.module).split(".")[0]
                        imports[_import_line(one)] = (_bound(one), top in sys.stdlib_module_names)
                continue
            if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant):
                continue    # the module docstring
            units.append((node, lines, _defines(node)))
    tail_tree = ast.parse(tail)
    # shadowing: a name defined again later leaves the earlier definition dead
    live = []
    for i, (node, lines, defs) in enumerate(units):
        if defs and all(any(d in later for _, _, later in units[i + 1:]) for d in defs):
            continue
        live.append((node, lines, defs))
    reached = _names(tail_tree)
    kept = [defs == set() for _, _, defs in live]    # statements that define nothing run for their effect
    for (node, _, _), k in zip(live, kept):
        if k:
            reached |= _names(node)
    grew = True
    while grew:
        grew = False
        for i, (node, _, defs) in enumerate(live):
            if kept[i] or not (defs & reached):
                continue
            kept[i] = grew = True
            if isinstance(node, ast.ClassDef):    # its methods only as they are reached (below)
                reached |= set().union(*(_names(b) for b in node.bases)) if node.bases else set()
                reached |= set().union(*(_names(s) for s in node.body if not _is_method(s)), set())
            else:
                reached |= _names(node)
        for i, (node, _, _) in enumerate(live):
            if kept[i] and isinstance(node, ast.ClassDef):
                for s in node.body:
                    if _is_method(s) and (s.name.startswith("__") or s.name in reached):
                        new = _names(s) - reached
                        if new:
                            reached |= new
                            grew = True
    body = []
    for (node, lines, _), k in zip(live, kept):
        if not k:
            continue
        start, end = _span(node)
        if isinstance(node, ast.ClassDef):
            skip = set()
            for s in node.body:
                if _is_method(s) and not (s.name.startswith("__") or s.name in reached):
                    skip.update(range(_span(s)[0], s.end_lineno + 1))
            rows = [r for r in range(start, end + 1) if r not in skip]
        else:
            rows = range(start, end + 1)
        code = [lines[r] for r in rows if lines[r] is not None]
        body.append((isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef), code))
    out = [line for _, code in body for line in code]
    used = _names(ast.parse("\n".join(out) + "\n" + tail))     # what the kept code uses (methods left out)
    head = [line for std in (True, False) for line in _import_group(
        [line for line, (b, s) in imports.items() if s is std and b & used])]
    return "\n".join(head) + "\n\n" + "\n".join(out) + "\n\n" + tail


def _is_method(node) -> bool:
    return isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)


def _import_group(lines) -> list:
    """One group's import lines (the standard library's, or the others'), as short as they read: every
    ``import x`` of the group on one line (``import importlib.metadata, platform, sys``), then each ``from x
    import y``, each part in isort's order."""
    lines = sorted(lines, key=_import_key)
    plain = [line.removeprefix("import ") for line in lines if line.startswith("import ")]
    froms: dict = {}
    for line in lines:
        if line.startswith("from "):
            module, name = line.removeprefix("from ").split(" import ")
            froms.setdefault(module, []).append(name)
    return ([f"import {', '.join(plain)}"] if plain else []) + [
        f"from {m} import {', '.join(sorted(names, key=str.lower))}" for m, names in froms.items()]


def _import_key(line: str) -> tuple:
    """isort's order within a group: ``import x`` lines before ``from x import y`` lines, by module name."""
    return (line.startswith("from "), line.split()[1].lower())
