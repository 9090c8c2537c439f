"""The report draws with matplotlib's public API only: no module of ``reports`` reads, writes or
imports a private (``_name``) attribute of anything but itself — matplotlib's objects, fonts and
renderers included — and none imports a private module, so a matplotlib release that keeps its public
API keeps the report drawing."""
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def private_uses(source: str) -> list:
    """``(line, what)`` of every private attribute used on anything but ``self`` / ``cls``, every
    ``getattr``/``setattr``/``hasattr`` of a private name, and every import of a private module or name
    from another package."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and _private(node.attr) and \
                not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
            out.append((node.lineno, f".{node.attr}"))
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and \
                node.func.id in ("getattr", "setattr", "hasattr", "delattr") and len(node.args) > 1 and \
                isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str) and \
                _private(node.args[1].value):
            out.append((node.lineno, f"{node.func.id}(..., {node.args[1].value!r})"))
        elif isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if any(_private(p) for p in a.name.split("."))]
        elif (isinstance(node, ast.ImportFrom) and not node.level
                and not (node.module or "").startswith("reports")):
            out += [(node.lineno, f"{node.module}.{a.name}") for a in node.names
                    if _private(a.name) or any(_private(p) for p in (node.module or "").split("."))]
    return sorted(out)


def test_the_report_uses_no_private_name_of_another_module():
    bad = [f"{p.relative_to(ROOT)}:{line}: {what}" for p in sorted((ROOT / "reports").rglob("*.py"))
           for line, what in private_uses(p.read_text(encoding="utf-8"))]
    assert not bad, "\n".join(bad)


def test_planted_private_uses_are_found():
    planted = ("from matplotlib.font_manager import fontManager, _get_font\n"
               "import matplotlib._api\n"
               "def f(fig, prop):\n"
               "    fig._rb_extra = []\n"
               "    getattr(fig.canvas, '_lastKey', None)\n"
               "    return fontManager._find_fonts_by_props(prop), self._own\n")
    assert private_uses(planted) == [(1, "matplotlib.font_manager._get_font"), (2, "matplotlib._api"),
                                     (4, "._rb_extra"), (5, "getattr(..., '_lastKey')"),
                                     (6, "._find_fonts_by_props")]
