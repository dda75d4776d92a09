"""`pgrf.metrics` against scikit-image (0.26) on a seeded pair, committed as numbers."""

import numpy as np
import pytest

import pgrf

# np.random.default_rng(20261127): ref = rng.random((4, 48, 40), float32),
# out = ref + (rng.random(same) - 0.5) * 0.2; scikit-image's
# peak_signal_noise_ratio and structural_similarity(channel_axis=0) on
# ELD's x255 clamped images (data_range 255), and on the values as given
# (data_range 1).
SKIMAGE = {"eld": (24.949387796842206, 0.9806362982572088), "plain": (24.754502996974924, 0.9799427395310756)}


def pair():
    rng = np.random.default_rng(20261127)
    ref = rng.random((4, 48, 40), dtype=np.float32)
    out = (ref + (rng.random((4, 48, 40), dtype=np.float32) - 0.5) * 0.2).astype(np.float32)
    # The generator's stream is what the numbers were computed on.
    assert ref[0, 0, :3] == pytest.approx([0.7926939, 0.36915338, 0.32008135], abs=1e-7)
    return out, ref


@pytest.mark.parametrize("protocol", ["eld", "plain"])
def test_psnr_and_ssim_equal_scikit_image(protocol):
    out, ref = pair()
    p, s, gain = pgrf.metrics.scores(out, ref, protocol=protocol)
    want_p, want_s = SKIMAGE[protocol]
    assert p == pytest.approx(want_p, abs=1e-6)
    assert s == pytest.approx(want_s, abs=1e-6)
    assert gain is None
    assert pgrf.metrics.psnr(out, ref, protocol) == p and pgrf.metrics.ssim(out, ref, protocol) == s


def test_identical_images_and_the_illuminance_gain():
    out, ref = pair()
    assert pgrf.metrics.psnr(ref, ref) == float("inf")
    assert pgrf.metrics.ssim(ref, ref) == pytest.approx(1.0)
    # A uniformly darker output: ELD's gain recovers the brightness.
    p, _, gain = pgrf.metrics.scores(ref * 0.5, ref, illuminance_correct=True)
    assert gain == pytest.approx(2.0, rel=1e-4) and p > 60
    assert pgrf.metrics.psnr(ref[0], ref[0]) == float("inf")  # (H, W) images
    with pytest.raises(ValueError, match="protocol"):
        pgrf.metrics.psnr(out, ref, protocol="srgb")
    with pytest.raises(ValueError):
        pgrf.metrics.psnr(out, ref[:, :10])
