"""The curated top-level API: one home module per name, listed in docs/architecture.md's table, constants left in their
modules, every name importable and defined where the table says. And its one argument convention: readings
first, then the model, then keyword-only options, ``rng`` keyword-only everywhere; the families of functions that share
a call form, listed in docs/architecture.md's "Call forms" table, each with its result type and the one result
vocabulary of the filters."""
import importlib
import inspect
import re
from typing import NamedTuple

import pytest

import locbook
from builders import REPO_ROOT

API_DOC = REPO_ROOT / "docs" / "architecture.md"


def public_api_section() -> str:
    if not API_DOC.exists():   # the installed package is tested without the clone's docs
        pytest.skip("docs/architecture.md is not beside the tests")
    text = API_DOC.read_text(encoding="utf-8")
    return text.split("\n## Public API\n", 1)[1].split("\n## ", 1)[0]


def readme_table_rows() -> list[tuple[str, str, tuple[str, ...]]]:
    section = public_api_section().split("\n### ", 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or cells[0] in ("role", "") or set(cells[0]) <= set("-: "):
            continue
        module = cells[1].strip("`")
        names = tuple(re.findall(r"`([^`]+)`", cells[2]))
        rows.append((cells[0], module, names))
    return rows


def expected_rows():
    return [(role, f"locbook.{module}", tuple(names)) for role, module, names in locbook._API]


def render_table() -> str:
    lines = ["| role | module | names |", "|---|---|---|"]
    for role, module, names in expected_rows():
        lines.append(f"| {role} | `{module}` | " + ", ".join(f"`{n}`" for n in names) + " |")
    return "\n".join(lines)


def test_readme_lists_exactly_the_public_api():
    assert readme_table_rows() == expected_rows(), ("docs/architecture.md's Public API table should read:\n"
                                                    + render_table())


def test_every_public_name_has_one_home_and_is_defined_there():
    names = [n for _, _, ns in locbook._API for n in ns]
    assert len(names) == len(set(names)), sorted({n for n in names if names.count(n) > 1})
    assert set(locbook.__all__) == {"__version__", *names}
    for _, module, ns in locbook._API:
        for name in ns:
            value = getattr(locbook, name)
            if inspect.isclass(value) or inspect.isfunction(value):
                assert value.__module__ == f"locbook.{module}", (name, value.__module__, module)


def test_constants_stay_in_their_modules():
    constants = [n for n in locbook.__all__ if n != "__version__" and re.fullmatch(r"[A-Z][A-Z0-9_]+", n)]
    assert constants == []


def test_an_unknown_name_is_an_attribute_error_naming_it():
    with pytest.raises(AttributeError, match="no attribute 'kalman_filtre'"):
        locbook.kalman_filtre


# -- the call forms --------------------------------------------------------------------------------------

class Family(NamedTuple):
    """Public functions (or classes) called the same way: ``leading`` their first positional parameters, ``keywords``
    the keyword-only ones the call form names, ``members`` (the first one's signature is the call form shown) and
    ``result`` what they return (every class named in a member's return annotation must appear in it)."""
    name: str
    leading: tuple[str, ...]
    keywords: tuple[str, ...]
    members: tuple[str, ...]
    result: str


FAMILIES = (
    Family("Kalman filters", ("F", "Q", "x0", "P0", "measurements"), (),
           ("kalman_filter", "extended_kalman_filter", "unscented_kalman_filter", "square_root_kalman_filter"),
           "`KalmanResult`, `SquareRootKalmanResult`"),
    Family("interacting multiple models", ("motions", "transition", "x0", "P0", "measurements"), (), ("imm_filter",),
           "`ImmResult`"),
    Family("online filter", ("kind", "F", "Q", "x0", "P0"), (), ("OnlineFilter",),
           "`OnlineFilter`; each `step(measurements)` a `KalmanResult`"),
    Family("noise fits", ("F", "Q", "x0", "P0"), (), ("fit_noise_ml", "fit_noise_em"), "`NoiseFit`"),
    Family("smoothers", ("result",), (), ("rts_smoother", "fixed_lag_smoother"),
           "`SmoothedResult`, `FixedLagResult`"),
    Family("particle filter", ("rss_dbm", "model"), ("rng",), ("particle_filter",), "`ParticleFilterResult`"),
    Family("grid filter", ("rss_dbm", "model", "cells_m"), (), ("grid_bayes_filter",), "`BayesFilterResult`"),
    Family("resampling", ("weights",), ("rng",), ("resample", "resample_where"),
           "ancestor indices `(..., M)` (`resample_where`: and the rows resampled)"),
    Family("RSS estimators", ("rss_dbm", "model"), (), ("rss_ml_position", "grid_ml_position"),
           "`LocalizationResult`"),
    Family("fingerprinting", ("rss_dbm", "fingerprints_dbm", "cells_m"), (), ("knn_position",),
           "positions `(..., 2)`"),
    Family("lateration", ("anchors_m", "distance_m"), (),
           ("lateration_ls", "lateration_wls", "lateration_box_ls", "lateration_system"),
           "`LocalizationResult` (`lateration_system`: its matrices `A`, `b`)"),
    Family("range lateration", ("range_m", "anchors_m"), (), ("range_nls_position",), "`LocalizationResult`"),
    Family("static bounds", ("position_m", "model"), ("variant",),
           ("rss_crlb_m", "rss_fisher_information", "rss_position_information"),
           "the bound (m) `(...)`; the information `(..., dim, dim)`"),
    Family("range bounds", ("position_m", "model"), (), ("range_crlb_m", "range_position_information"),
           "the bound (m) `(...)`; the information `(..., dim, dim)`"),
    Family("bound over an area", ("points_m", "model"), ("variant",), ("crlb_rms_over_area_m",),
           "the RMS of the bound (m)"),
    Family("posterior bound", ("prior_information", "F", "Q", "measurement_information"), (), ("posterior_crlb",),
           "information matrices `(K + 1, ..., n, n)`"),
    Family("state information", ("states", "model", "position_index"), (), ("rss_state_information",),
           "information `(..., n, n)`"),
    Family("path-loss fits", ("distance_m", "rss_dbm"), (),
           ("fit_path_loss", "fit_path_loss_closed_form", "calibrate_path_loss", "calibrate_path_loss_devices",
            "path_loss_exp_given_ref_power", "path_loss_exp_ratio_estimate"),
           "`PathLossFit` (the exponent given the reference power: arrays)"),
    Family("error statistics", ("error_m",), (),
           ("rmse_m", "mean_error_m", "median_error_m", "percentile_error_m", "error_std_m", "rmse_standard_error_m",
            "empirical_cdf", "error_summary", "accuracy_metrics"),
           "a value, or an array over `axis` (`error_summary`, `accuracy_metrics`: a dict)"),
    Family("block bootstrap", ("n", "block_length", "n_resamples"), ("rng",),
           ("circular_block_indices", "moving_block_indices"), "index arrays `(n_resamples, n)`"),
)

#: the public functions in no family (each called its own way): a new public function goes into a family (and is
#: held to its call form) or here
UNGROUPED = (
    "register_to_dbm", "dbm_to_register", "quantize_db", "pairwise_distance_m", "correlated_shadowing_db",
    "wall_crossings", "small_scale_fading_db", "log_normal_range_moments", "correct_range_bias",
    "per_state", "per_step", "RssMeasurementModel",
    "fix_error_covariance", "calibrate_from_reference_tags", "pooled_sigma_db", "smooth_rssi",
    "check_anchor_geometry", "implausible_powers", "recursive_least_squares", "model_fingerprints",
    "pattern_fingerprints",
    "constant_velocity", "constant_acceleration", "reflect_into_box", "simulate_states", "waypoint_trajectory",
    "polyline_trajectory",
    "accelerometer_readings", "gyroscope_readings", "stationary_bias", "rotation_2d", "world_to_body",
    "body_to_world", "integrate", "dead_reckon", "inertial_measurement_function", "inertial_measurement_jacobian",
    "unscented_weights", "sigma_points", "unscented_transform", "LinearMeasurement", "RssMeasurement",
    "NonlinearMeasurement", "nis_divergence", "nees", "predict", "update", "embed", "fuse_estimates",
    "kernel_map_estimate", "grid_transition_matrix", "systematic_resample", "effective_sample_size",
    "counts_to_indices", "position_bound_m", "linear_measurement_information",
    "position_error_m", "reduction_pct",
    "spawn_generators", "streams", "seed_from_values", "canonical_encoding", "mc_standard_error",
    "bootstrap_standard_error", "jackknife_standard_error", "replicate_standard_error", "single_run_interval",
    "read_readings", "read_anchors", "read_outline", "read_path_segments", "validate_readings", "epochs",
    "regular_epochs", "scan_interval_s", "load_dataset", "shipped_datasets", "dataset_summary",
    "inside_outline", "grid_in_outline", "outline_box", "box_outline", "distance_to_segments", "printed",
    "read_ranges", "align_ranges", "nearest_on_outline",
)

#: the one result vocabulary of every filter (locbook/tracking/results.py, FilterResult)
VOCABULARY = ("mean", "cov", "steps", "log_likelihood", "diverged", "diverged_step", "position_m")

_POSITIONAL = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)


def _parameters(value) -> list[inspect.Parameter]:
    """The parameters a caller gives (``self`` left out)."""
    return [p for p in inspect.signature(value).parameters.values() if p.name != "self"]


def call_form(value, keywords=()) -> str:
    """``name(required positional, ..., *, keywords, ...)`` from the signature: ``...`` after the positional ones
    when more (with defaults) follow, the named keyword-only ones (``=...`` where they have a default), ``...`` for
    the other keyword-only ones."""
    params = _parameters(value)
    positional = [p for p in params if p.kind in _POSITIONAL]
    parts = [p.name for p in positional if p.default is p.empty]
    more = len(parts) < len(positional) or any(p.kind is p.VAR_POSITIONAL for p in params)
    keyword_only = [p for p in params if p.kind in (p.KEYWORD_ONLY, p.VAR_KEYWORD)]
    if more:
        parts.append("...")
    if keywords:
        by_name = {p.name: p for p in params}
        parts += ["*", *(k if by_name[k].default is by_name[k].empty else f"{k}=..." for k in keywords)]
        if len(keyword_only) > len(keywords):
            parts.append("...")
    elif keyword_only and not more:
        parts += ["*", "..."]
    return f"{value.__name__}({', '.join(parts)})"


def _is_filter_result(name: str) -> bool:
    from locbook.tracking.results import FilterResult
    value = getattr(locbook, name, None)
    return inspect.isclass(value) and issubclass(value, FilterResult)


def render_call_forms() -> str:
    """The Call forms table: one row per family (its first member's call form; the result, marked FilterResult
    where it is one), and the vocabulary line under it."""
    lines = ["| family | call form | also | result |", "|---|---|---|---|"]
    for family in FAMILIES:
        first = getattr(locbook, family.members[0])
        also = ", ".join(f"`{name}`" for name in family.members[1:]) or "-"
        named = re.findall(r"`([A-Z]\w+)`", family.result)
        mark = " (FilterResult)" if any(_is_filter_result(n) for n in named) else ""
        lines.append(f"| {family.name} | `{call_form(first, family.keywords)}` | {also} | {family.result}{mark} |")
    lines += ["", "FilterResult (`locbook/tracking/results.py`), the one result vocabulary of every filter: "
              + ", ".join(f"`{name}`" for name in VOCABULARY) + "."]
    return "\n".join(lines)


def readme_call_forms() -> str:
    """The Call forms subsection of docs/architecture.md from its table on (the prose before it is free)."""
    section = public_api_section()
    assert "\n### Call forms\n" in section, "docs/architecture.md's Public API section should have a '### Call forms'"
    body = section.split("\n### Call forms\n", 1)[1]
    return body[body.index("\n|") + 1:].strip()


def _public_functions() -> dict[str, object]:
    """The public functions (anything callable but a class: ``printed`` is cached)."""
    return {name: getattr(locbook, name) for _, _, names in locbook._API for name in names
            if callable(getattr(locbook, name)) and not inspect.isclass(getattr(locbook, name))}


def _callables_of_the_home_modules(methods: bool = True):
    """Every public function, public class (with a signature) and public method of a public class of the API's home
    modules (their ``__all__``), as ``(qualified name, callable)``; ``methods=False``: no methods."""
    seen = set()
    for module in sorted({module for _, module, _ in locbook._API}):
        mod = importlib.import_module(f"locbook.{module}")
        for name in getattr(mod, "__all__", ()):
            value = getattr(mod, name)
            if id(value) in seen or not (inspect.isfunction(value) or inspect.isclass(value)):
                continue
            seen.add(id(value))
            try:
                inspect.signature(value)
            except ValueError:          # an exception class: no signature of its own
                continue
            yield f"{module}.{name}", value
            if methods and inspect.isclass(value):
                for attr, method in inspect.getmembers(value, inspect.isfunction):
                    if not attr.startswith("_"):
                        yield f"{module}.{name}.{attr}", method


def test_the_call_forms_table_is_the_rendering_of_the_signatures():
    assert readme_call_forms() == render_call_forms(), \
        "docs/architecture.md's Call forms table should read:\n" + render_call_forms()


def test_every_function_of_a_family_has_its_leading_parameters_and_keywords():
    wrong = []
    for family in FAMILIES:
        for name in family.members:
            params = _parameters(getattr(locbook, name))
            leading = tuple(p.name for p in params[:len(family.leading)] if p.kind in _POSITIONAL)
            keyword_only = {p.name for p in params if p.kind is p.KEYWORD_ONLY}
            if leading != family.leading or not set(family.keywords) <= keyword_only:
                wrong.append(f"{name}: {leading} (keyword-only {sorted(keyword_only & set(family.keywords))}), "
                             f"the {family.name} take {family.leading} (keyword-only {list(family.keywords)})")
    assert wrong == []


def test_every_public_function_is_in_one_family_or_listed_as_ungrouped():
    members = [name for family in FAMILIES for name in family.members]
    assert len(members) == len(set(members)), sorted({n for n in members if members.count(n) > 1})
    assert not set(members) & set(UNGROUPED), sorted(set(members) & set(UNGROUPED))
    functions = set(_public_functions())
    assert functions - set(members) - set(UNGROUPED) == set(), "a new public function: put it in a family or UNGROUPED"
    assert set(UNGROUPED) - functions == set()
    assert set(members) - functions <= {name for name in members if inspect.isclass(getattr(locbook, name))}


def test_the_result_column_names_every_annotated_result():
    for family in FAMILIES:
        for name in family.members:
            value = getattr(locbook, name)
            annotation = "" if inspect.isclass(value) else inspect.signature(value).return_annotation
            for cls in re.findall(r"\b[A-Z]\w+", annotation if isinstance(annotation, str) else ""):
                assert f"`{cls}`" in family.result, (family.name, name, annotation)


def test_no_public_callable_takes_rng_positionally():
    positional = [f"{name}{inspect.signature(value)}" for name, value in _callables_of_the_home_modules()
                  if "rng" in inspect.signature(value).parameters
                  and inspect.signature(value).parameters["rng"].kind is not inspect.Parameter.KEYWORD_ONLY]
    assert positional == [], "rng is keyword-only everywhere (f(..., *, rng, ...))"


def test_a_model_comes_second_after_the_readings_or_positions():
    """In every public function and constructor (a method's receiver holds its data: ``trajectory.states(model)``)."""
    wrong = []
    for name, value in _callables_of_the_home_modules(methods=False):
        names = [p.name for p in _parameters(value) if p.kind in _POSITIONAL]
        if "model" in names and names.index("model") != 1:
            wrong.append(f"{name}({', '.join(names)})")
    assert wrong == []


def test_every_filter_result_has_the_one_vocabulary():
    from locbook.tracking.results import FilterResult
    results = {value for _, _, names in locbook._API for value in (getattr(locbook, n) for n in names)
               if inspect.isclass(value) and issubclass(value, FilterResult) and value is not FilterResult}
    filters = ("Kalman filters", "interacting multiple models", "smoothers", "particle filter", "grid filter")
    for family in FAMILIES:
        if family.name in filters:
            for name in family.members:
                annotation = inspect.signature(getattr(locbook, name)).return_annotation
                assert getattr(locbook, annotation) in results, (name, annotation)
    for cls in results:
        fields = getattr(cls, "__dataclass_fields__", {})
        missing = [name for name in VOCABULARY if name not in fields and not hasattr(cls, name)]
        assert missing == [], (cls.__name__, missing)
