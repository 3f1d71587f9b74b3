"""Ozkaya (2011)'s Chs. 5-6: the literature constants (Tables 5.1-5.3), the calibration of Tables 6.1-6.2, the test
bed's geometry and synthetic calibration campaigns (:func:`synthetic_campaign`).
"""
from __future__ import annotations

import numpy as np

from ..models.channel import PathLossModel, quantize_db
from .ozkaya_simulation import PRINTED


def _per_reader(table: str, statistic: str) -> tuple[float, ...]:
    return tuple(PRINTED.get(f"Table {table}", f"Reader {j}", statistic).value for j in (1, 2, 3))


# -- Chapters 5-6: literature constants, calibration, the test bed -----------------------------------
def literature_table(table: str) -> list[dict]:
    """Tables 5.1-5.3 (literature values the thesis quotes from Rappaport [4] and Seidel & Rappaport [36]), one
    dict per printed row with the printed texts."""
    out: dict = {}
    for p in PRINTED.where(f"Table {table}"):
        out.setdefault(p.item, {"row": p.item})[p.statistic] = p.text
    if not out:
        raise KeyError(f"Table {table} is not one of the literature tables 5.1-5.3")
    return list(out.values())


#: Table 6.1, offline calibration per reader: alpha (dBm), n, WAF (dB), sigma (dB).
OFFLINE_PARAMETERS = {"alpha_dbm": _per_reader("6.1", "alpha_dbm"),
                      "path_loss_exp": _per_reader("6.1", "path_loss_exp"),
                      "waf_db": PRINTED.get("Sec. 6.1 text", "WAF", "waf_db").value,
                      "sigma_db": _per_reader("6.1", "sigma_db")}
#: Table 6.2, automatic calibration with the reference tags (static environment): one pooled sigma.
AUTO_PARAMETERS = {"alpha_dbm": _per_reader("6.2", "alpha_dbm"), "path_loss_exp": _per_reader("6.2", "path_loss_exp"),
                   "sigma_db": PRINTED.get("Table 6.2", "all readers (pooled)", "sigma_db").value}
#: Fig. 6.6 text (Reader 3): same-room distances, then other-room distances (one wall).
R3_CALIBRATION_DISTANCES_M = tuple(tuple(p.value for p in PRINTED.where("Fig. 6.6 text") if f" {room} room " in p.item)
                                   for room in ("same", "other"))
READER_SENSITIVITY_DBM = PRINTED.get("Sec. 6.1 text", "readers", "sensitivity_dbm").value
WAF_DB = OFFLINE_PARAMETERS["waf_db"]

def synthetic_campaign(reader: int, n_campaigns: int, rng: np.random.Generator, distances_m, walls, *,
                       location_sigma_db: float, locations_per_distance: int, readings_per_location: int,
                       parameters: dict | None = None) -> np.ndarray:
    """Synthetic offline calibration campaigns of Sec. 6.1 for reader ``reader`` (0-based) of
    ``parameters`` (default :data:`OFFLINE_PARAMETERS`, Table 6.1), shape
    ``(n_campaigns, distances, locations_per_distance, readings_per_location)``.

    Reading = Eq. (6.4)'s mean ``alpha - 10 n log10 d - WAF walls`` + a per-location offset
    ``N(0, location_sigma_db^2)`` (orientation, position on the arc) + per-reading noise
    ``N(0, sigma^2 - location_sigma_db^2)``, so the total per-distance variance is Table 6.1's ``sigma^2``; then 1 dB
    reader resolution and the -90 dBm sensitivity floor (:func:`~locbook.models.channel.quantize_db`). The offsets
    are drawn before the readings' noise (one stream, ``rng``)."""
    P = OFFLINE_PARAMETERS if parameters is None else parameters
    read_var = P["sigma_db"][reader] ** 2 - location_sigma_db**2
    if not read_var >= 0:
        raise ValueError(f"location_sigma_db = {location_sigma_db!r} exceeds the reader's total sigma "
                         f"{P['sigma_db'][reader]!r} dB")
    distances_m = np.asarray(distances_m, float)
    mean = PathLossModel(P["alpha_dbm"][reader], P["path_loss_exp"][reader],
                         wall_attenuation_db=P["waf_db"]).mean_rss_dbm(distances_m, walls)
    read_sd = np.sqrt(read_var)
    offs = location_sigma_db * rng.standard_normal((n_campaigns, distances_m.size, locations_per_distance, 1))
    noise = read_sd * rng.standard_normal((n_campaigns, distances_m.size, locations_per_distance,
                                           readings_per_location))
    return quantize_db(mean[:, None, None] + offs + noise, 1.0, READER_SENSITIVITY_DBM)


#: Synthetic two-room test bed (Sec. 6.1: rooms of 3 m x 4 m and 4 m x 6 m; every coordinate ASSUMED: the plan
#: exists only in figures):
#: small room x in [0, 3], large room x in [3, 9], both y in [0, 4], brick wall at x = 3.
TESTBED_SIZE_M = (9.0, 4.0)
TESTBED_WALLS_M = (((3.0, 0.0), (3.0, 4.0)),)
#: R1, R2 in the large room, R3 in the small room, at corners (Sec. 6.1).
TESTBED_READERS_M = ((9.0, 4.0), (9.0, 0.0), (0.0, 0.0))
#: T1, T2 in the small room and T3, T4 in the large room, toward the centre of the area (Sec. 7.3.1).
REFERENCE_TAGS_M = ((1.5, 1.5), (2.0, 3.0), (4.5, 1.5), (5.0, 3.0))
