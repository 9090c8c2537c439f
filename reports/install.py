"""The files the report needs beside its code, checked where rbcheck is installed.

A wheel carries only the package data pyproject.toml names; a template left out would surface as
``TemplateNotFound`` after a whole sweep. The commands that end in a report check every template before
any work (:func:`check_templates`) and name the missing file.
"""
from __future__ import annotations

from importlib.resources import files

__all__ = ["TEMPLATE_FILES", "IncompleteInstallation", "check_templates", "incomplete"]

#: Every file of ``reports/templates/`` the pages are rendered from: each must be installed with the
#: package (pyproject.toml's package data; tests/test_packaging.py installs the wheel and renders).
TEMPLATE_FILES = ("base.html", "index.html", "ranking.html", "integrators.html", "scenario.html", "fuzz.html",
                  "sort.js", "style.css", "animation.js")


class IncompleteInstallation(RuntimeError):
    """A file rbcheck ships (a report template) is missing from where it is installed."""


def incomplete(template: str) -> IncompleteInstallation:
    """The error for ``template`` (a file name under reports/templates/), naming its installed path."""
    return IncompleteInstallation(
        f"{files('reports') / 'templates' / template}: missing from this installation of "
        "rbcheck: the installation is incomplete (a package data file was left out); "
        "reinstall rbcheck (pip install --force-reinstall, or pip install -e . in a clone)")


def check_templates() -> None:
    """IncompleteInstallation naming the first template missing from the installed package."""
    folder = files("reports") / "templates"
    for name in TEMPLATE_FILES:
        if not (folder / name).is_file():
            raise incomplete(name)
