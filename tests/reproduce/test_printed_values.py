"""Printed numbers live only in locbook/data/printed/<document>.csv: none is typed into Python code or a notebook
cell. Numeric literals of the package and the notebooks' code cells are compared with every printed
number of at least four significant digits (shorter ones, such as 1.87, collide with ordinary constants)."""
import ast
import io
import json
import tokenize

import locbook as lb
from builders import REPO_ROOT
from locbook.reproduce.printed_values import PRINTED_DIR

ROOT = REPO_ROOT


def _significant_digits(text: str) -> int:
    """Significant digits of a printed number: ``2.2867`` 5, ``0.0152`` 3, ``1000`` 1 (an integer's trailing
    zeros are not significant: 1000 runs is a round count, not a measured value)."""
    mantissa = text.lower().split("e")[0].replace("-", "").replace("+", "")
    digits = mantissa.replace(".", "").lstrip("0")
    if "." not in mantissa:
        digits = digits.rstrip("0")
    return len(digits)


def test_significant_digits():
    assert [_significant_digits(t) for t in ("2.2867", "0.0152", "1000", "1500", "914", "-0.00023", "1.50")] == [
        5, 3, 1, 2, 3, 2, 3]


def _printed_literals() -> dict[float, str]:
    out = {}
    for path in PRINTED_DIR.glob("*.csv"):
        for p in lb.printed(path.stem):
            if not any(c.isdigit() for c in p.text):
                continue                            # a quoted statement without a number
            number = next(tok for tok in p.text.replace("%", " ").split() if any(c.isdigit() for c in tok))
            if _significant_digits(number) >= 4:
                out[p.value] = f"{p.document}: {p.where} = {p.text}"
    return out


def _number_tokens(source: str):
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.NUMBER and not tok.string.lower().endswith("j"):
            yield tok.start[0], float(ast.literal_eval(tok.string))      # 1_000, 0x3ff, 1e-3 alike


def test_no_printed_number_is_typed_in_code():
    printed = _printed_literals()
    assert len(printed) > 10
    found = []
    for path in sorted((ROOT / "locbook").rglob("*.py")):
        for line, value in _number_tokens(path.read_text(encoding="utf-8")):
            if value in printed:
                found.append(f"{path.relative_to(ROOT)}:{line}: {value} ({printed[value]})")
    for path in sorted((ROOT / "notebooks").rglob("*.ipynb")):
        cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
        for i, cell in enumerate(cells):
            if cell["cell_type"] != "code":
                continue
            source = "".join(cell["source"])
            try:
                numbers = list(_number_tokens(source))
            except (tokenize.TokenError, IndentationError, SyntaxError):
                continue
            for line, value in numbers:
                if value in printed:
                    found.append(f"{path.relative_to(ROOT)} cell {i} line {line}: {value} ({printed[value]})")
    assert not found, "printed numbers typed in code (read them from locbook/data/printed/):\n" + "\n".join(found)
