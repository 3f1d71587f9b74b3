"""The executed notebook's HTML page needs nothing from the network: its math is drawn to SVG by matplotlib's
mathtext (the TeX kept as the image's alt text), and the page loads no script from a CDN (nbconvert's lab template
loads MathJax, require.js and mermaid from cdnjs)."""
import base64
import re

import nbformat
import pytest
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

from locbook.suite.notebook_html import _rewrite, export_html, render_math


def test_inline_and_display_math_become_svg_images_and_code_keeps_its_dollars():
    out = render_math("The mean $\\bar s_j = \\alpha - 10\\,n\\log_{10} d_j$ and\n$$\\sigma_\\mathrm{ACC}^2 \\le 1$$"
                      " but `cost = $5` stays.")
    images = re.findall(r'<img class="math[^"]*" alt="([^"]*)" src="data:image/svg\+xml;base64,([^"]+)">', out)
    assert [alt for alt, _ in images] == ["\\bar s_j = \\alpha - 10\\,n\\log_{10} d_j",
                                          "\\sigma_\\mathrm{ACC}^2 \\le 1"]
    for _, data in images:
        assert base64.b64decode(data).lstrip().startswith((b"<?xml", b"<svg"))
    assert 'class="math math-display"' in out.split("<img")[2]      # $$...$$ on its own line
    assert "`cost = $5` stays." in out


def test_tex_mathtext_cannot_read_is_rewritten_or_shown_as_code():
    assert _rewrite("\\sigma_\\mathrm{ACC} \\ge \\tfrac34 \\Big( \\mathcal N \\Big)") == \
        "\\sigma_{\\mathrm{ACC}} \\geq \\frac{3}{4} ( \\mathcal{N} )"
    out = render_math("$\\begin{bmatrix} 1 & 0 \\end{bmatrix}$")
    assert out == "<code>\\begin{bmatrix} 1 &amp; 0 \\end{bmatrix}</code>"


@pytest.mark.installed
def test_the_exported_page_loads_nothing_from_the_network(tmp_path):
    nb = new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [new_markdown_cell("The bound $J(p) = \\sum_j u_j u_j^\\top / d_j^2$."), new_code_cell("1 + 1")]
    path = tmp_path / "t.ipynb"
    nbformat.write(nb, str(path))
    page = export_html(path)
    assert re.findall(r'<script[^>]+src="https?://', page) == [] and "cdnjs" not in page and "MathJax" not in page
    images = re.findall(r"<img [^>]*>", page)
    assert len(images) == 1 and 'class="math"' in images[0] and 'src="data:image/svg+xml;base64,' in images[0]
    assert "img.math {" in page and "The bound" in page


def test_math_drawing_leaves_the_callers_matplotlib_backend_alone(tmp_path):
    """The runner draws the pages' math in its own process, which may be a user's Jupyter session: the pyplot
    backend stays whatever it was (run in a fresh interpreter, whose backend is chosen by MPLBACKEND; an empty cache
    folder, so the formula is drawn, not read)."""
    import subprocess
    import sys
    code = ("import matplotlib.pyplot\nfrom locbook.suite.notebook_html import math_svg\n"
            "assert math_svg('x^2') is not None\nimport matplotlib\nprint(matplotlib.get_backend())")
    env = {**__import__("os").environ, "MPLBACKEND": "svg", "LOCBOOK_CACHE_DIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.strip().lower() == "svg"
    assert len(list((tmp_path / "math").glob("*.svg"))) == 1          # and kept for the next run


def test_a_drawn_formula_is_kept_and_a_broken_or_unwritable_cache_is_drawn_around(tmp_path, monkeypatch):
    """A formula drawn once is read back from the cache folder by the next process (here: the memo emptied); a cached
    file that is not an SVG is drawn again and replaced; a cache folder that cannot be written changes nothing but
    the time (the formula is still drawn)."""
    import locbook.suite.notebook_html as nh
    monkeypatch.setenv("LOCBOOK_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(nh, "_MATH_MEMO", {})
    drawn = nh.math_svg("\\alpha_{k}^2")
    files = list((tmp_path / "cache" / "math").glob("*.svg"))
    assert drawn is not None and len(files) == 1 and files[0].read_bytes().startswith(b"<?xml")
    marker = files[0].read_bytes().replace(b"</svg>", b"<!-- kept --></svg>")
    files[0].write_bytes(marker)
    monkeypatch.setattr(nh, "_MATH_MEMO", {})
    kept = nh.math_svg("\\alpha_{k}^2")
    assert base64.b64decode(re.search(r'base64,([^"]+)"', kept).group(1)) == marker     # read, not drawn
    files[0].write_bytes(b"truncated")
    monkeypatch.setattr(nh, "_MATH_MEMO", {})
    again = nh.math_svg("\\alpha_{k}^2")
    assert base64.b64decode(re.search(r'base64,([^"]+)"', again).group(1)).startswith(b"<?xml")
    assert files[0].read_bytes().startswith(b"<?xml")                       # replaced by the drawing
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where the cache folder would be")
    monkeypatch.setenv("LOCBOOK_CACHE_DIR", str(blocked))
    monkeypatch.setattr(nh, "_MATH_MEMO", {})
    assert nh.math_svg("\\beta") is not None


def _highlighted_code_is_unchanged_by_clean_html(sources):
    from nbconvert.filters.highlight import Highlight2HTML
    from nbconvert.filters.strings import clean_html
    highlight = Highlight2HTML(pygments_lexer="ipython3")
    for source in sources:
        html_code = highlight(source)
        assert clean_html(html_code) == html_code, source[:80]


@pytest.mark.slow
def test_nbconverts_sanitiser_changes_no_code_cell_of_any_notebook():
    """The lab template's bleach pass over highlighted code, which locbook's template leaves out, returns pygments'
    HTML of every code cell of every notebook unchanged (nbconvert's own ``clean_html`` is the oracle): the page is
    the one the lab template writes. About 50 ms a cell, so in the slow pass."""
    from builders import REPO_ROOT
    cells = [c.source for p in sorted((REPO_ROOT / "notebooks").glob("*/*.ipynb"))
             for c in nbformat.read(str(p), as_version=4).cells if c.cell_type == "code"]
    assert len(cells) > 100
    _highlighted_code_is_unchanged_by_clean_html(cells)


def test_code_cells_skip_a_sanitiser_pass_that_changes_nothing_and_a_reused_exporter_gives_the_same_page(tmp_path):
    """locbook's template writes a code cell's highlighted source without the lab template's bleach pass: pygments
    escapes every character, so nbconvert's ``clean_html`` returns it unchanged, hostile source included (every
    notebook's cells: the slow test above). A page exported by the process's kept exporter equals one from a fresh
    exporter, and its code cells equal the lab template's."""
    from nbconvert import HTMLExporter
    from nbconvert.filters.highlight import Highlight2HTML

    from locbook.suite import notebook_html as nh
    _highlighted_code_is_unchanged_by_clean_html(
        ["x = '<b>&amp;</b>'  # \"quoted\" <script>alert(1)</script>", "s = f'{a!r}' if a < b else \"&lt;\""])
    assert "<script>" not in Highlight2HTML(pygments_lexer="ipython3")("<script>alert(1)</script>")
    nb = new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [new_code_cell("s = '<i>x</i>' & y  # <tag>"), new_markdown_cell("Text with $x^2$.")]
    path = tmp_path / "t.ipynb"
    nbformat.write(nb, str(path))
    first, again = export_html(path), export_html(path)
    assert first == again and nh._EXPORTER is not None
    fresh = nbformat.read(str(path), as_version=4)
    fresh.cells[1].source = nh.render_math(fresh.cells[1].source)
    page, _ = HTMLExporter(template_name=nh.TEMPLATE_NAME,
                           extra_template_basedirs=[str(nh.TEMPLATES)]).from_notebook_node(fresh)
    assert page == first
    lab, _ = HTMLExporter(template_name="lab").from_notebook_node(fresh)
    code = re.compile(r'<div class="cm-editor cm-s-jupyter">.*?</div>', re.S)
    assert code.findall(page) == code.findall(lab)        # the code cells exactly as the lab template writes them
