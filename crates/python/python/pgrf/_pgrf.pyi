# Type stubs of the Rust extension module (crates/python/src). The public,
# documented API is the package `pgrf` (__init__.py, metrics.py), which
# wraps these calls.
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np
import numpy.typing as npt

__version__: str

F32 = npt.NDArray[np.float32]

class Header:
    """The decoded frame a Metadata came from, without its pixels (opaque)."""

class Profile:
    @staticmethod
    def builtin(name: str) -> Profile: ...
    @staticmethod
    def load(spec: str) -> Profile: ...
    @staticmethod
    def names() -> List[str]: ...
    @staticmethod
    def darktable(maker_model: str, path: Optional[str] = None) -> Profile: ...
    @staticmethod
    def dng(path: str) -> Profile: ...
    @staticmethod
    def json(path: str) -> Profile: ...
    @staticmethod
    def calibration(path: str, base: str = "sony-a7s2") -> Profile: ...
    @property
    def camera(self) -> str: ...
    @property
    def calibrated(self) -> bool: ...

class CalibrationData:
    @staticmethod
    def load(path: str) -> CalibrationData: ...
    @property
    def maps(self) -> Dict[str, F32]: ...
    @property
    def record_json(self) -> str: ...
    def save(self, path: str) -> None: ...

class Network:
    @staticmethod
    def load(spec: str, sampler: str = "two-stage", t2: Optional[float] = None, samples: int = 1, device: str = "cpu") -> Network: ...
    @property
    def description(self) -> str: ...
    @property
    def method(self) -> str: ...
    @property
    def noise_aware(self) -> bool: ...
    @property
    def nfe(self) -> int: ...
    @property
    def record_json(self) -> str: ...
    def restore(
        self,
        packed: F32,
        ratio: float,
        noise: Optional[Tuple[float, float]] = None,
        meta: Optional[Dict[str, Any]] = None,
        tile: Optional[int] = None,
        overlap: Optional[int] = None,
        seed: int = 0,
    ) -> Tuple[F32, Optional[str]]: ...

def read(path: str, clip: bool = True) -> Tuple[F32, Dict[str, Any]]: ...
def write_dng(path: str, packed: F32, meta: Dict[str, Any]) -> None: ...
def read_photo(path: str) -> F32: ...
def synth(
    clean: F32,
    profile: Profile,
    seed: int,
    settings: Dict[str, Any],
    meta: Optional[Dict[str, Any]] = None,
    cfa: Optional[str] = None,
) -> Tuple[F32, F32, Dict[str, Any], Optional[Dict[str, Any]], Optional[Dict[str, Any]]]: ...
def synth_batch(
    clean: F32,
    profile: Profile,
    seeds: Sequence[int],
    settings: Dict[str, Any],
    cfa: Optional[str] = None,
) -> Tuple[F32, F32, List[Dict[str, Any]]]: ...
def unprocess(
    photo: F32, camera: Any, seed: Optional[int] = None, exposure: float = 1.0, wb_spread: float = 1.25
) -> F32: ...
def calibrate(
    bias: Sequence[str],
    flat: Sequence[str],
    dark: Sequence[str] = (),
    iso: Optional[int] = None,
    reject: bool = False,
    temperature_tolerance: Optional[float] = None,
) -> CalibrationData: ...
def scores(
    output: F32, reference: F32, protocol: str = "eld", illuminance_correct: bool = False
) -> Tuple[float, float, Optional[float]]: ...
def set_threads(n: Optional[int] = None) -> None: ...
def get_threads() -> int: ...
