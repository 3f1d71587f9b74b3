"""The report site in a real browser: every link and image of index.html and of each page it links resolves.

A toy suite (three notebooks: one that records a number, a figure, a table and an assumption; one that fails;
one never run) is run with papermill into a temporary reports folder. Headless Chromium (Debian's
``chromium`` and ``chromium-driver``, driven by selenium) then opens ``index.html`` from file://, follows every
link to a local HTML page, and checks on each page that every ``a[href]`` and ``img[src]`` names a file that
exists and that every image loaded. A screenshot of the index goes to ``$LOCBOOK_SCREENSHOT_DIR`` (default
``.ci/artifacts/``, git-ignored).
"""
from __future__ import annotations

import os
import shutil
import urllib.parse
import urllib.request
from pathlib import Path

import pytest

from builders import REPO_ROOT
from locbook.suite import load_suite, run_suite
from toy_suite import (
    READINGS,
    STUDY_BODY,
    STUDY_PARAMS,
    TOY_STUDY,
    _notebook,
    document_toml,
    example,
    experiment_toml,
    suite_toml,
    write_data_folder,
)

pytestmark = [pytest.mark.notebooks, pytest.mark.browser]   # executes (toy) notebooks with papermill

REPO = REPO_ROOT
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")

PARAMS = "seed: int = 1  # seed\nn: int = 12  # samples\nfail: bool = False  # raise at the end\n"
BODY = """\
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import locbook as lb
report = lb.Report("toy")
x = lb.streams(seed, "a")["a"].normal(size=n)
printed = lb.Printed("george", "Table 1", "mean", "", "", "0.0")
report.number("mean", printed, float(x.mean()), kind="reproduction",
              ambiguity=lb.Ambiguity(1.0, "test window", "toy Sec. 1"))
fig, ax = plt.subplots(figsize=(3, 2))
ax.plot(x)
report.figure(fig, "trace", "the <toy> samples & their order")
report.table("samples", [{"i": i, "x": float(v)} for i, v in enumerate(x)], "the samples")
report.assumption("n", n, "small, to keep the test fast")
if fail:
    raise RuntimeError("deliberate failure")
"""
TOML = "\n" + suite_toml(
    experiment_toml("george-good", "toy.ipynb", title="A good experiment", section="Table 1"),
    experiment_toml("george-failed", "toy.ipynb", title="A failing experiment", section="Table 2",
                    quick={"fail": True}, full={"fail": True}),
    experiment_toml("george-absent", "toy.ipynb", title="An experiment not run", section="Table 3"),
    document=document_toml(title="A toy document", authors="A. Author"), rules={"n": {"ge": 1}})


def _toy_suite(root: Path):
    nbdir = root / "notebooks"
    nbdir.mkdir(parents=True)
    _notebook(nbdir / "toy.ipynb", PARAMS, BODY)
    (nbdir / "experiments.toml").write_text(TOML)
    return load_suite(nbdir / "experiments.toml")


@pytest.fixture(scope="module")
def browser():
    if not (CHROMIUM and CHROMEDRIVER):
        pytest.skip("needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver; "
                    ".ci/run installs them): " + ", ".join(n for n, p in (("chromium", CHROMIUM),
                                                                         ("chromedriver", CHROMEDRIVER)) if not p)
                    + " not found")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--window-size=1400,1000",
                "--allow-file-access-from-files"):
        options.add_argument(arg)
    options.binary_location = CHROMIUM
    driver = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
    driver.set_page_load_timeout(60)
    try:
        yield driver
    finally:
        driver.quit()


@pytest.fixture(scope="module")
def site_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("site")
    suite = _toy_suite(root / "repo")
    chosen = [e for e in suite.experiments if e.id != "george-absent"]
    run = run_suite(suite, chosen, "quick", report_root=root / "reports", jobs=2, progress="quiet")
    assert {o.id: o.status for o in run.outcomes} == {"george-good": "ok", "george-failed": "failed"}
    return run.report_dir


def _local_file(url: str) -> Path | None:
    """The file a file:// URL names (query and fragment dropped); ``None`` for any other scheme."""
    parts = urllib.parse.urlsplit(url)
    if parts.scheme != "file":
        return None
    return Path(urllib.request.url2pathname(parts.path))


def check_page(driver, page: Path) -> tuple[list[str], list[str], list[Path]]:
    """Open ``page`` from file:// and return ``(broken, external, linked pages)``: the ``href`` / ``src`` values
    (as written) whose local file is missing, and the images that did not load; the links that leave the
    machine; the local HTML pages it links to."""
    driver.get(page.as_uri())
    refs = driver.execute_script("""
        return [].concat(
            Array.from(document.querySelectorAll('a[href]'), a => [a.getAttribute('href'), a.href]),
            Array.from(document.querySelectorAll('img[src]'), i => [i.getAttribute('src'), i.src]));""")
    broken, external, pages = [], [], []
    for raw, resolved in refs:
        target = _local_file(resolved)
        if target is None:
            if not resolved.startswith("data:"):
                external.append(raw)
        elif not target.is_file():
            broken.append(raw)
        elif target.suffix == ".html" and target != page:
            pages.append(target)
    not_loaded = driver.execute_script(
        "return Array.from(document.images).filter(i => !(i.complete && i.naturalWidth > 0))"
        ".map(i => i.getAttribute('src'));")
    broken += [f"image not loaded: {src}" for src in not_loaded]
    return broken, external, pages


def crawl(driver, start: Path, inside: Path) -> dict[Path, tuple[list[str], list[str]]]:
    """Every local HTML page reachable from ``start`` within the folder ``inside``: its broken and its external
    references."""
    seen, todo = {}, [start.resolve()]
    while todo:
        page = todo.pop()
        if page in seen:
            continue
        broken, external, pages = check_page(driver, page)
        seen[page] = (broken, external)
        todo += [p.resolve() for p in pages if p.resolve().is_relative_to(inside.resolve())]
    return seen


def _screenshot_dir() -> Path:
    folder = Path(os.environ.get("LOCBOOK_SCREENSHOT_DIR") or REPO / ".ci" / "artifacts")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def test_the_checker_finds_a_broken_link_and_a_broken_image(browser, tmp_path):
    (tmp_path / "there.html").write_text("<!doctype html><title>there</title><p>here")
    page = tmp_path / "page.html"
    page.write_text('<!doctype html><title>t</title><a href="there.html">ok</a> <a href="#top">self</a> '
                    '<a href="missing.html">gone</a> <a href="sub/missing.csv?x=1#y">gone too</a> '
                    '<img src="missing.png" alt="gone"> <a href="https://example.org/">out</a>')
    broken, external, pages = check_page(browser, page)
    assert broken == ["missing.html", "sub/missing.csv?x=1#y", "missing.png", "image not loaded: missing.png"]
    assert external == ["https://example.org/"]
    assert [p.resolve() for p in pages] == [(tmp_path / "there.html").resolve()]


def test_every_link_and_image_of_the_site_resolves(browser, site_dir, tmp_path):
    from selenium.webdriver.common.by import By

    index = site_dir / "index.html"
    pages = crawl(browser, index, site_dir)
    problems = {str(p.relative_to(site_dir.resolve())): b for p, (b, _e) in pages.items() if b}
    assert problems == {}
    visited = {p.relative_to(site_dir.resolve()).as_posix() for p in pages}
    assert visited == {"index.html", "george-good/report.html", "george-good/george-good.html"}
    for name in ("index.html", "george-good/report.html"):             # the site itself never leaves the machine
        assert pages[(site_dir / name).resolve()][1] == [], name
    # no page loads a script or style sheet from the network (the notebook page's math is SVG, not MathJax)
    for page in pages:
        browser.get(page.as_uri())
        remote = [e.get_attribute("src") or e.get_attribute("href") for e in
                  browser.find_elements(By.CSS_SELECTOR, "script[src], link[href]")
                  if (e.get_attribute("src") or e.get_attribute("href") or "").startswith(("http:", "https:"))]
        assert remote == [], page
    # every experiment page with compared numbers shows ours against printed (an inline SVG per table)
    for page in pages:
        if page.name == "report.html":
            browser.get(page.as_uri())
            scored = browser.find_elements(By.XPATH, "//h2[text()='Reproduced versus printed']/following::table[1]"
                                                     "//td[@class='v-within' or @class='v-loose' or @class='v-miss']")
            plots = browser.find_elements(By.CSS_SELECTOR, "figure.pvo svg")
            assert bool(scored) == bool(plots), page
            for plot in plots:
                assert plot.size["width"] >= 200 and plot.find_elements(By.CSS_SELECTOR, "circle"), page

    # the index: kind-by-verdict tables coloured by verdict, one row per experiment, run status as text
    browser.get(index.as_uri())
    shots = [tmp_path / "site-index.png", _screenshot_dir() / "site-index.png"]
    for shot in shots:
        assert browser.save_screenshot(str(shot)) and shot.stat().st_size > 0
    # generated from the rows (the answer per document is a list of its own above)
    findings = browser.find_elements(By.CSS_SELECTOR, "ul.findings:not(.answer) li")
    answers = browser.find_elements(By.CSS_SELECTOR, "ul.answer li")
    assert len(answers) == 1 and answers[0].text.startswith("A. Author (2015), george: 0 of 1 scored printed numbers")
    assert [f.text for f in findings] == ["A. Author (2015), george: Of 1 printed number reproduced independently, 0 "
                                          "are within its window, 1 loose (a window too wide to decide) and 0 missed."]
    counts = browser.find_element(By.CSS_SELECTOR, "table.counts")
    assert [c.text for c in counts.find_elements(By.CSS_SELECTOR, "thead th")] == ["kind", "loose", "rows"]
    reproduction = counts.find_element(By.XPATH, ".//tr[th='reproduction']")
    assert "v-loose" in reproduction.find_element(By.TAG_NAME, "td").get_attribute("class")
    body = browser.find_element(By.TAG_NAME, "body").text
    assert "Independent reproductions: 0 within, 1 loose, 0 missed, of 1" in body
    rows = {r.get_attribute("id"): r for r in browser.find_elements(By.CSS_SELECTOR, "table.experiments tbody tr")}
    assert list(rows) == ["george-good", "george-failed", "george-absent"]
    good = [a.get_attribute("href") for a in rows["george-good"].find_elements(By.TAG_NAME, "a")]
    assert (site_dir / "george-good" / "report.html").resolve().as_uri() in good
    assert (site_dir / "george-good" / "george-good.html").resolve().as_uri() in good
    assert "ok" in rows["george-good"].find_element(By.CSS_SELECTOR, "td.status").text
    shaded = rows["george-good"].find_element(By.CSS_SELECTOR, "td.shares").value_of_css_property("background-image")
    assert shaded == "linear-gradient(to right, rgb(255, 241, 194) 0%, rgb(255, 241, 194) 100%)"
    # (one loose row: the whole cell amber, site.css's --loose as the browser computes it)
    failed = rows["george-failed"]
    assert "failed" in failed.find_element(By.CSS_SELECTOR, ".flag").text
    assert "deliberate failure" in failed.find_element(By.CSS_SELECTOR, ".err").text
    assert [a.text for a in failed.find_elements(By.TAG_NAME, "a")] == ["failed notebook"]
    assert "v-" not in failed.find_element(By.CSS_SELECTOR, "td.status").get_attribute("class")
    assert "not run" in rows["george-absent"].text and rows["george-absent"].find_elements(By.TAG_NAME, "a") == []

    # an experiment's page: back link, parameters, the figure (loaded), the table, numbers coloured by verdict
    page = site_dir / "george-good" / "report.html"
    browser.get(page.as_uri())
    browser.save_screenshot(str(_screenshot_dir() / "site-page.png"))
    plot = browser.find_element(By.CSS_SELECTOR, "figure.pvo")
    assert "Table 1" in plot.find_element(By.TAG_NAME, "figcaption").text
    assert len(plot.find_elements(By.CSS_SELECTOR, "circle")) == 1              # the one compared number
    plot.screenshot(str(_screenshot_dir() / "site-printed-versus-ours.png"))
    text = browser.find_element(By.TAG_NAME, "body").text
    assert "A good experiment" in text and "A. Author" in text and "Table 1" in text
    assert "the <toy> samples & their order" in text                       # escaped, shown as written
    assert browser.find_elements(By.TAG_NAME, "toy") == []
    links = {a.text: a.get_attribute("href") for a in browser.find_elements(By.TAG_NAME, "a")}
    assert any(href.endswith("/index.html") for href in links.values())
    assert links["executed notebook"].endswith("/george-good/george-good.html")
    img = browser.find_element(By.CSS_SELECTOR, "figure img")
    assert img.get_attribute("src").endswith("/george-good/trace.png")
    assert browser.execute_script("return arguments[0].complete && arguments[0].naturalWidth > 0", img)
    verdict = browser.find_element(By.XPATH, "//h2[text()='Reproduced versus printed']/following::table[1]"
                                             "//td[text()='loose']")
    assert "v-loose" in verdict.get_attribute("class")
    # parameters and assumptions are folded below the results: closed until a reader opens them
    assert "small, to keep the test fast" not in text
    browser.execute_script("document.querySelectorAll('details.folded').forEach(d => d.open = true)")
    text = browser.find_element(By.TAG_NAME, "body").text
    assert "test window (toy Sec. 1)" in text and "small, to keep the test fast" in text
    # the results lead: the printed-versus-ours plot and the figures come before the parameters
    order = browser.execute_script("return Array.from(document.querySelectorAll('h2'), h => h.textContent)")
    assert order.index("Reproduced versus printed") < order.index("Figures") < order.index(
        "Parameters and assumptions")
    assert "samples.csv" in links and "numbers in LaTeX" in links


def test_a_data_sets_page_shows_its_results_table_first(browser, tmp_path):
    """A data set's page (reports/<profile>/data-<name>/index.html) opens with the answer: the first table
    a reader sees is the results table, and every link and image of the page resolves."""
    from selenium.webdriver.common.by import By

    folder = example(tmp_path / "set", ("calibration", "static"), name="mine")
    report_dir = tmp_path / "reports" / "quick" / "data-mine"
    record = write_data_folder(report_dir, folder, load_suite())
    index = report_dir / "index.html"
    broken, external, _pages = check_page(browser, index)
    assert broken == [] and external == []
    assert browser.find_element(By.TAG_NAME, "h1").text == record["title"]
    first = next(t for t in browser.find_elements(By.TAG_NAME, "table") if t.is_displayed())
    assert "results" in first.get_attribute("class").split()
    head = [th.text for th in first.find_elements(By.CSS_SELECTOR, "thead th")]
    assert head[:5] == ["method", "recording", "epochs", "coverage", "mean (m)"] and "ratio" in head
    cells = [td.text for td in first.find_element(By.CSS_SELECTOR, "tbody tr").find_elements(By.TAG_NAME, "td")]
    assert cells[:2] == ["lls", "pooled"]                      # each method's pooled row first
    # the table sits above the fold of a 1400 x 1000 window: the page opens with it
    assert first.location["y"] < 1000
    assert record["attribution"] in browser.find_element(By.TAG_NAME, "body").text
    for shot in (tmp_path / "data-index.png", _screenshot_dir() / "data-index.png"):
        assert browser.save_screenshot(str(shot))
        data = shot.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 1000


def test_a_floor_plan_is_drawn_under_the_map_on_a_data_sets_page(browser, tmp_path):
    """On a data run whose data set has a floor plan, the page's map image loads and shows the plan: the
    plan's floor tint fills most of the map as the browser draws it (a screenshot of the image element)."""
    import io

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.image as mpimg
    import matplotlib.pyplot as plt
    import numpy as np
    from selenium.webdriver.common.by import By

    import locbook as lb
    from locbook.data.example import PLAN_FLOOR_RGB, write_example_dataset
    from locbook.plotting import draw_floor, map_panels

    folder = write_example_dataset(tmp_path / "set", np.random.default_rng(3), name="mine", walk_s=30.0,
                                   roles=("calibration", "static"), floor_plan=True)
    ds = lb.load_dataset(folder)
    report_dir = tmp_path / "reports" / "quick" / "data-mine"
    loc = report_dir / "measured-localization"
    loc.mkdir(parents=True)
    truth = ds.epochs("points").position_m[:, :2]
    fig, axes = map_panels(ds, 2)              # the map figure as measured-localization draws it
    for ax in axes:
        draw_floor(ax, ds)
        ax.plot(truth[:, 0], truth[:, 1], ".", color="0.6", ms=2)
    fig.savefig(loc / "maps.png", dpi=110, bbox_inches="tight", metadata={"Software": None})
    plt.close(fig)
    write_data_folder(report_dir, folder, load_suite())
    index = report_dir / "index.html"
    broken, external, _pages = check_page(browser, index)
    assert broken == [] and external == []
    img = next(i for i in browser.find_elements(By.CSS_SELECTOR, "img") if i.get_attribute("src").endswith(
        "/measured-localization/maps.png"))
    assert browser.execute_script("return arguments[0].complete && arguments[0].naturalWidth > 0", img)
    browser.execute_script("arguments[0].scrollIntoView()", img)
    shot = mpimg.imread(io.BytesIO(img.screenshot_as_png))[..., :3]
    tint = (np.abs(shot - np.asarray(PLAN_FLOOR_RGB)) < 4 / 255).all(axis=-1)
    assert tint.mean() > 0.3                    # the hall's floor tint: the plan is under the map
    for target in (tmp_path / "data-floor-plan.png", _screenshot_dir() / "data-floor-plan.png"):
        assert img.screenshot(str(target))


def test_a_p_runs_index_links_its_comparison_with_the_base(browser, site_dir, tmp_path):
    """A ``-p`` run beside the toy site's quick run: its index links ``compare-quick.html``, whose every link
    resolves (back to both runs' indexes and to its CSV) and whose table shows the one printed number in both runs
    with the difference."""
    from selenium.webdriver.common.by import By

    suite = load_suite(site_dir.parents[1] / "repo" / "notebooks" / "experiments.toml")
    good = [e for e in suite.experiments if e.id == "george-good"]
    variant = run_suite(suite, good, "quick", overrides={"n": "30"}, report_root=site_dir.parent, jobs=1,
                        progress="quiet")
    assert [o.status for o in variant.outcomes] == ["ok"]
    pages = crawl(browser, variant.report_dir / "index.html", variant.report_dir)
    compare_page = (variant.report_dir / "compare-quick.html").resolve()
    assert compare_page in pages
    for page, (broken, external) in pages.items():
        assert broken == [] and external == [], (page, broken, external)
    browser.get(compare_page.as_uri())
    assert "against" in browser.find_element(By.TAG_NAME, "h1").text
    hrefs = {a.get_attribute("href") for a in browser.find_elements(By.CSS_SELECTOR, "a[href]")}
    assert (site_dir / "index.html").resolve().as_uri() in hrefs            # the base run's index
    changed = [td.text for td in browser.find_element(By.XPATH, "//h2[text()='Parameters that differ']"
                                                          "/following::table[1]//tbody/tr").find_elements(
        By.TAG_NAME, "td")]
    assert changed == ["george-good", "quick", "n", "12 (the notebook's default)", "30"]
    table = browser.find_element(By.CSS_SELECTOR, "table.compare")
    head = [th.text for th in table.find_elements(By.CSS_SELECTOR, "thead th")]
    assert head[:6] == ["quantity", "where", "printed", "base", "variant", "difference"]
    first = [td.text for td in table.find_element(By.CSS_SELECTOR, "tbody tr").find_elements(By.TAG_NAME, "td")]
    assert first[0].startswith("mean") and first[3] != first[4]              # n = 12 against n = 30: other draws
    assert float(first[5]) == pytest.approx(float(first[4]) - float(first[3]), abs=2e-3)   # 4 digits shown
    for shot in (tmp_path / "site-compare.png", _screenshot_dir() / "site-compare.png"):
        assert browser.save_screenshot(str(shot)) and shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def sweeps(tmp_path_factory):
    """The toy study (8 points) and a toy bracket (5 points) of one toy repository, run through the CLI."""
    from locbook.suite.cli import main
    root = tmp_path_factory.mktemp("sweeps")
    nbdir = root / "repo" / "notebooks"
    nbdir.mkdir(parents=True)
    _notebook(nbdir / "study.ipynb", STUDY_PARAMS, STUDY_BODY)
    (nbdir / "experiments.toml").write_text(suite_toml(document=document_toml()) + TOY_STUDY)
    (root / "interpretations.csv").write_text(READINGS)
    common = ["--suite", str(nbdir / "experiments.toml")]
    assert main([*common, "study", "toy", "--reports", str(root / "reports"), "--progress", "quiet"]) == 0
    assert main([*common, "bracket", "george-study", "--interpretations", str(root / "interpretations.csv"),
                 "--reports", str(root / "reports"), "--progress", "quiet"]) == 0
    return root / "reports"


def test_a_studys_page_shows_its_points_by_their_settings_and_its_plots(browser, sweeps, tmp_path):
    from selenium.webdriver.common.by import By
    page = sweeps / "studies" / "toy" / "index.html"
    broken, external, _pages = check_page(browser, page)
    assert broken == [] and external == []
    images = browser.find_elements(By.CSS_SELECTOR, ".plots img")
    assert len(images) == 2                      # the collected value, against a and against b
    rows = [[td.text for td in tr.find_elements(By.TAG_NAME, "td")]
            for tr in browser.find_elements(By.CSS_SELECTOR, "table tbody tr")]
    assert len(rows) == 4                        # 4 points, the 2 replicates of each joined
    value = {r[2]: r for r in rows if r[1].startswith("value")}
    # value = 10 a + b + seed, seeds 3 and 4: the replicates' mean 10 a + b + 3.5, its SE 0.5 / sqrt(2) x sqrt(2)/2
    # (two values 1 apart: sample sd 0.7071, over sqrt(2): 0.5)
    row = value["a=1.5, b=0.5, tag=q"]
    assert float(row[4]) == pytest.approx(15 + 0.5 + 3.5) and float(row[5]) == pytest.approx(0.5)
    assert row[6] == "2"
    body = browser.find_element(By.TAG_NAME, "body").text
    assert "george-study-" not in body and "built-in method" not in body     # no hash, no Python repr
    assert "a (grid [1.0, 1.5])" in body
    for shot in (tmp_path / "site-study.png", _screenshot_dir() / "site-study.png"):
        assert browser.save_screenshot(str(shot))


def test_a_brackets_page_draws_a_strip_per_printed_number(browser, sweeps, tmp_path):
    from selenium.webdriver.common.by import By
    page = sweeps / "brackets" / "george-study" / "index.html"
    broken, external, _pages = check_page(browser, page)
    assert broken == [] and external == []
    strips = browser.find_elements(By.CSS_SELECTOR, "svg.strip")
    assert len(strips) == 2                      # value and twice
    for strip in strips:                          # every one of the 5 points a dot on its window
        assert len(strip.find_elements(By.CSS_SELECTOR, "circle.ours")) == 5
        assert len(strip.find_elements(By.CSS_SELECTOR, "line.window")) == 5
        assert len(strip.find_elements(By.CSS_SELECTOR, "line.printed")) == 1
    labels = [e.text for e in strips[0].find_elements(By.CSS_SELECTOR, "text.label")]
    assert labels == ["default", "slope: a=1.3", "slope: a=0.0", "slope: a=2.0", "offset: b=0.5"]
    # value = 10 a + b + 3 against 16.0: a = 1.3 gives 16, within; the default (a = 1) gives 13, a miss
    classes = [g.get_attribute("class") for g in strips[0].find_elements(By.CSS_SELECTOR, "g")]
    assert classes[0] == "v-miss default" and classes[1] == "v-within"
    assert "george-study-" not in browser.find_element(By.TAG_NAME, "body").text
    strips[0].screenshot(str(_screenshot_dir() / "site-bracket-strip.png"))
    for shot in (tmp_path / "site-bracket.png", _screenshot_dir() / "site-bracket.png"):
        assert browser.save_screenshot(str(shot))
