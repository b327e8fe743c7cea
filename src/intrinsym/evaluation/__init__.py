"""Scores against ground truth (the paper's Sec. 6 evaluation and the benchmarks').

:mod:`.evaluate` scores marginals and vertex maps against a true symmetry map (errors,
correspondence curves, calibration); :mod:`.partial_truth` reads and scores partial
ground truth (a partner, "no partner", or not scored); :mod:`.symmetry_group` scores the
found symmetries against several true maps (a shape's symmetry group).
"""

from __future__ import annotations

from .evaluate import MapScores, MarginalScores, load_symmetry_map, score_map, score_marginals
from .partial_truth import PartialTruth, load_truth, score_partial
from .symmetry_group import load_truths, symmetry_scores

__all__ = [
    "MapScores",
    "MarginalScores",
    "PartialTruth",
    "load_symmetry_map",
    "load_truth",
    "load_truths",
    "score_map",
    "score_marginals",
    "score_partial",
    "symmetry_scores",
]
