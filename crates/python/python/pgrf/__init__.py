"""pgrf for Python: RAW reading, per-pixel noise calibration, physics-based
low-light noise synthesis, unprocessing, the ELD protocol's metrics and the
denoising networks (the built-in SPC and PGRF, or your own), on numpy arrays.

The work is pgrf's Rust library (the same code the ``pgrf`` command runs),
with the GIL released, so a PyTorch DataLoader's workers synthesise in
parallel. Every random result depends on its seed alone: the same image,
settings and seed give the same array at any thread count, in any worker,
and the same numbers as ``pgrf synth --seed``.

Packed images are float32 ``(4, H/2, W/2)``: the four 2x2 sub-lattices of
the mosaic in the order R, G1, B, G2 (a monochrome sensor's four
sub-lattices in the same order), normalised as (DN - black) / (white - black).

    >>> import pgrf
    >>> clean, meta = pgrf.read("clean.dng")
    >>> cap = pgrf.synth(clean, pgrf.Profile.builtin("sony-a7s2"), ratio=100, iso=1600, seed=1, meta=meta)
    >>> pgrf.write_dng("dark.dng", cap.dark, cap.meta)
    >>> pgrf.metrics.psnr(cap.brightened, clean)
    >>> restored = pgrf.Model.load("builtin:spc").restore(cap.dark, ratio=cap.ratio, meta=cap.meta)
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, fields, replace
from os import PathLike, fspath
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _pgrf
from . import metrics
from ._pgrf import Header, Profile, get_threads, set_threads

__version__: str = _pgrf.__version__

__all__ = [
    "BatchCapture",
    "Calibration",
    "Capture",
    "Header",
    "Metadata",
    "Model",
    "Profile",
    "calibrate",
    "get_threads",
    "metrics",
    "read",
    "read_photo",
    "set_threads",
    "synth",
    "synth_batch",
    "unprocess",
    "write_dng",
]

PathType = Union[str, "PathLike[str]"]


@dataclass
class Metadata:
    """What a RAW frame says about itself besides its pixels.

    ``read`` fills every field and keeps the decoded file's ``header``
    (opaque), so that ``write_dng`` keeps what the file had (EXIF, colour
    matrices); change the descriptive fields (ISO, exposure, camera, white
    balance, ...) freely. To describe another frame (another size, CFA or
    levels), make a new ``Metadata`` (``header=None``).
    """

    width: int
    height: int
    #: Bayer phase of pixel (0, 0): "RGGB", "BGGR", "GRBG", "GBRG"; or "mono".
    cfa: str
    #: Black level per packed plane R, G1, B, G2, DN.
    black: Tuple[float, float, float, float]
    #: Saturation level, DN.
    white: int
    #: Bits per sample the file declares.
    bits: int = 16
    #: As-shot white balance R, G, B (G = 1).
    wb: Optional[Tuple[float, float, float]] = None
    #: (illuminant, XYZ -> camera 3x3) pairs, the D65-like one last.
    color_matrices: List[Tuple[str, List[List[float]]]] = field(default_factory=list)
    iso: Optional[int] = None
    exposure_s: Optional[float] = None
    make: str = "pgrf"
    model: str = "python"
    #: EXIF orientation (1: as stored).
    orientation: int = 1
    temperature_c: Optional[float] = None
    #: DNG NoiseProfile (S, O) pairs: variance S x + O at normalised signal x.
    noise_profile: Optional[List[Tuple[float, float]]] = None
    header: Optional[Header] = field(default=None, repr=False, compare=False)

    @property
    def mono(self) -> bool:
        """A monochrome sensor (no colour filter)."""
        return self.cfa.lower() == "mono"

    @property
    def packed_shape(self) -> Tuple[int, int, int]:
        """The shape of this frame's packed planes."""
        return (4, self.height // 2, self.width // 2)

    def _fields(self) -> Dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["black"] = [float(b) for b in self.black]
        out["wb"] = None if self.wb is None else [float(w) for w in self.wb]
        return out

    @classmethod
    def _of(cls, d: Dict[str, Any]) -> "Metadata":
        d = dict(d)
        d["black"] = tuple(d["black"])
        if d.get("wb") is not None:
            d["wb"] = tuple(d["wb"])
        return cls(**d)


def _array(x: Any, ndim: int, what: str) -> np.ndarray:
    """`x` as a C-contiguous float32 array of `ndim` dimensions (no copy when it already is one)."""
    a = np.ascontiguousarray(np.asarray(x), dtype=np.float32)
    if a.ndim != ndim:
        raise ValueError(f"{what}: expected {ndim} dimensions, got shape {a.shape}")
    return a


def _profile(p: Union[Profile, str]) -> Profile:
    if isinstance(p, Profile):
        return p
    if isinstance(p, str):
        return Profile.load(p)
    raise TypeError(f"profile: expected a pgrf.Profile or a --profile string, got {type(p).__name__}")


def read(path: PathType, clip: bool = True) -> Tuple[np.ndarray, Metadata]:
    """Decode a RAW file (any camera rawler reads, DNG, FITS).

    Returns the packed planes, float32 ``(4, H/2, W/2)`` normalised to
    (DN - black) / (white - black), clipped to [0, 1] unless ``clip`` is
    False (dark frames keep their negative read noise then), and the
    frame's :class:`Metadata`. Raises ``OSError`` when the file cannot be
    read and ``ValueError`` when it is not a RAW pgrf handles.
    """
    packed, meta = _pgrf.read(fspath(path), clip)
    return packed, Metadata._of(meta)


def write_dng(path: PathType, packed: Any, meta: Metadata) -> None:
    """Write packed normalised planes as a DNG of the frame ``meta`` describes.

    Values are rounded to whole DN and saturated to 16 bits; the file is
    written to a temporary name and renamed. LibRaw and pgrf read it back.
    """
    _pgrf.write_dng(fspath(path), _array(packed, 3, "write_dng packed"), meta._fields())


def read_photo(path: PathType) -> np.ndarray:
    """An ordinary photo (JPEG, PNG, TIFF) as float32 ``(H, W, 3)`` sRGB values in [0, 1]."""
    return _pgrf.read_photo(fspath(path))


@dataclass
class Capture:
    """One simulated low-light capture and what it was made with."""

    #: What the camera records: the clean image / ratio plus noise, clipped
    #: at white, the read noise around black kept (values may be negative).
    dark: np.ndarray = field(repr=False)
    #: ``dark`` multiplied back by the ratio and clipped to [0, 1]: a network's input.
    brightened: np.ndarray = field(repr=False)
    ratio: float
    exposure_s: float
    #: The ISO, when one was set (else parameters were drawn from the profile's fits).
    iso: Optional[int]
    #: The terms the model drew, e.g. "P,G" for "pg", "P,G,H,Q,F" for
    #: "eld" (F: its colour bias), those asked for with "pgrf".
    components: str
    #: System gain K, DN per electron.
    k: float
    #: Read-noise scale, DN (Tukey-lambda's for ELD's model).
    read_dn: float
    #: Row-noise sigma, DN (0 when the model draws none).
    row_dn: float
    #: With ``meta``: the dark capture's metadata (ISO, exposure, NoiseProfile
    #: as ``pgrf synth`` writes them): ``write_dng(path, cap.dark, cap.meta)``.
    meta: Optional[Metadata] = field(default=None, repr=False)
    #: With ``meta``: the brightened capture's metadata.
    brightened_meta: Optional[Metadata] = field(default=None, repr=False)


#: The keyword arguments of synth and synth_batch that set the capture.
_SETTINGS = ("ratio", "iso", "model", "components", "global_maps", "gaussian_read",
             "exposure_s", "dark_rate", "dark_law", "noise_bank")


def _settings(args: Dict[str, Any]) -> Dict[str, Any]:
    """The capture settings among a call's arguments (its ``locals()``)."""
    return {k: args[k] for k in _SETTINGS}


def synth(
    clean: Any,
    profile: Union[Profile, str],
    *,
    ratio: Optional[float] = None,
    iso: Optional[int] = None,
    model: str = "pgrf",
    components: str = "P,G,H,Q,F,A",
    seed: int = 0,
    meta: Optional[Metadata] = None,
    cfa: Optional[str] = None,
    exposure_s: Optional[float] = None,
    global_maps: bool = False,
    gaussian_read: bool = False,
    dark_rate: Optional[float] = None,
    dark_law: str = "sqrt",
    noise_bank: bool = False,
) -> Capture:
    """Simulate the low-light capture of a packed clean image.

    ``clean``: float32 ``(4, H/2, W/2)`` in [0, 1] (``read``, ``unprocess``).
    ``profile``: a :class:`Profile` (or what ``--profile`` takes).
    ``ratio``: how many times darker, 1 to 10000 (None: drawn from
    U(100, 300) by the seed). ``iso``: None takes the profile's only ISO,
    else ``meta``'s, else draws parameters from the profile's ELD fits.
    ``model``: "pg" (Poisson-Gaussian), "eld" (ELD's: shot, Tukey-lambda
    read, row, quantisation) or "pgrf" (the paper's, with ``components``
    any of P, G, H, Q, F, A; per-pixel maps with a calibrated profile).
    ``meta``: the clean frame's metadata: its CFA (row noise follows the
    sensor rows), ISO and exposure, as ``pgrf synth`` takes them from the
    file; without it ``cfa`` (default RGGB). ``exposure_s``: the capture's
    exposure (None: ``meta``'s / ratio, else drawn). ``global_maps``: the
    paper's "noD" ablation. ``gaussian_read``: ELD with Gaussian read
    noise. ``dark_rate``/``dark_law``: dark current in electrons per
    sqrt(s) ("sqrt") or per s ("linear"). ``noise_bank``: draw the read,
    row and quantisation noise from the calibration's bank of its bias
    frames' residuals (``Profile.calibration``; ``pgrf synth --noise-bank``).

    The same arguments and seed give the same arrays, in any thread or
    process, and the numbers ``pgrf synth --seed`` writes for that file.
    """
    settings = _settings(locals())
    dark, bright, info, dmeta, bmeta = _pgrf.synth(
        _array(clean, 3, "synth clean"),
        _profile(profile),
        _seed(seed),
        settings,
        None if meta is None else meta._fields(),
        cfa,
    )
    return Capture(
        dark=dark,
        brightened=bright,
        meta=None if dmeta is None else Metadata._of(dmeta),
        brightened_meta=None if bmeta is None else Metadata._of(bmeta),
        **info,
    )


@dataclass
class BatchCapture:
    """Simulated captures of a batch: arrays ``(N, 4, H/2, W/2)`` and per-item numbers."""

    dark: np.ndarray = field(repr=False)
    brightened: np.ndarray = field(repr=False)
    #: One dict per item: ratio, exposure_s, iso, components, k, read_dn, row_dn.
    info: List[Dict[str, Any]]

    @property
    def ratio(self) -> np.ndarray:
        """The items' ratios (the brightening a network is told of)."""
        return np.array([i["ratio"] for i in self.info], dtype=np.float32)


def synth_batch(
    clean: Any,
    profile: Union[Profile, str],
    seeds: Sequence[int],
    *,
    ratio: Optional[float] = None,
    iso: Optional[int] = None,
    model: str = "pgrf",
    components: str = "P,G,H,Q,F,A",
    cfa: Optional[str] = None,
    exposure_s: Optional[float] = None,
    global_maps: bool = False,
    gaussian_read: bool = False,
    dark_rate: Optional[float] = None,
    dark_law: str = "sqrt",
    noise_bank: bool = False,
) -> BatchCapture:
    """:func:`synth` of each image of ``clean`` ``(N, 4, H/2, W/2)`` with its own seed.

    Item i equals ``synth(clean[i], profile, seed=seeds[i], ...)`` exactly;
    the items are made in parallel. With ``ratio=None`` each item draws its
    own ratio from its seed.
    """
    settings = _settings(locals())
    dark, bright, infos = _pgrf.synth_batch(
        _array(clean, 4, "synth_batch clean"),
        _profile(profile),
        [_seed(s) for s in seeds],
        settings,
        cfa,
    )
    return BatchCapture(dark=dark, brightened=bright, info=list(infos))


def _seed(s: Any) -> int:
    s = int(s)
    if not 0 <= s < 2**64:
        raise ValueError(f"seed must be in [0, 2^64), got {s}")
    return s


def unprocess(
    photo: Any,
    camera: Union[str, Metadata] = "sony-a7s2",
    *,
    seed: Optional[int] = None,
    exposure: float = 1.0,
    wb_spread: float = 1.25,
) -> np.ndarray:
    """An sRGB photo in a camera's RAW space, packed ``(4, H/2, W/2)`` (Brooks et al., CVPR 2019).

    ``photo``: ``(H, W, 3)`` uint8, uint16, or float in [0, 1] (``read_photo``).
    ``camera``: "sony-a7s2" or the :class:`Metadata` of a RAW of the camera
    (its colour matrix, white balance, CFA and levels). Without ``seed``:
    the camera's own colours at ``exposure``. With ``seed``: exposure,
    white balance (red and blue by up to ``wb_spread``) and colour matrix
    jittered as ``pgrf train`` does per crop, drawn from the seed.
    """
    a = np.asarray(photo)
    if a.dtype == np.uint8:
        a = a.astype(np.float32) / 255.0
    elif a.dtype == np.uint16:
        a = a.astype(np.float32) / 65535.0
    cam = camera._fields() if isinstance(camera, Metadata) else camera
    return _pgrf.unprocess(
        _array(a, 3, "unprocess photo"),
        cam,
        None if seed is None else _seed(seed),
        float(exposure),
        float(wb_spread),
    )


class Calibration:
    """A sensor's per-pixel calibration (``pgrf calibrate``'s file).

    ``maps``: packed ``(4, H/2, W/2)`` float32 arrays by name (fixed_pattern,
    sigma_read, dark_rate, defects, gain, response, ...); ``record``: how it
    was made and the global figures (K, read and row noise, dark law, ...).
    """

    def __init__(self, data: "_pgrf.CalibrationData"):
        self._data = data
        self.maps: Dict[str, np.ndarray] = dict(data.maps)
        self.record: Dict[str, Any] = json.loads(data.record_json)

    @classmethod
    def load(cls, path: PathType) -> "Calibration":
        """Read a calibration file."""
        return cls(_pgrf.CalibrationData.load(fspath(path)))

    def save(self, path: PathType) -> None:
        """Write pgrf's calibration file (``pgrf synth --calib``, ``Profile.calibration``)."""
        self._data.save(fspath(path))

    def __repr__(self) -> str:
        r = self.record
        return f"pgrf.Calibration({r.get('make', '')} {r.get('model', '')}, ISO {r.get('iso')}, {r.get('width')}x{r.get('height')})"


def calibrate(
    bias: Sequence[PathType],
    flat: Sequence[PathType],
    dark: Sequence[PathType] = (),
    *,
    iso: Optional[int] = None,
    reject: bool = False,
    temperature_tolerance: Optional[float] = None,
) -> Calibration:
    """Calibrate a sensor pixel by pixel from its bias, flat and dark frames (files).

    As ``pgrf calibrate``: bias frames (shortest exposure, capped), flats
    (evenly lit, one or more levels), darks (capped, two or more exposure
    times; optional). ``reject`` drops frames that stand out from their stack.
    """
    data = _pgrf.calibrate(
        [fspath(p) for p in bias],
        [fspath(p) for p in flat],
        [fspath(p) for p in dark],
        iso,
        reject,
        temperature_tolerance,
    )
    return Calibration(data)


NoiseArg = Union[Tuple[float, float], Sequence[Tuple[float, float]]]


def _noise_pair(noise: NoiseArg) -> Tuple[float, float]:
    """(S, O) from a pair or from per-plane pairs (their means, as ``pgrf enhance`` reads a DNG's)."""
    a = np.asarray(noise, dtype=np.float64)
    if a.shape == (2,):
        return float(a[0]), float(a[1])
    if a.ndim == 2 and a.shape[1] == 2 and a.shape[0] >= 1:
        return float(a[:, 0].mean()), float(a[:, 1].mean())
    raise ValueError(f"noise: expected (S, O) or a list of (S, O) pairs, got shape {a.shape}")


class Model:
    """A denoising network: the built-in SPC or PGRF, or a weight file ``pgrf train`` wrote.

    ``restore`` runs what ``pgrf enhance`` runs after decoding a file: the
    capture multiplied by the exposure ratio and clipped at 1, the noise
    level a noise-aware network is told, the tiled restoration; the same
    array, ratio and noise give the pixels ``pgrf enhance`` writes. The GIL
    is released while it works (in the thread pool ``set_threads`` sizes),
    and one model may be used from several threads at once.

        >>> model = pgrf.Model.load("builtin:spc")
        >>> dark, meta = pgrf.read("dark.dng", clip=False)
        >>> clean = model.restore(dark, ratio=100, meta=meta)
    """

    def __init__(self, net: "_pgrf.Network"):
        self._net = net

    @classmethod
    def load(
        cls,
        spec: PathType = "builtin:spc",
        *,
        sampler: str = "two-stage",
        t2: Optional[float] = None,
        samples: int = 1,
        device: str = "cpu",
    ) -> "Model":
        """Load ``"builtin:spc"``, ``"builtin:pgrf"`` or a weight file (``pgrf train``'s, or
        ``pgrf import-weights``'). A flow model samples with ``sampler`` ("two-stage" at the
        file's searched ``t2`` unless given, "one-step" or "euler:N"), averaging ``samples``
        samples; ``device`` "cuda" needs a package built with CUDA."""
        return cls(_pgrf.Network.load(fspath(spec), sampler, t2, int(samples), device))

    @property
    def description(self) -> str:
        """The network and its sampler, as ``pgrf enhance`` prints them."""
        return self._net.description

    @property
    def method(self) -> str:
        """"spc" (one pass) or "pgrf" (the flow model)."""
        return self._net.method

    @property
    def noise_aware(self) -> bool:
        """Whether the network is told its input's noise (then ``restore`` needs ``noise`` or ``meta``)."""
        return self._net.noise_aware

    @property
    def nfe(self) -> int:
        """Network evaluations per tile."""
        return self._net.nfe

    @property
    def record(self) -> Dict[str, Any]:
        """The weight file's record: architecture, noise it learnt, training run, t2."""
        return json.loads(self._net.record_json)

    def restore(
        self,
        packed: Any,
        *,
        ratio: float,
        noise: Optional[NoiseArg] = None,
        meta: Optional[Metadata] = None,
        tile: Optional[int] = None,
        overlap: Optional[int] = None,
        seed: int = 0,
        return_noise: bool = False,
    ) -> Any:
        """Restore a dark capture: ``packed`` float32 ``(4, H/2, W/2)`` normalised as
        ``read(path, clip=False)`` gives it (values below black kept), brightened by ``ratio``.

        Returns the restored planes ``(4, H/2, W/2)`` in [0, 1] on the same scale (``write_dng``
        writes them with ``meta``). A noise-aware model needs the capture's noise: ``noise``
        as (S, O), the variance S x + O of ``packed`` at signal x before the ratio (the DNG
        NoiseProfile's convention; per-plane pairs are averaged), or ``meta``, from which it is
        found as ``pgrf enhance`` finds it (the NoiseProfile, darktable's or a built-in profile
        of the camera at its ISO, else a blind estimate on the pixels). ``tile``/``overlap``:
        tile side and overlap in packed pixels (default: from free memory, as ``pgrf enhance``);
        ``seed``: the flow model's start noise. With ``return_noise`` also returns what the
        lookup found (None when ``noise`` was given or the model needs none).
        """
        args = (
            _array(packed, 3, "restore packed"),
            float(ratio),
            None if noise is None else _noise_pair(noise),
            None if meta is None else meta._fields(),
            tile,
            overlap,
            _seed(seed),
        )
        out, found = self._net.restore(*args)
        return (out, found) if return_noise else out

    def __repr__(self) -> str:
        return f"pgrf.Model({self.description})"
