"""The unary term (paper Sec. 3, Eq. 5): point descriptors and the potentials made of them.

:mod:`.descriptors` computes spin images with their NMI similarity (paper Sec. 4) and
the spectral signatures (WKS, HKS); :mod:`.unary` turns the descriptors of the source
samples and the targets into the potentials of the MRF.
"""

from __future__ import annotations

from .descriptors import heat_kernel_signature, nmi, spin_images, wave_kernel_signature
from .unary import nmi_potential, unary_potentials

__all__ = [
    "heat_kernel_signature",
    "nmi",
    "nmi_potential",
    "spin_images",
    "unary_potentials",
    "wave_kernel_signature",
]
