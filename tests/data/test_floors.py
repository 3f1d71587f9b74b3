"""Floors (zones, scenes) of a data set, placeholder anchors and the floor plan under the maps:
locbook.data.floors, the loader's hooks, the example's building, and locbook.plotting's map figures."""
import io
import re
import shutil

import numpy as np
import pandas as pd
import pytest

import locbook as lb
from locbook.data import floors as fl
from locbook.data.example import (
    EXAMPLE_SITE,
    FLOOR_ATTENUATION_DB,
    FLOOR_HEIGHT_M,
    PLAN_FLOOR_RGB,
    PLAN_WALL_RGB,
    write_example_dataset,
)
from locbook.data.measured import DataFormatError
from locbook.scenarios import measured as me

WALK_S = 40.0          # short walks: the battery runs four times on them


@pytest.fixture(scope="module")
def building(tmp_path_factory):
    folder = tmp_path_factory.mktemp("floors") / "building"
    write_example_dataset(folder, np.random.default_rng(3), walk_s=WALK_S, floors=2, floor_plan=True)
    return folder


def _one_line(exc) -> str:
    text = str(exc.value)
    assert "\n" not in text and "Traceback" not in text
    return text


def _count(note: str, recording: str) -> int:
    return int(re.search(rf"([\d,]+) in {recording}\b", note).group(1).replace(",", ""))


# -- loading ------------------------------------------------------------------------------------------------------
def test_a_building_loads_floor_by_floor_with_each_floors_anchors_rows_and_height(building):
    whole = lb.load_dataset(building)
    assert whole.floors == ("F1", "F2") and whole.floor is None and len(whole.anchor_ids) == 16
    with pytest.raises(lb.ParameterError, match="one floor at a time"):
        me.calibrate(whole)                                    # a building is never run as one floor
    anchors = pd.read_csv(building / "anchors.csv", dtype={"id": str})
    for k, floor in enumerate(("F1", "F2")):
        ds = lb.load_dataset(f"{building}@{floor}")
        assert ds.name == lb.load_dataset(building, floor=floor).name == f"example-{floor.lower()}"
        assert ds.floor == floor and ds.selector == f"@{floor}"
        assert list(ds.anchor_ids) == anchors.loc[anchors["floor"] == floor, "id"].tolist()
        # the generated truth: the tag stands k storeys up on floor k (the median of its rows' z_m)
        assert ds.tag_height_m == pytest.approx(EXAMPLE_SITE["tag_height_m"] + k * FLOOR_HEIGHT_M)
        np.testing.assert_allclose(ds.anchors_m[:, 2], EXAMPLE_SITE["anchors_m"][:, 2] + k * FLOOR_HEIGHT_M)
        assert set(ds.recordings) == {"survey", "points", "walk_a" if k == 0 else "walk_b"}
        assert ds.floor_plan == building / "plan.png" and ds.floor_plan_extent_m == (-1.0, 21.0, -1.0, 13.0)
        for name, rec in ds.recordings.items():
            raw = pd.read_csv(building / rec.file.name, dtype={"receiver": str, "floor": str})
            here = raw["floor"] == floor
            mine = raw["receiver"].isin(ds.anchor_ids)
            assert len(rec.readings) == int((here & mine).sum())                 # this floor's tag, its anchors
            assert set(rec.readings["receiver"]) <= set(ds.anchor_ids)
            if name in ("survey", "points"):                                     # spanning the floors: split
                assert "split recordings" in ds.notes and f"{name}: {int(here.sum()):,} of its {len(raw):,}" in \
                    ds.notes["split recordings"]
            # readings of this floor's tag by the other floor's anchors: ignored and counted
            assert _count(ds.notes["cross-floor readings"], name) == int((here & ~mine).sum()) > 0


def test_cross_floor_readings_are_weaker_by_the_floor_attenuation(building):
    """The generated building's readings across a floor are FLOOR_ATTENUATION_DB weaker than the same anchor
    heard at the same plan distance from its own floor, up to the shadowing's spread (an independent check of what
    the loader drops)."""
    raw = pd.read_csv(building / "survey.csv", dtype={"receiver": str, "floor": str})
    raw = raw[pd.to_numeric(raw["rssi_dbm"], errors="coerce").lt(0)]
    raw["rssi_dbm"] = raw["rssi_dbm"].astype(float)
    anchors = pd.read_csv(building / "anchors.csv", dtype={"id": str}).set_index("id")
    a = anchors.loc[raw["receiver"]]
    d = np.sqrt((raw["x_m"].to_numpy() - a["x"].to_numpy()) ** 2 + (raw["y_m"].to_numpy() - a["y"].to_numpy()) ** 2
                + (raw["z_m"].to_numpy() - a["z"].to_numpy()) ** 2)
    j = (raw["receiver"].str[1:].astype(int) - 1).to_numpy()
    mean = EXAMPLE_SITE["ref_power_dbm"][j] - 10 * EXAMPLE_SITE["path_loss_exp"][j] * np.log10(d)
    across = (raw["floor"].to_numpy() != a["floor"].to_numpy())
    near = d < 8.0                     # well above the -95 dBm sensitivity: no truncation of the shadowing
    gap = (mean - raw["rssi_dbm"].to_numpy())
    assert gap[across & near].mean() == pytest.approx(FLOOR_ATTENUATION_DB, abs=0.5)
    assert gap[~across & near].mean() == pytest.approx(0.0, abs=0.5)


def _independent_floor(building, floor, dest):
    """One floor of the building written as a data set of its own from the same files, filtered by pandas: that
    floor's anchors, each file's rows with that truth floor and a receiver on it (no floor column)."""
    dest.mkdir()
    anchors = pd.read_csv(building / "anchors.csv", dtype={"id": str, "floor": str})
    anchors = anchors[anchors["floor"] == floor]
    anchors.drop(columns="floor").to_csv(dest / "anchors.csv", index=False)
    shutil.copy(building / "outline.csv", dest / "outline.csv")
    manifest = (building / "dataset.toml").read_text()
    manifest = manifest.replace('name = "example"', f'name = "example-{floor.lower()}"')
    manifest = re.sub(r'floor_plan.*\n', "", manifest)
    blocks = manifest.split("\n[[recording]]")
    kept = [blocks[0]]
    for block in blocks[1:]:
        file = re.search(r'file = "(.+)"', block).group(1)
        raw = pd.read_csv(building / file, dtype=str, keep_default_na=False)
        rows = raw[(raw["floor"] == floor) & raw["receiver"].isin(anchors["id"])]
        if len(rows):
            rows.drop(columns="floor").to_csv(dest / file, index=False)
            kept.append(block)
    (dest / "dataset.toml").write_text("\n[[recording]]".join(kept))
    return dest


def _battery(ds):
    model = me.channel(me.calibrate(ds))
    proto = me.protocol(ds, model, grid_spacing_m=0.25)         # a coarser grid than the rule's: a faster test
    static = me.static_results(ds, model, proto, seed=4, n_bootstrap=40, block_s=5.0)
    tracking = me.tracking_results(ds, model, proto, seed=4, n_particles=200, particle_runs=2, n_bootstrap=40,
                                   block_s=5.0)
    return static, tracking, model


def test_the_per_floor_battery_is_the_battery_on_each_floor_built_on_its_own(building, tmp_path):
    for floor in ("F1", "F2"):
        static, tracking, model = _battery(lb.load_dataset(building, floor=floor))
        alone = lb.load_dataset(_independent_floor(building, floor, tmp_path / floor))
        static_alone, tracking_alone, model_alone = _battery(alone)
        np.testing.assert_array_equal(model.ref_power_dbm, model_alone.ref_power_dbm)
        np.testing.assert_array_equal(model.path_loss_exp, model_alone.path_loss_exp)
        assert static["rows"] == static_alone["rows"] and len(static["rows"]) > 0
        assert tracking["rows"] == tracking_alone["rows"] and len(tracking["rows"]) > 0
        # the floor's own channel: near the generated one (P_0 of each anchor within its fit's spread)
        assert np.abs(np.asarray(model.ref_power_dbm) - EXAMPLE_SITE["ref_power_dbm"]).max() < 3.0


def _write(path, text):
    path.write_text(text)
    return path


def test_bad_floor_columns_are_refused_in_one_line(building, tmp_path):
    def copy(name):
        dest = tmp_path / name
        shutil.copytree(building, dest)
        return dest

    bad = copy("anchor-empty")
    anchors = (bad / "anchors.csv").read_text().splitlines()
    anchors[3] = anchors[3].rsplit(",", 1)[0] + ","                     # line 4: an anchor without its floor
    _write(bad / "anchors.csv", "\n".join(anchors) + "\n")
    with pytest.raises(DataFormatError) as exc:
        lb.load_dataset(bad)
    assert "line 4, column 'floor': the floor is empty" in _one_line(exc)

    bad = copy("reading-empty")
    survey = pd.read_csv(bad / "survey.csv", dtype=str, keep_default_na=False)
    survey.loc[6, "floor"] = ""                                          # line 8 of the file
    survey.to_csv(bad / "survey.csv", index=False)
    with pytest.raises(DataFormatError) as exc:
        lb.load_dataset(bad)
    assert "survey.csv, line 8, column 'floor': the floor is empty" in _one_line(exc)

    bad = copy("reading-unknown")
    survey.loc[6, "floor"] = "F9"
    survey.to_csv(bad / "survey.csv", index=False)
    with pytest.raises(DataFormatError) as exc:
        lb.load_dataset(bad)
    assert "line 8, column 'floor': floor 'F9' has no anchor" in _one_line(exc)

    bad = copy("readings-without")
    survey.drop(columns="floor").to_csv(bad / "survey.csv", index=False)
    with pytest.raises(DataFormatError) as exc:
        lb.load_dataset(bad)
    assert "survey.csv: no 'floor' column, but the anchors have floors" in _one_line(exc)

    bad = copy("anchors-without")
    pd.read_csv(bad / "anchors.csv").drop(columns="floor").to_csv(bad / "anchors.csv", index=False)
    with pytest.raises(DataFormatError) as exc:
        lb.load_dataset(bad)
    assert "a 'floor' column, but the anchors file has none" in _one_line(exc)

    with pytest.raises(lb.ParameterError) as exc:
        lb.load_dataset(f"{building}@F3")
    assert "has no floor 'F3'; its floors are F1, F2" in _one_line(exc)

    bad = copy("outline-table")
    text = (bad / "dataset.toml").read_text().replace('outline = "outline.csv"\n', "")
    _write(bad / "dataset.toml", text.replace("[epochs]", '[geometry.outline]\nF1 = "outline.csv"\nG7 = "outline.csv"'
                                                          "\n\n[epochs]"))
    with pytest.raises(DataFormatError) as exc:
        lb.load_dataset(bad)
    assert "[geometry] outline: floor(s) ['G7'] have no anchor" in _one_line(exc)


def test_an_outline_table_gives_each_floor_its_own(building, tmp_path):
    dest = tmp_path / "outlines"
    shutil.copytree(building, dest)
    pd.DataFrame({"x": [-0.5, 20.5, 20.5, -0.5], "y": [-0.5, -0.5, 12.5, 12.5]}).to_csv(dest / "wide.csv", index=False)
    text = (dest / "dataset.toml").read_text().replace('outline = "outline.csv"\n', "")
    _write(dest / "dataset.toml", text.replace("[epochs]", '[geometry.outline]\nF2 = "wide.csv"\n\n[epochs]'))
    f1, f2 = (lb.load_dataset(dest, floor=f) for f in ("F1", "F2"))
    np.testing.assert_array_equal(f2.outline_m, pd.read_csv(dest / "wide.csv").to_numpy(float))
    assert "outline" in f1.notes and "outline" not in f2.notes           # F1: none named, the default box


# -- placeholders ----------------------------------------------------------------------------------------------------
def test_placeholder_anchors_at_one_point_load_and_are_ignored(tmp_path):
    plain = write_example_dataset(tmp_path / "plain", np.random.default_rng(8), walk_s=WALK_S)
    held = tmp_path / "held"
    shutil.copytree(plain, held)
    anchors = pd.read_csv(held / "anchors.csv", dtype={"id": str})
    anchors["used"] = "true"
    extra = pd.DataFrame({"id": ["P1", "P2"], "x": [0.0, 0.0], "y": [0.0, 0.0], "z": [0.0, 0.0],
                          "used": ["false", "FALSE"]})
    pd.concat([anchors, extra]).to_csv(held / "anchors.csv", index=False)
    added = {}
    for file in ("survey.csv", "walk_a.csv"):
        raw = pd.read_csv(held / file, dtype=str, keep_default_na=False)
        rows = raw.iloc[::50].copy()
        rows["receiver"] = np.where(np.arange(len(rows)) % 2, "P1", "P2")
        rows["rssi_dbm"] = "-60"
        pd.concat([raw, rows]).to_csv(held / file, index=False)          # out of time order: the manifest sorts
        added[file[:-4]] = len(rows)
    ds, ref = lb.load_dataset(held), lb.load_dataset(plain)
    assert ds.anchor_ids == ref.anchor_ids
    for name, n in added.items():
        assert f"{n:,} in {name}" in ds.notes["placeholder anchors"]
    static, tracking, model = _battery(ds)
    static_ref, tracking_ref, model_ref = _battery(ref)
    assert static["rows"] == static_ref["rows"] and tracking["rows"] == tracking_ref["rows"]
    # without the used column the same two ids at one point are refused, as before
    pd.concat([anchors.drop(columns="used"), extra.drop(columns="used")]).to_csv(held / "anchors.csv", index=False)
    with pytest.raises(DataFormatError) as exc:
        lb.load_dataset(held)
    assert "are at the same position" in _one_line(exc)
    anchors.assign(used="maybe").to_csv(held / "anchors.csv", index=False)
    with pytest.raises(DataFormatError) as exc:
        lb.load_dataset(held)
    assert "line 2, column 'used': 'maybe' is not true or false" in _one_line(exc)


# -- the floor plan --------------------------------------------------------------------------------------------------
def _pixels(fig, points_m=()):
    """The figure's RGB pixels (top row first), each axes' pixel box (x0, x1, top, bottom), and the pixel
    (column, row) of each data point ``(x, y)`` of the first axes."""
    import matplotlib.image as mpimg
    import matplotlib.pyplot as plt
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=fig.dpi)
    height = fig.get_size_inches()[1] * fig.dpi
    boxes = []
    for ax in fig.axes:
        if ax.get_visible():
            b = ax.get_window_extent(fig.canvas.get_renderer())
            boxes.append((int(b.x0) + 2, int(b.x1) - 2, int(height - b.y1) + 2, int(height - b.y0) - 2))
    at = [(int(round(u)), int(round(height - v))) for u, v in fig.axes[0].transData.transform(np.asarray(points_m))]\
        if len(points_m) else []
    plt.close(fig)
    buf.seek(0)
    return mpimg.imread(buf)[..., :3], boxes, at


def _tint(rgb):
    return (np.abs(rgb - np.asarray(PLAN_FLOOR_RGB)) < 3 / 255).all(axis=-1)


def test_the_floor_plan_is_drawn_under_the_map(building):
    from locbook.plotting import draw_floor, map_panels
    ds = lb.load_dataset(building, floor="F1")
    fig, axes = map_panels(ds, 3)
    for ax in axes:
        draw_floor(ax, ds)
        ax.plot([2.0, 18.0], [6.0, 6.0], "-", color="tab:blue", lw=3)      # a track drawn over the plan
    # the plan's georeference (write_floor_plan: an inner wall at x = 0.4 w from y = 0 to 0.3 h and from 0.6 h to
    # h): wall pixels where the walls are, the floor's tint in the door gap, so x and y are neither shifted nor flipped
    probes = [(8.0, 1.5), (8.0, 10.0), (8.0, 4.0), (6.0, 4.0)]
    rgb, boxes, at = _pixels(fig, probes)
    wall = (np.abs(rgb - np.asarray(PLAN_WALL_RGB)) < 0.05).all(axis=-1)
    assert [bool(wall[r - 1:r + 2, c - 1:c + 2].any()) for c, r in at] == [True, True, False, False]
    tint = _tint(rgb)
    inside = np.zeros(tint.shape, bool)
    for x0, x1, top, bottom in boxes:
        inside[top:bottom, x0:x1] = True
        # the hall (20 m x 12 m of the 21 m x 13 m view) is tinted: most of each plot area is the plan's floor
        assert tint[top:bottom, x0:x1].mean() > 0.6
        # the track lies over the plan: its colour, not the tint, at the middle of its line (y = 6 m)
        row = top + int((bottom - top) * (13.0 - 6.5) / 13.0)
        assert not tint[row - 1:row + 2, (x0 + x1) // 2].any()
    assert not tint[~inside].any()                                      # the plan stays inside the plot areas
    # the same map without a plan has no tint at all
    plain = lb.load_dataset(building, floor="F1")
    object.__setattr__(plain, "floor_plan", None)
    fig, axes = map_panels(plain, 1)
    draw_floor(axes[0], plain)
    assert not _tint(_pixels(fig)[0]).any()
    # deterministic bytes: the same map drawn twice saves the same PNG (as report.figure saves it)
    saved = []
    for _ in range(2):
        fig, axes = map_panels(ds, 2)
        for ax in axes:
            draw_floor(ax, ds)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", bbox_inches="tight", metadata={"Software": None})
        saved.append(buf.getvalue())
    assert saved[0] == saved[1]


def test_bad_floor_plans_and_extents_are_refused_in_one_line(building, tmp_path):
    dest = tmp_path / "plan"
    shutil.copytree(building, dest)
    good = (dest / "dataset.toml").read_text()

    def refused(text=None, plan: bytes | None = None):
        _write(dest / "dataset.toml", good if text is None else text)
        if plan is not None:
            (dest / "bad.png").write_bytes(plan)
        with pytest.raises(DataFormatError) as exc:
            lb.load_dataset(dest)
        return _one_line(exc)

    with_bad = good.replace('floor_plan = "plan.png"', 'floor_plan = "bad.png"')
    assert "bad.png is not a PNG" in refused(with_bad, b"GIF89a not a png at all")
    png = (dest / "plan.png").read_bytes()
    assert "bad.png: matplotlib cannot read it" in refused(with_bad, png[:60])       # truncated
    assert "does not exist" in refused(good.replace('"plan.png"', '"absent.png"'))
    assert "must be a file inside the data set's folder" in refused(good.replace('"plan.png"', '"../plan.png"'))
    extent = "floor_plan_extent_m = [-1, 21, -1, 13]"
    assert "needs x0 < x1 and y0 < y1" in refused(good.replace(extent, "floor_plan_extent_m = [21, -1, -1, 13]"))
    assert "four finite numbers" in refused(good.replace(extent, "floor_plan_extent_m = [nan, 21, -1, 13]"))
    assert "four finite numbers" in refused(good.replace(extent, "floor_plan_extent_m = [0, 21, 13]"))
    assert "floor_plan needs floor_plan_extent_m too" in refused(good.replace(extent + "\n", ""))
    assert "floor_plan_extent_m needs floor_plan too" in refused(good.replace('floor_plan = "plan.png"\n', ""))


# -- map and track figures -------------------------------------------------------------------------------------------
def test_the_map_layout_follows_the_rooms_aspect():
    from locbook.plotting import MAP_PANEL_PAD_IN, map_layout

    def figure_aspect(view, ncols, n):
        """Width over height of the grid with ncols columns (slots of the room's aspect, a pad for the title)."""
        ratio = (view[3] - view[2]) / (view[1] - view[0])
        w = min(15.0 / ncols, 8.0 / ratio)
        return ncols * w / (-(-n // ncols) * (w * ratio + MAP_PANEL_PAD_IN))

    for view, n in (((0, 27, 0, 10), 9), ((0, 11, 0, 11), 9), ((0, 21, 0, 13), 8), ((0, 6, 0, 40), 5)):
        nrows, ncols, (width, height) = map_layout(view, n)
        assert nrows * ncols >= n > (nrows - 1) * ncols                   # no empty row
        ratio = (view[3] - view[2]) / (view[1] - view[0])
        # each slot has the room's aspect: the floor fills its panel's width at equal scale
        assert (height / nrows - MAP_PANEL_PAD_IN) / (width / ncols) == pytest.approx(ratio, rel=1e-3)
        # no other column count gives a figure nearer to square
        mine = abs(np.log(figure_aspect(view, ncols, n)))
        assert all(mine <= abs(np.log(figure_aspect(view, c, n))) + 1e-9 for c in range(1, n + 1))
    # the hall, 26 m x 9 m: 2 wide columns of 9 panels (not 4 columns of tiny ones); a square room more
    assert map_layout((0, 27, 0, 10), 9)[1] == 2 and map_layout((0, 11, 0, 11), 9)[1] >= 3


def test_a_view_widens_to_the_estimates_that_leave_the_room_and_marks_the_farther_ones():
    import matplotlib.pyplot as plt

    from locbook.plotting import map_row, mark_beyond_view, points_view_m
    room = (-1.0, 3.0, -1.0, 9.0)
    pts = np.array([[1.0, 4.0], [-4.0, 2.0], [2.0, 12.5], [30.0, 4.0], [np.nan, 0.0], [1.0, -20.0]])
    # within 5 m of the view: (-4, 2) 3 m left, (2, 12.5) 3.5 m above; (30, 4) 27 m and (1, -20) 19 m out stay out
    view = points_view_m(room, pts, reach_m=5.0, pad_m=0.5)
    assert view == pytest.approx((-4.5, 3.0, -1.0, 13.0))
    assert points_view_m(room, pts[:1], reach_m=5.0) == pytest.approx(room)        # inside: the view as it was
    fig, (left, right) = map_row([view, (-1.0, 3.0, view[2], view[3])], height_in=6.0)
    try:
        assert left.get_xlim() == pytest.approx((-4.5, 3.0)) and right.get_ylim() == pytest.approx((-1.0, 13.0))
        # one scale: the panels' widths are in proportion to their x ranges (7.5 m against 4 m)
        fig.canvas.draw()
        w_left, w_right = (ax.get_position().width for ax in (left, right))
        assert w_left / w_right == pytest.approx(7.5 / 4.0, rel=0.02)
        assert mark_beyond_view(left, pts) == 2
        line = left.lines[-1]
        edge = np.column_stack([line.get_xdata(), line.get_ydata()])
        # on the view's edge, each in its direction from the centre (-0.75, 6): (30, 4) at x = 3, (1, -20) at y = -1
        assert edge[0] == pytest.approx([3.0, 6.0 - 2.0 * 3.75 / 30.75]) and edge[1][1] == pytest.approx(-1.0)
        assert "2 beyond the view" in left.texts[-1].get_text() and "27.0 m out" in left.texts[-1].get_text()
    finally:
        plt.close(fig)


def test_the_track_figure_draws_every_tracker_yours_included(building):
    import matplotlib.pyplot as plt

    from locbook.plotting import map_view_m, tracks_figure
    ds = lb.load_dataset(building, floor="F2")
    t = np.linspace(0, 1, 30)
    truth = np.column_stack([2 + 16 * t, 3 + 6 * t])
    trackers = [*me.TRACKERS, "centroid"]
    est = {k: (truth + 0.1 * i)[None] for i, k in enumerate(trackers)}
    fig = tracks_figure(ds, {"walk_b": (truth, None, est)}, trackers)
    shown = [ax for ax in fig.axes if ax.get_visible()]
    assert [ax.get_title() for ax in shown] == trackers and len(trackers) == 8
    x0, x1, y0, y1 = map_view_m(ds.outline_m)
    for ax in shown:
        assert ax.get_xlim() == (x0, x1) and ax.get_ylim() == (y0, y1) and ax.get_aspect() == 1.0
        assert len(ax.images) == 1                                       # the floor plan under it
    plt.close(fig)


def test_floor_selectors_and_runs(building):
    assert fl.split_floor_selector(f"{building}@F2") == (str(building), "F2")
    assert fl.split_floor_selector(str(building)) == (str(building), None)
    assert fl.floor_runs(str(building)) == [f"{building}@F1", f"{building}@F2"]
    assert fl.floor_runs(f"{building}@F1") == [f"{building}@F1"]
    assert fl.floor_runs("kolakowski2021") == ["kolakowski2021"]
    assert fl.floor_slug("Ground_Floor") == "ground-floor"


def test_the_default_example_is_unchanged_by_the_new_options(tmp_path):
    """floors=1 and no plan write the default example byte for byte (the building draws on its own path), and a
    plan alone adds its file and two manifest lines, the readings unchanged."""
    a = write_example_dataset(tmp_path / "a", np.random.default_rng(1))
    b = write_example_dataset(tmp_path / "b", np.random.default_rng(1), floors=1, floor_plan=False)
    c = write_example_dataset(tmp_path / "c", np.random.default_rng(1), floor_plan=True)
    for f in sorted(p.name for p in a.iterdir()):
        assert (a / f).read_bytes() == (b / f).read_bytes()
        if f != "dataset.toml":
            assert (a / f).read_bytes() == (c / f).read_bytes()
    assert sorted(p.name for p in c.iterdir()) == sorted([*(p.name for p in a.iterdir()), "plan.png"])
    extra = set((c / "dataset.toml").read_text().splitlines()) - set((a / "dataset.toml").read_text().splitlines())
    assert extra == {'floor_plan = "plan.png"', "floor_plan_extent_m = [-1, 21, -1, 13]"}
    assert (c / "plan.png").read_bytes() == write_example_dataset(tmp_path / "d", np.random.default_rng(2),
                                                                  floor_plan=True).joinpath("plan.png").read_bytes()


def test_a_run_on_a_building_is_one_data_run_per_floor(building, tmp_path, monkeypatch, capsys):
    """`locbook run --data DIR` on a data set with floors: one data run per floor, each its own folder
    (data-<name>-<floor>/) whose tasks get DIR@FLOOR; `--data DIR@F2` runs that floor alone (run_tasks stood in
    for, as in test_data_runs: the command line up to where notebooks would run)."""
    import json

    from locbook.suite import run as suite_run
    from locbook.suite import runner
    from locbook.suite.cli import main
    seen = []

    def run_tasks(suite, tasks, profile, report_dir, *, write_reports, progress="plain", **_kwargs):
        seen.append((report_dir.name, {t.key: t.parameters["data"] for t in tasks}))
        report_dir.mkdir(parents=True, exist_ok=True)
        outcomes = [runner.Outcome(t.key, "ok", 0.0) for t in tasks]
        write_reports(report_dir, outcomes)
        return runner.SuiteRun(outcomes, report_dir)

    monkeypatch.setattr(runner, "run_tasks", run_tasks)
    assert main(["run", "--data", str(building), "--reports", str(tmp_path / "r"), "--quiet"]) == 0
    assert [name for name, _ in seen] == ["data-example-f1", "data-example-f2"]
    for (name, data), floor in zip(seen, ("F1", "F2")):
        values = {v if isinstance(v, str) else v[0] for v in data.values()}
        assert values == {f"{building}@{floor}"} and "measured-tracking" in data
        record = json.loads((tmp_path / "r" / "quick" / name / "dataset.json").read_text())
        assert record["data set"] == f"{building}@{floor}" and record["name"] == name[len("data-"):]
    out = capsys.readouterr().out
    assert f"data set {building}@F1" in out and f"data set {building}@F2" in out
    seen.clear()
    assert main(["run", "--data", f"{building}@F2", "--reports", str(tmp_path / "r"), "--quiet"]) == 0
    assert [name for name, _ in seen] == ["data-example-f2"]
    # a building given to the runner itself (not through the command line's loop) is refused in one line
    with pytest.raises(lb.ParameterError, match="one floor at a time"):
        suite_run.load_data_argument(str(building))


def test_per_floor_tables_of_plan_and_height(building, tmp_path):
    dest = tmp_path / "tables"
    shutil.copytree(building, dest)
    text = (dest / "dataset.toml").read_text()
    text = re.sub(r"floor_plan.*\n", "", text)
    text = text.replace("[epochs]", '[geometry.floor_plan]\nF2 = "plan.png"\n\n[geometry.floor_plan_extent_m]\n'
                                     'F2 = [-1.0, 21.0, -1.0, 13.0]\n\n[geometry.tag_height_m]\nF1 = 1.1\nF2 = 4.3\n\n'
                                     "[epochs]")
    _write(dest / "dataset.toml", text)
    whole = lb.load_dataset(dest)
    assert whole.floor_plan is None and whole.floors == ("F1", "F2")
    f1, f2 = (lb.load_dataset(dest, floor=f) for f in ("F1", "F2"))
    assert (f1.floor_plan, f2.floor_plan) == (None, dest / "plan.png")
    assert (f1.tag_height_m, f2.tag_height_m) == (1.1, 4.3) and f1.tag_height_source == "manifest"
    _write(dest / "dataset.toml", text.replace('[geometry.floor_plan]\nF2 = "plan.png"', '[geometry.floor_plan]\n'
                                                                                        'F1 = "plan.png"'))
    with pytest.raises(DataFormatError) as exc:
        lb.load_dataset(dest)
    assert "floor 'F1': a floor_plan needs its floor_plan_extent_m" in _one_line(exc)
