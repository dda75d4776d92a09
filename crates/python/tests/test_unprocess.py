"""`pgrf.unprocess`: sRGB photos into the camera's RAW space."""

import numpy as np
import pytest

import pgrf

R = 16383 - 512  # the A7S2's range, DN


def srgb_decode(v):
    v = np.asarray(v, dtype=np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def test_grey_lands_on_the_green_planes_linearised():
    """A grey photo: camera-from-sRGB rows sum to 1 and green's white
    balance is 1, so both green planes hold the linear grey, rounded to the
    camera's DN steps (to 1/R)."""
    for code in (32, 128, 200):
        photo = np.full((16, 20, 3), code, dtype=np.uint8)
        packed = pgrf.unprocess(photo, "sony-a7s2")
        assert packed.shape == (4, 8, 10) and packed.dtype == np.float32
        want = srgb_decode(code / 255.0)
        for g in (1, 3):
            assert np.all(np.abs(packed[g] - want) <= 0.5 / R + 1e-6), (code, packed[g, 0, 0], want)
        # Every value is a whole number of DN steps.
        assert np.allclose(packed * R, np.rint(packed * R), atol=2e-3)


def test_inputs_and_seeds():
    rng = np.random.default_rng(8)
    photo8 = rng.integers(0, 256, size=(32, 24, 3), dtype=np.uint8)
    a = pgrf.unprocess(photo8)
    b = pgrf.unprocess(photo8.astype(np.float32) / 255.0)
    assert np.array_equal(a, b)
    assert a.min() >= 0.0 and a.max() <= 1.0
    j1 = pgrf.unprocess(photo8, seed=3)
    j2 = pgrf.unprocess(photo8, seed=3)
    j3 = pgrf.unprocess(photo8, seed=4)
    assert np.array_equal(j1, j2) and not np.array_equal(j1, j3) and not np.array_equal(j1, a)
    # Odd sides lose their last row or column, as packing a RAW does.
    assert pgrf.unprocess(photo8[:31, :23]).shape == (4, 15, 11)


def test_another_camera_from_its_raw(asset_dng):
    """The 550D's own space (its matrix, white balance, levels 2056..15000)."""
    _, meta = pgrf.read(asset_dng)
    photo = np.full((8, 8, 3), 128, dtype=np.uint8)
    packed = pgrf.unprocess(photo, meta)
    want = srgb_decode(128 / 255.0)
    assert np.all(np.abs(packed[1] - want) <= 0.5 / (15000 - 2056) + 1e-6)


def test_bad_photos_are_refused():
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        pgrf.unprocess(np.zeros((8, 8, 4), np.uint8))
    with pytest.raises(ValueError, match="sony-a7s2"):
        pgrf.unprocess(np.zeros((8, 8, 3), np.uint8), "canon-eos70d")
    with pytest.raises(ValueError, match="exposure"):
        pgrf.unprocess(np.zeros((8, 8, 3), np.uint8), exposure=0.0)
