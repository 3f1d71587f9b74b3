"""The executed notebook as an HTML page that needs nothing from the network.

nbconvert's JupyterLab template loads MathJax, require.js and mermaid from a CDN, so a report opened offline showed
its formulas as raw TeX. Here the math of every Markdown cell (``$...$`` and ``$$...$$``) is drawn to SVG by
matplotlib's mathtext before the export and embedded in the page, and the page is exported with
``templates/nbconvert/locbook_lab`` (the lab template without those scripts). mathtext covers a subset of TeX: a few
spellings it lacks are rewritten to equivalents (:data:`_TEX_REWRITES`), and a formula it still cannot draw is
shown as its TeX source in a ``<code>`` element, never dropped.
"""
from __future__ import annotations

import base64
import html
import io
import re
from pathlib import Path

TEMPLATES = Path(__file__).resolve().parent / "templates" / "nbconvert"
TEMPLATE_NAME = "locbook_lab"
_MATH = re.compile(r"\$\$(.+?)\$\$|(?<![\\$])\$([^$\n]+?)\$", re.S)
_CODE = re.compile(r"(```.*?```|`[^`\n]*`)", re.S)          # code spans keep their dollars
#: TeX that mathtext does not read, and what it reads instead (same rendering)
_TEX_REWRITES = (
    (re.compile(r"\s*\n\s*"), " "),
    (re.compile(r"\\(le|ge|ne)(?![A-Za-z])"), r"\\\1q"),
    (re.compile(r"\\(mathcal|mathrm|mathbf|mathbb|mathit|mathsf|sqrt|hat|bar|tilde|vec|dot)\s*([A-Za-z0-9])(?![A-Za-z])"),
     r"\\\1{\2}"),
    (re.compile(r"\\[Bb]igg?[lr]?(?=[()\[\]|.])|\\[Bb]igg?[lr]?(?=\\[{}|])"), ""),
    (re.compile(r"\\lVert|\\rVert"), r"\\Vert"),
    (re.compile(r"\\lvert|\\rvert"), "|"),
    (re.compile(r"\\[td]frac"), r"\\frac"),
    (re.compile(r"\\frac(\d)(\d)"), r"\\frac{\1}{\2}"),
    (re.compile(r"\\text\{"), r"\\mathrm{"),
    (re.compile(r"\\operatorname\{"), r"\\mathrm{"),
)


def _brace_scripts(tex: str) -> str:
    """``x_\\mathrm{ab}`` (a command as an unbraced subscript or superscript, which mathtext refuses) as
    ``x_{\\mathrm{ab}}``."""
    pattern = re.compile(r"([_^])(\\(?:mathrm|mathcal|mathbf|mathit|text|operatorname)\{)")
    out, i = [], 0
    while True:
        m = pattern.search(tex, i)
        if not m:
            out.append(tex[i:])
            return "".join(out)
        depth, j = 1, m.end()
        while j < len(tex) and depth:
            depth += {"{": 1, "}": -1}.get(tex[j], 0)
            j += 1
        out.append(tex[i:m.start()] + m.group(1) + "{" + tex[m.start(2):j] + "}")
        i = j


def _text_spaces(tex: str) -> str:
    """The spaces inside ``\\text{...}`` kept (mathtext's roman drops them): each as ``\\ ``."""
    return re.sub(r"\\text\{([^{}]*)\}", lambda m: "\\text{" + m.group(1).replace(" ", "\\ ") + "}", tex)


def _rewrite(tex: str) -> str:
    tex = _brace_scripts(_text_spaces(tex))
    for pattern, repl in _TEX_REWRITES:
        tex = pattern.sub(repl, tex)
    return tex


def math_svg(tex: str, display: bool = False) -> str | None:
    """``tex`` drawn by mathtext as an ``<img>`` holding the SVG (None when mathtext cannot read it)."""
    # math_to_image draws on a Figure of its own: no pyplot backend is chosen (this runs in the runner's process,
    # which may be the user's Jupyter session)
    from matplotlib.mathtext import math_to_image
    buf = io.BytesIO()
    try:
        math_to_image(f"${_rewrite(tex.strip())}$", buf, format="svg", dpi=72)
    except Exception:               # noqa: BLE001 - mathtext's parse errors have no common base
        return None
    data = base64.b64encode(buf.getvalue()).decode("ascii")
    # classes, not a style attribute: nbconvert's sanitiser keeps classes (the template's CSS places them)
    return (f'<img class="{"math math-display" if display else "math"}" alt="{html.escape(tex.strip(), quote=True)}" '
            f'src="data:image/svg+xml;base64,{data}">')


def render_math(markdown: str) -> str:
    """Every ``$...$`` and ``$$...$$`` of a Markdown cell (outside code spans) as an SVG image, or its TeX in
    ``<code>`` where mathtext cannot draw it."""
    def one(m):
        display = m.group(1) is not None
        tex = m.group(1) if display else m.group(2)
        img = math_svg(tex, display)
        return img if img is not None else f"<code>{html.escape(tex.strip())}</code>"
    parts = _CODE.split(markdown)
    return "".join(p if i % 2 else _MATH.sub(one, p) for i, p in enumerate(parts))


def export_html(notebook_path) -> str:
    """The executed notebook ``notebook_path`` as one self-contained HTML page (module docstring)."""
    import nbformat
    from nbconvert import HTMLExporter
    nb = nbformat.read(str(notebook_path), as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "markdown" and "$" in cell.source:
            cell.source = render_math(cell.source)
    exporter = HTMLExporter(template_name=TEMPLATE_NAME, extra_template_basedirs=[str(TEMPLATES)])
    body, _ = exporter.from_notebook_node(nb)
    return body
