"""PSNR and SSIM as low-light restoration papers measure them.

``protocol="eld"`` (default) is ELD's (also PMN's and the PGRF paper's):
output clamped to [0, 1], both images x255 as floats and clipped, PSNR with
data range 255, SSIM with scikit-image's defaults (7x7 uniform window,
sample covariance, mean over channels); ``illuminance_correct`` applies
ELD's least-squares brightness gain first. ``protocol="plain"`` is
scikit-image on the values as given with data range 1. The numbers equal
``pgrf eval``'s and scikit-image's (pgrf's tests pin them).

Images are ``(C, H, W)`` (packed planes) or ``(H, W)``.
"""

from __future__ import annotations

from typing import Any, Optional, Tuple

import numpy as np

from . import _pgrf

__all__ = ["psnr", "ssim", "scores"]


def _chw(x: Any, what: str) -> np.ndarray:
    a = np.ascontiguousarray(np.asarray(x), dtype=np.float32)
    if a.ndim == 2:
        a = a[None]
    if a.ndim != 3:
        raise ValueError(f"{what}: expected (C, H, W) or (H, W), got shape {a.shape}")
    return a


def scores(
    output: Any, reference: Any, protocol: str = "eld", illuminance_correct: bool = False
) -> Tuple[float, float, Optional[float]]:
    """(PSNR dB, SSIM, the illuminance gain applied or None), one pass over both images."""
    return _pgrf.scores(
        _chw(output, "output"), _chw(reference, "reference"), protocol, illuminance_correct
    )


def psnr(output: Any, reference: Any, protocol: str = "eld", illuminance_correct: bool = False) -> float:
    """PSNR in dB (inf when identical)."""
    return scores(output, reference, protocol, illuminance_correct)[0]


def ssim(output: Any, reference: Any, protocol: str = "eld", illuminance_correct: bool = False) -> float:
    """SSIM, mean over channels."""
    return scores(output, reference, protocol, illuminance_correct)[1]
