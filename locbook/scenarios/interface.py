"""The one interface of the per-document scenario modules: each name two or more of them define has one signature.

A document module (:mod:`locbook.scenarios.dogan`, :mod:`locbook.scenarios.ozkaya`, ...) defines the subset of
:class:`DocumentScenario` its source needs, and each name it defines has the signature below: the leading
parameters are positional (their names may differ per document, ``runs`` or ``results``), followed, where the
signature ends in ``*settings, **options``, by the document's own settings; a signature without them admits only
optional extra parameters. Where two modules' functions differ in meaning they have different names
(``dogan.run_channels`` returns runs per channel, ``ozkaya.run_tables`` scored rows;
``dogan.calibrated_from_text`` returns a row's ``calibrated_from`` text, ``ozkaya.fitted_interpretations``
interpretation names).
tests/scenarios/test_interface.py checks every module against this class with :func:`inspect.signature`.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

__all__ = ["DocumentScenario"]


class DocumentScenario(Protocol):
    """The shared names of the scenario modules, one signature each (the module docstring says how a module matches)."""

    def printed_tables(self) -> Sequence[dict]:
        """Every printed table cell the module reproduces, one dict per cell, as printed."""
        ...

    def table_view(self, rows: Sequence[dict], table: str, /) -> list[dict]:
        """One display row per printed row of ``table``: printed and ours side by side."""
        ...

    def table_rows(self, runs: Any, /) -> list[dict]:
        """The rows of the printed tables (printed beside reproduced) from the module's runs."""
        ...

    def record_tables(self, report: Any, rows: Sequence[dict], /, *settings: Any, **options: Any) -> object:
        """Score ``rows`` against the printed cells into ``report`` (one scored number per printed quantity)."""
        ...

    def noise_fit(self, scenario: Any, /, *settings: Any, **options: Any) -> dict:
        """Maximum-likelihood noise levels of the module's filter on ``scenario`` beside the hand-set ones."""
        ...

    def crlb_m(self, setting: Any, /, *settings: Any, **options: Any) -> np.ndarray:
        """The position CRLB (m) of the module's geometry at the given positions."""
        ...
