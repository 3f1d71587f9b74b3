"""Sphinx configuration: the docs/ pages (Markdown, through myst-parser) and an API reference generated from
``locbook._API``, the one table of the public API, so that the reference cannot drift from what ``import locbook``
offers. Build: ``python -m sphinx -W --keep-going -b html docs docs/_build/html`` (docs/testing.md)."""
import importlib
import inspect
import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS.parent))          # build from a clone without installing

import locbook  # noqa: E402

project = "locbook"
release = version = locbook.__version__
extensions = ["myst_parser", "sphinx.ext.autodoc", "numpydoc", "sphinx.ext.mathjax"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}   # .rst: numpydoc's autosummary
root_doc = "index"
exclude_patterns = ["_build", "README.md"]
html_theme = "pydata_sphinx_theme"
html_title = f"locbook {release}"
html_theme_options = {"navigation_with_keys": False, "show_toc_level": 2}
myst_heading_anchors = 4                      # `page.md#a-heading` links work as on GitHub
myst_enable_extensions = ["dollarmath"]
numpydoc_show_class_members = False           # members are listed where they matter, in the docstrings
numpydoc_class_members_toctree = False
numpydoc_validation_checks = set()
autodoc_member_order = "bysource"
autodoc_typehints = "none"                    # the signatures are shown; the docstrings give units and shapes
def _api_pages() -> None:
    """Write docs/api/ (git-ignored): one page per role of ``locbook._API``, one autodoc entry per name."""
    out = DOCS / "api"
    out.mkdir(exist_ok=True)
    roles: dict[str, list[tuple[str, str]]] = {}
    for role, module, names in locbook._API:
        roles.setdefault(role, []).extend((module, name) for name in names)
    index = ["# API reference", "",
             "Every public name of `locbook` (`import locbook as lb`; `lb.NAME`), by role, as listed in "
             "`locbook._API`. Each is documented in the module that is its home.", "",
             "```{toctree}", ":maxdepth: 1", ""]
    for role, entries in roles.items():
        slug = re.sub(r"[^a-z0-9]+", "-", role.lower()).strip("-")
        index.append(slug)
        lines = [f"# {role[0].upper() + role[1:]}", "", "```{eval-rst}", ".. currentmodule:: locbook", ""]
        for module, name in entries:
            obj = getattr(importlib.import_module(f"locbook.{module}"), name)
            kind = ("autoclass" if inspect.isclass(obj) else
                    "autofunction" if callable(obj) else "autodata")
            lines += [f".. {kind}:: {name}", ""]
        lines.append("```")
        _write(out / f"{slug}.md", "\n".join(lines) + "\n")
    index.append("```")
    _write(out / "index.md", "\n".join(index) + "\n")


def _write(path: Path, text: str) -> None:
    if not path.exists() or path.read_text(encoding="utf-8") != text:      # unchanged pages are not rebuilt
        path.write_text(text, encoding="utf-8")


def _outside_links(app, docname, source):
    """A link to a file of the repository outside docs/ (``../README.md``, ``../benchmarks/RESULTS.md``) works on
    GitHub as it is; in the build it becomes a download link to that file (myst's ``path:``), not a missing page."""
    up = "../" * (docname.count("/") + 1)
    source[0] = re.sub(r"\]\((" + re.escape(up) + r"[^)\s]+)\)", r"](path:\1)", source[0])


def setup(app):
    from pygments.lexers.special import TextLexer
    app.add_lexer("csv", TextLexer)           # the data-format pages' CSV samples, shown as they are
    _api_pages()
    app.connect("source-read", _outside_links)
