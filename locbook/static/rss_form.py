"""The call form of the RSS estimators: the readings first, then one :class:`~locbook.RssModel`; what an
estimator cannot honour in that model is refused by name (:func:`rss_model_parts`), and the earlier form
(anchors, readings, a :class:`~locbook.PathLossModel`; deprecated) is accepted for one release with a warning
(:func:`accepts_old_form`). Used by :mod:`locbook.static.rss_ml`, :mod:`locbook.static.grid_ml` and
:mod:`locbook.static.fingerprint`.
"""
from __future__ import annotations

import inspect

from .._deprecation import old_form
from ..models.channel import PathLossModel
from ..models.rss import RssModel

__all__ = ["rss_model_parts", "is_old_form", "accepts_old_form", "old_estimator_call"]


def rss_model_parts(model, who: str, *, form: str | None = None, walls: bool = False, per_step: bool = False,
                     heights: bool = True):
    """``(anchors_m, channel, tag_height_m)`` of the :class:`~locbook.RssModel` ``model`` given to ``who``; what
    ``who`` cannot honour is refused by name in one line: anything but an RssModel (``form``: the call to write),
    per-run anchors, per-run or per-step channel parameters (unless ``per_step``), walls that attenuate (unless
    ``walls``), a tag height (unless ``heights``)."""
    form = form or f"{who}(rss_dbm, RssModel(anchors_m, channel, tag_height_m=...), ...)"
    if not isinstance(model, RssModel):
        raise ValueError(f"{who}: model must be an RssModel (the anchors, the channel and the tag height in one "
                         f"object), got {type(model).__name__}: pass {form}")
    varying = model.per_run_or_step()
    if "anchors_m" in varying:
        raise ValueError(f"{who}: model.anchors_m is per run or per step, shape {varying['anchors_m']}; it takes one "
                         "layout (m, dim) shared by every problem: give each run its own RssModel")
    ch = model.channel
    channel_axes = [name for name in varying if name != "anchors_m"]
    if channel_axes and not per_step:
        raise ValueError(f"{who}: model.{channel_axes[0]} is per run or per step, shape {varying[channel_axes[0]]}; it "
                         "takes scalar or per-anchor (m,) parameters: give each run and step its own RssModel")
    if not walls and model.walls_m is not None and ch.wall_attenuation_db != 0.0:
        raise ValueError(f"{who}: model.walls_m ({model.walls_m.shape[0]} wall(s), {ch.wall_attenuation_db:g} dB each) "
                         "is not modelled by this estimator: give it a model without walls (walls_m=None)")
    if not heights and model.tag_height_m is not None:
        raise ValueError(f"{who}: model.tag_height_m is not supported (the map uses plan distances): give it a model "
                         "with plan anchors (m, 2) and no tag height")
    return model.anchors_m, ch, model.tag_height_m


def is_old_form(args, kwargs, leading) -> bool:
    """Whether a call is in the earlier, deprecated form: a :class:`~locbook.PathLossModel` third (positionally, or as
    ``model=`` after the two ``leading`` arguments), or ``anchors_m=`` given; an RssModel second is the new form."""
    model = kwargs["model"] if "model" in kwargs else (args[2] if len(args) > 2 else None)
    return "anchors_m" in kwargs or (isinstance(model, PathLossModel)
                                     and len(args) + sum(name in kwargs for name in leading) >= 2)


def accepts_old_form(old_call):
    """:func:`locbook._deprecation.old_form` of a public function whose ``old_call(args, kwargs)`` is None for a call in
    the new form, else ``(old, new, run)``: the deprecated form, the one to use, and ``run(function)``, the same
    result."""
    return old_form(lambda function, args, kwargs: old_call(args, kwargs))


def old_estimator_call(args, kwargs, who: str, v1):
    """:func:`accepts_old_form`'s ``old_call`` of the RSS ML estimators: the earlier form (anchors, readings,
    a PathLossModel, ..., ``tag_height_m=``) builds the RssModel; ``grid_m=`` is the old spelling of ``cells_m=``."""
    if is_old_form(args, kwargs, ("anchors_m", "rss_dbm")):
        given = inspect.signature(v1).bind(*args, **kwargs).arguments      # a TypeError as the old function gave
        anchors_m, rss_dbm, channel = given.pop("anchors_m"), given.pop("rss_dbm"), given.pop("model")
        tag_height_m = given.pop("tag_height_m", None)
        if "grid_m" in given:
            given["cells_m"] = given.pop("grid_m")
        return (f"{who}(anchors_m, rss_dbm, channel, ...)",
                f"{who}(rss_dbm, RssModel(anchors_m, channel, tag_height_m=...), ...)",
                lambda new: new(rss_dbm, RssModel(anchors_m, channel, tag_height_m=tag_height_m), **given))
    if "tag_height_m" in kwargs:
        raise ValueError(f"{who}: tag_height_m is the model's: pass RssModel(anchors_m, channel, "
                         "tag_height_m=...) as model")
    if "grid_m" in kwargs:
        if "cells_m" in kwargs or len(args) > 2:
            raise TypeError(f"{who}() got cells_m and grid_m, its old spelling: give cells_m only")
        kwargs = dict(kwargs)
        kwargs["cells_m"] = kwargs.pop("grid_m")
        return f"{who}(..., grid_m=...)", f"{who}(..., cells_m=...)", lambda new: new(*args, **kwargs)
    return None

