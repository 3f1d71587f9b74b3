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
import hashlib
import html
import io
import os
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


#: the drawn formulas of this process, by :func:`_math_key`
_MATH_MEMO: dict[str, bytes | None] = {}


def math_cache_dir() -> Path:
    """Where drawn formulas are kept between runs: ``$LOCBOOK_CACHE_DIR/math``, else ``$XDG_CACHE_HOME/locbook/math``
    (``~/.cache/locbook/math``). Drawing one takes about 50 ms, and every page of a run draws the same ones again."""
    root = os.environ.get("LOCBOOK_CACHE_DIR")
    if root:
        return Path(root) / "math"
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "locbook" / "math"


def _math_key(tex: str) -> str:
    """The drawing's inputs: the TeX mathtext reads, matplotlib's version and this module's settings."""
    import matplotlib
    return hashlib.sha256(f"svg dpi=72 matplotlib={matplotlib.__version__}\n{tex}".encode()).hexdigest()


def _drawn_svg(tex: str) -> bytes | None:
    """The SVG mathtext draws for ``tex`` (already rewritten), None when it cannot read it: from this process's memo,
    else the cache folder (:func:`math_cache_dir`), else drawn and kept in both. A cache that cannot be read or
    written is drawn around, never an error."""
    key = _math_key(tex)
    if key in _MATH_MEMO:
        return _MATH_MEMO[key]
    cached = math_cache_dir() / f"{key}.svg"
    try:
        svg = cached.read_bytes()
    except OSError:
        svg = None
    if not svg or not svg.startswith(b"<?xml"):
        # math_to_image draws on a Figure of its own: no pyplot backend is chosen (this runs in the runner's
        # process, which may be the user's Jupyter session)
        from matplotlib.mathtext import math_to_image
        buf = io.BytesIO()
        try:
            math_to_image(f"${tex}$", buf, format="svg", dpi=72)
        except Exception:               # noqa: BLE001 - mathtext's parse errors have no common base
            _MATH_MEMO[key] = None
            return None
        svg = buf.getvalue()
        try:
            cached.parent.mkdir(parents=True, exist_ok=True)
            tmp = cached.with_name(f".{key}.{os.getpid()}.tmp")
            tmp.write_bytes(svg)
            os.replace(tmp, cached)         # whole or absent: a concurrent run reads one or the other
        except OSError:
            pass
    _MATH_MEMO[key] = svg
    return svg


def math_svg(tex: str, display: bool = False) -> str | None:
    """``tex`` drawn by mathtext as an ``<img>`` holding the SVG (None when mathtext cannot read it)."""
    svg = _drawn_svg(_rewrite(tex.strip()))
    if svg is None:
        return None
    data = base64.b64encode(svg).decode("ascii")
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


#: this process's exporter: its compiled templates are kept for the next page (nbconvert's own command reuses one
#: exporter for every notebook it converts)
_EXPORTER = None


def _exporter():
    global _EXPORTER
    if _EXPORTER is None:
        from nbconvert import HTMLExporter
        _EXPORTER = HTMLExporter(template_name=TEMPLATE_NAME, extra_template_basedirs=[str(TEMPLATES)])
    return _EXPORTER


def export_html(notebook_path) -> str:
    """The executed notebook ``notebook_path`` as one self-contained HTML page (module docstring)."""
    import nbformat
    nb = nbformat.read(str(notebook_path), as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "markdown" and "$" in cell.source:
            cell.source = render_math(cell.source)
    body, _ = _exporter().from_notebook_node(nb)
    return body
