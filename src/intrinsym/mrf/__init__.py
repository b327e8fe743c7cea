"""The Markov random field over correspondences and its inference (paper Sec. 3 and 3.1, 4).

:mod:`.model` holds the MRF: the unary (Eq. 5) and the truncated geodesic pairwise term
(Eq. 6), with the trivial match suppressed; :mod:`.bp` runs sum-product loopy belief
propagation on it with the exact sparse message (CPU, GPU, and the dense test oracle).
"""

from __future__ import annotations

from .bp import BPResult, belief_propagation, belief_propagation_dense
from .model import MRF, pairwise_dense, truncation_width

__all__ = ["MRF", "BPResult", "belief_propagation", "belief_propagation_dense", "pairwise_dense", "truncation_width"]
