"""Assist-View selection and conditioning (C++ module ``assist``): the model side of AVSplat on
per-view tokens, and greedy view coverage on point maps."""

from ._avsplat import (
    AssistSelection,
    ViewCoverage,
    assist_objective,
    condition_tokens,
    select_assist_views,
    select_views_by_coverage,
)

__all__ = ["AssistSelection", "ViewCoverage", "assist_objective", "condition_tokens", "select_assist_views",
           "select_views_by_coverage"]
