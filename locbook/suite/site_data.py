"""A data set's reports (``locbook run --data``: a folder holding dataset.json): its index page in Markdown and HTML.

The page opens with the answer: the data set's own title and attribution, then every method's errors beside its
bound, then the channel fits, then the bookkeeping. It uses none of the reproduction vocabulary of the suite's own
pages (:mod:`locbook.suite.site`, which links these pages from a profile's index): a data set has no printed number
to compare with.
"""
from __future__ import annotations

from pathlib import Path

from ..reproduce.report import Table
from .compare import comparison_pages
from .files import read_csv, read_json
from .findings import md_cell, profile_of
from .pages import caption_md, first_file, index_entry, page_outputs, render
from .spec import finite_float

__all__ = ["DATA_RESULTS", "DATA_FIGURES", "DATA_FITS", "POOLED", "dataset_record", "dataset_title", "dataset_credit",
           "data_page", "data_index_markdown", "data_index_html", "dataset_sections", "datasets"]


#: the results tables of a data set's page: (experiment, the kind of its ``results.csv`` rows, heading); the columns
#: are those of :data:`locbook.scenarios.measured.RESULT_COLUMNS`
DATA_RESULTS = (("measured-localization", "static", "Static localization"),
                ("measured-tracking", "tracking", "Tracking"))
#: the figures shown inline below the results: (experiment, file)
DATA_FIGURES = (("measured-localization", "cdf.png"), ("measured-localization", "maps.png"),
                ("measured-tracking", "tracks.png"))
#: the channel fits shown after the results: (experiment, file)
DATA_FITS = ("measured-calibration", "fits.csv")
#: the results row that holds every scored recording together (``recording`` column)
POOLED = "pooled"
#: columns of a results table on the page: (shown name, results.csv column)
_RESULT_CELLS = (("method", "method"), ("recording", "recording"), ("epochs", "epochs"), ("coverage", "coverage"),
                 ("mean (m)", "mean_m"), ("mean interval (m)", ""), ("median (m)", "median_m"),
                 ("p90 (m)", "p90_m"), ("CE95 (m)", "ce95_m"), ("bound median (m)", "bound_median_m"),
                 ("ratio", "ratio"), ("ratio note", "ratio_note"), ("settings", "settings"))
#: columns of the fits table on the page (the measured-calibration notebook's fits.csv)
_FIT_CELLS = ("mode", "fit", "anchor", "P_0 (dBm)", "n", "residual sigma (dB)", "samples", "status")


def dataset_record(report_dir: Path) -> dict | None:
    """The record of the data set a reports folder holds (its ``dataset.json``, written by the runner when a data run
    claims the folder: name, identity, title, attribution, licence, manifest, geometry, the experiments left out and
    why), or None for a folder of the suite's own reports."""
    record = read_json(Path(report_dir) / "dataset.json", {})
    return record if isinstance(record.get("data set"), str) and record.get("data set") else None


def dataset_title(record: dict) -> str:
    return str(record.get("title") or record.get("name") or "a data set")


def dataset_credit(record: dict) -> str:
    """The manifest's attribution and licence in one sentence ('' when the record has neither)."""
    parts = []
    if record.get("attribution"):
        parts.append(f"Attribution: {str(record['attribution']).rstrip('.')}.")
    if record.get("licence"):
        parts.append(f"Licence: {str(record['licence']).rstrip('.')}.")
    return " ".join(parts)


def _result_rows(path: Path, kind: str) -> list[dict]:
    """The rows of ``kind`` of a results.csv, grouped per method (in the file's order), each method's pooled row
    first, then its recordings in the file's order. A method scored on one recording keeps its pooled row only
    (the same epochs), named ``pooled (= <recording>)``."""
    rows = [r for r in read_csv(path) if (r.get("kind") or kind) == kind and r.get("method")]
    out = []
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = sorted((r for r in rows if r["method"] == method), key=lambda r: r.get("recording") != POOLED)
        if len(mine) == 2 and mine[0].get("recording") == POOLED != mine[1].get("recording"):
            mine = [{**mine[0], "recording": f"{POOLED} (= {mine[1].get('recording')})"}]
        out += mine
    return out


def _interval_cell(row: dict) -> str:
    low, high = finite_float(row.get("mean_low_m")), finite_float(row.get("mean_high_m"))
    if low is not None and high is not None:
        return f"[{row['mean_low_m']}, {row['mean_high_m']}]"
    return (row.get("interval_note") or "").strip() or "n/a"


def _result_table(rows: list[dict]) -> tuple[list[dict], list[dict]]:
    """(cells by shown column, notes): each distinct ratio note numbered once (``[n]``), in order of first use."""
    numbered: dict[str, int] = {}
    out = []
    for r in rows:
        cells = {}
        for shown, column in _RESULT_CELLS:
            if shown == "mean interval (m)":
                cells[shown] = _interval_cell(r)
            elif column == "ratio":
                cells[shown] = r.get("ratio") if finite_float(r.get("ratio")) is not None else "n/a"
            elif column == "ratio_note":
                note = (r.get("ratio_note") or "").strip()
                cells[shown] = f"[{numbered.setdefault(note, len(numbered) + 1)}]" if note else ""
            else:
                cells[shown] = r.get(column) or ""
        if (r.get("failure") or "").strip():         # a method of your own that gave no positions, and why
            cells["mean (m)"], cells["mean interval (m)"] = "failed", r["failure"].strip()
        cells["pooled"] = str(r.get("recording")).startswith(POOLED)
        out.append(cells)
    return out, [{"n": n, "text": t} for t, n in numbered.items()]


def _state_of(eid: str, record: dict, status: dict, folder: Path) -> tuple[str, str]:
    """(state, why) of an experiment of a data set's page: "left out", "failed", "interrupted", "not run", "ok" or
    "cached" (the last run's), with the reason of the first four."""
    left = (record.get("left out") or {}) if isinstance(record.get("left out"), dict) else {}
    if eid in left:
        return "left out", str(left[eid])
    last = status.get(eid) if isinstance(status.get(eid), dict) else {}
    state = last.get("status") or ""
    present = (folder / eid / "summary.md").is_file()
    if state in ("failed", "interrupted"):
        return state, str(last.get("error") or "")
    if not present:
        return "not run", "it has not run on this data set yet"
    return state or "ok", ""


def _missing_line(eid: str, state: str, why: str, what: str) -> str:
    """One line for a result the page cannot show: which experiment, and why."""
    if state == "left out":
        return f"{eid}: left out: {why}."
    if state in ("failed", "interrupted"):
        return f"{eid} {state}: {why or 'no reason recorded'}."
    if state == "not run":
        return f"{eid}: not run: {why}."
    return f"{eid}: its report holds no {what}."


def _best(rows: list[dict]) -> dict | None:
    """The pooled row with the lowest finite mean error (None: no such row)."""
    pooled = [r for r in rows
              if str(r.get("recording")).startswith(POOLED) and finite_float(r.get("mean_m")) is not None]
    return min(pooled, key=lambda r: finite_float(r["mean_m"])) if pooled else None


def _answer_text(parts: list[dict]) -> str:
    """One sentence: per kind, the method with the lowest pooled mean error, beside the median of its bound."""
    said = []
    for p in parts:
        best = _best(p["source_rows"])
        if best is None:
            continue
        bound = (best.get("bound") or "bound").split(" (")[0]
        text = f"{p['heading'].lower()}, {best['method']} {best['mean_m']} m"
        if finite_float(best.get("bound_median_m")) is not None:
            text += f" ({bound} median {best['bound_median_m']} m)"
        if finite_float(best.get("coverage")) is not None and finite_float(best["coverage"]) < 1:
            text += f", an estimate at {best['coverage']} of the epochs"
        said.append(text)
    return ("Lowest mean error over every scored recording together: " + "; ".join(said) + ".") if said else ""


def data_page(report_dir: Path, entries, record: dict) -> dict:
    """What a data set's page shows (:func:`data_index_markdown`, :func:`data_index_html`), read from the folder:
    ``entries`` as :func:`locbook.suite.site.write_suite_reports` builds them, ``record`` its dataset.json."""
    report_dir = Path(report_dir)
    status = read_json(report_dir / "status.json", {})
    by_id = {e["exp"].id: e for e in entries}
    results = []
    for eid, kind, heading in DATA_RESULTS:
        state, why = _state_of(eid, record, status, report_dir)
        rows = _result_rows(report_dir / eid / "results.csv", kind) if state not in ("left out", "not run") else []
        note = ""
        if state in ("failed", "interrupted") and rows:
            note = f"The last run of {eid} {state} ({why or 'no reason recorded'}); these are its previous results."
        cells, notes = _result_table(rows)
        results.append({"id": eid, "heading": heading, "kind": kind, "rows": cells, "notes": notes,
                        "source_rows": rows, "note": note,
                        "bounds": list(dict.fromkeys(r.get("bound") for r in rows if r.get("bound"))),
                        "missing": "" if rows else _missing_line(eid, state, why, "results table (results.csv)"),
                        "link": first_file(report_dir, f"{eid}/report.html", f"{eid}/report.md")})
    figures = []
    for eid, name in DATA_FIGURES:
        folder = report_dir / eid
        if (folder / name).is_file() and _state_of(eid, record, status, report_dir)[0] != "left out":
            shown, _tables = page_outputs(folder, read_json(folder / "manifest.json", {"figures": [], "tables": []}))
            caption = next((f["caption"] for f in shown if f["file"] == name), "")
            figures.append({"file": f"{eid}/{name}", "caption": caption or name, "experiment": eid})
    fit_id, fit_file = DATA_FITS
    state, why = _state_of(fit_id, record, status, report_dir)
    fits = read_csv(report_dir / fit_id / fit_file) if state not in ("left out", "not run") else []
    used = _fit_used(by_id)
    if fits and used and {"mode", "fit"} <= set(fits[0]):
        shown_fits = [r for r in fits if r.get("mode") != "per_anchor" or r.get("fit") == used]
    else:
        shown_fits = fits
    fit_columns = [c for c in _FIT_CELLS if fits and c in fits[0]] or (list(fits[0]) if fits else [])
    experiments = []
    for e in entries:
        eid = e["exp"].id
        state, why = _state_of(eid, record, status, report_dir)
        entry = index_entry(report_dir, e) if state != "left out" else None
        experiments.append({"id": eid, "title": e["exp"].title, "state": state, "why": why,
                            "page": entry["page"] if entry else None, "links": entry["links"] if entry else [],
                            "time": entry["time"] if entry else "-", "stamp": entry["stamp"] if entry else "",
                            "profile": e["report"].get("profile", "")})
    return {"title": dataset_title(record), "name": record.get("name", ""), "credit": dataset_credit(record),
            "attribution": record.get("attribution", ""), "licence": record.get("licence", ""),
            "geometry": record.get("geometry", ""), "manifest": record.get("manifest", ""),
            "identity": record.get("data set", ""), "profile": profile_of(report_dir) or next(
                (x["profile"] for x in experiments if x["profile"]), ""),
            "answer": _answer_text(results), "results": results, "figures": figures,
            "fits": [{c: r.get(c) or "" for c in fit_columns} for r in shown_fits], "fit_columns": fit_columns,
            "fit_used": used if shown_fits is not fits else "",
            "fits_link": first_file(report_dir, f"{fit_id}/{fit_file}"),
            "fits_missing": "" if fits else _missing_line(fit_id, state, why, "fits table (fits.csv)"),
            "experiments": experiments, "comparisons": comparison_pages(report_dir)}


def _fit_used(by_id: dict) -> str:
    """The channel fit the methods ran on: measured-localization's (else measured-tracking's) ``fit`` parameter as
    its report records it, else the notebook's default; '' when neither declares one."""
    for eid in ("measured-localization", "measured-tracking"):
        e = by_id.get(eid)
        if e is None:
            continue
        params = e["report"].get("parameters") if isinstance(e["report"].get("parameters"), dict) else {}
        if params.get("fit"):
            return str(params["fit"])
        declared = e["exp"].declared_parameters()
        if "fit" in declared and declared["fit"].default:
            return str(declared["fit"].default)
    return ""


def _md_results(part: dict) -> list[str]:
    lines = [f"### {part['heading']}", ""]
    if not part["rows"]:
        return lines + [md_cell(part["missing"]), ""]
    if part["note"]:
        lines += [md_cell(part["note"]), ""]
    rows = [{k: (f"**{v}**" if k == "method" and r["pooled"] else md_cell(v)) for k, v in r.items() if k != "pooled"}
            for r in part["rows"]]
    lines += [Table(rows).to_markdown(), ""]
    about = f"From [{part['id']}]({part['id']}/report.md); the bound: {md_cell('; '.join(part['bounds']))}." \
        if part["bounds"] else f"From [{part['id']}]({part['id']}/report.md)."
    lines += [about + " Ratio: RMSE over the RMS bound on the epochs where the bound is defined.", ""]
    if part["notes"]:
        lines += ["Ratio notes:", ""] + [f"{n['n']}. {md_cell(n['text'])}" for n in part["notes"]] + [""]
    return lines


def data_index_markdown(report_dir: Path, entries, record: dict) -> str:
    """``index.md`` of a data set's reports folder: the answer first (title, attribution, licence, geometry; every
    method's errors beside its bound, the figures), then the channel fits, then the bookkeeping."""
    page = data_page(report_dir, entries, record)
    lines = [f"# {md_cell(page['title'])}", ""]
    for text in (page["credit"], page["geometry"] and page["geometry"].rstrip(".") + "."):
        if text:
            lines += [md_cell(text), ""]
    lines += ["## Results", ""]
    if page["answer"]:
        lines += [md_cell(page["answer"]), ""]
    for part in page["results"]:
        lines += _md_results(part)
    for f in page["figures"]:
        lines += [f"![{caption_md(f['caption'])}]({f['file']})", "", f"*{caption_md(f['caption'])}*", ""]
    lines += ["## Channel fits", ""]
    if page["fits"]:
        lines += [Table([{c: md_cell(v) for c, v in r.items()} for r in page["fits"]]).to_markdown(), ""]
        lines += [("Pooled fits, and each anchor's fit by the " + page["fit_used"] + " fit the methods ran on; "
                   if page["fit_used"] else "") + f"every fit: [{DATA_FITS[1]}]({page['fits_link']}).", ""]
    else:
        lines += [md_cell(page["fits_missing"]), ""]
    lines += ["## Experiments on this data set", ""]
    table = [{"experiment": f"[`{x['id']}`]({x['id']}/summary.md)" if x["links"] else f"`{x['id']}`",
              "title": md_cell(x["title"]), "last run": md_cell(x["state"] + (f": {x['why']}" if x["why"] else "")),
              "time": x["time"], "generated by": md_cell(x["stamp"])} for x in page["experiments"]]
    if table:
        lines += [Table(table).to_markdown(), ""]
    if page["comparisons"]:
        lines += ["Compared with: " + ", ".join(f"[{base}]({link})" for base, link in page["comparisons"])
                  + " (each method's errors in both runs, the difference and its standard error).", ""]
    lines += [f"Data set `{md_cell(page['name'])}`" + (f", manifest `{md_cell(page['manifest'])}`" if page["manifest"]
                                                       else "") + (f"; profile `{page['profile']}`" if page["profile"]
                                                                   else "") + ". A last run `cached` was up to date "
              "and not executed again; `ok` ran in that run.", ""]
    return "\n".join(lines)


def data_index_html(report_dir: Path, entries, record: dict, version: str) -> str:
    """``index.html`` of a data set's reports folder (as :func:`data_index_markdown`)."""
    return render("data_index.html", version=version, page=data_page(report_dir, entries, record))


def dataset_sections(report_dir: Path, page: str = "index.html") -> list[dict]:
    """The data sets of a profile's folder (``data-<name>/``, :func:`datasets`), each with its title, attribution
    and the answer sentence of its page: ``[{"name", "link", "title", "credit", "answer"}]``."""
    out = []
    for name, link in datasets(report_dir, page):
        folder = Path(report_dir) / f"data-{name}"
        record = dataset_record(folder) or {"name": name}
        parts = [{"heading": heading, "source_rows": _result_rows(folder / eid / "results.csv", kind)}
                 for eid, kind, heading in DATA_RESULTS
                 if eid not in (record.get("left out") or {})]
        out.append({"name": name, "link": link, "title": dataset_title(record), "credit": dataset_credit(record),
                    "answer": _answer_text(parts)})
    return out


def datasets(report_dir: Path, page: str = "index.html") -> list[tuple[str, str]]:
    """``(data set, link)`` of the reports of other data sets kept in this folder (``data-<name>/``): a link to its
    ``page`` (``index.html`` or ``index.md``), else to the other one; a folder with neither is not listed. Read from
    disk, whatever run wrote this index: committed reports hold index.md only (the HTML is not committed), and a
    partial run never drops a data set it did not touch."""
    other = "index.md" if page == "index.html" else "index.html"
    out = []
    for d in sorted(Path(report_dir).glob("data-*")):
        name = first_file(d, page, other)
        if d.is_dir() and name:
            out.append((d.name[len("data-"):], f"{d.name}/{name}"))
    return out
