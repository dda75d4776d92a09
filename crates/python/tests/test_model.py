"""pgrf.Model: the built-in networks restore numpy arrays to the pixels `pgrf enhance` writes,
and refuse what they cannot restore."""

import re
import threading

import numpy as np
import pytest

import pgrf


@pytest.fixture(scope="module")
def dark(asset_dng, run_pgrf, tmp_path_factory):
    """The built-in 550D chart made dark by `pgrf synth` (A7S2, ISO 1600, x100, seed 3): a DNG
    with a NoiseProfile and no masked pixels, so `pgrf enhance` takes the metadata's black."""
    path = tmp_path_factory.mktemp("model") / "dark.dng"
    run_pgrf("synth", asset_dng, "--profile", "sony-a7s2", "--iso", "1600", "--ratio", "100",
             "--seed", "3", "-o", path)
    return path


@pytest.fixture(scope="module")
def spc():
    return pgrf.Model.load("builtin:spc")


def written_dn(packed, meta):
    """The DN a DNG of `packed` holds: x * (white - black) + black in float32, rounded half away
    from zero, as pgrf's unpacking writes them."""
    black = np.asarray(meta.black, np.float32)[:, None, None]
    v = packed * (np.float32(meta.white) - black) + black
    return np.clip(np.floor(v + np.float32(0.5)), 0, 65535)


def read_dn(packed, meta):
    """The DN of a file read back by pgrf.read(clip=False) (exact integers)."""
    black = np.asarray(meta.black, np.float64)[:, None, None]
    return np.round(packed.astype(np.float64) * (meta.white - black) + black)


@pytest.mark.parametrize("name", ["builtin:spc", "builtin:pgrf"])
def test_restore_gives_the_pixels_enhance_writes(dark, run_pgrf, tmp_path, name):
    """`pgrf enhance dark.dng --model M --ratio 100` and Model.load(M).restore of the same file's
    array, its noise looked up from its metadata: the DNG's pixels are the array's written as
    whole DN, every one, and the noise is the one enhance reports."""
    out = tmp_path / "out.dng"
    r = run_pgrf("enhance", dark, "--model", name, "--ratio", "100", "-o", out)
    packed, meta = pgrf.read(dark, clip=False)
    model = pgrf.Model.load(name)
    assert model.noise_aware and model.method == name.split(":")[1]
    mine, found = model.restore(packed, ratio=100, meta=meta, return_noise=True)
    assert mine.shape == packed.shape and mine.dtype == np.float32
    assert found is not None and "DNG NoiseProfile" in found
    assert found in r.stdout + r.stderr
    theirs, tmeta = pgrf.read(out, clip=False)
    diff = np.abs(written_dn(mine, meta) - read_dn(theirs, tmeta))
    assert diff.max() == 0.0, (diff.max(), int((diff > 0).sum()))
    # Not a copy of the input: the restoration is far from the noisy capture x100.
    noisy = np.clip(packed * 100, 0, 1)
    assert np.abs(mine - noisy).mean() > 5e-3


def test_noise_given_as_the_profile_pair_equals_the_lookup(dark, spc):
    """(S, O) per plane from the file's NoiseProfile gives the looked-up level (the same
    numbers, converted once more), so the same restoration to float rounding."""
    packed, meta = pgrf.read(dark, clip=False)
    crop = np.ascontiguousarray(packed[:, 100:228, 200:328])
    by_meta = spc.restore(crop, ratio=100, meta=pgrf.Metadata(
        width=256, height=256, cfa=meta.cfa, black=meta.black, white=meta.white, bits=meta.bits,
        iso=meta.iso, make=meta.make, model=meta.model, noise_profile=meta.noise_profile))
    by_pair = spc.restore(crop, ratio=100, noise=meta.noise_profile)
    assert np.abs(by_meta - by_pair).max() < 1e-5
    # Another noise level gives another restoration: the level is used.
    s, o = meta.noise_profile[0]
    other = spc.restore(crop, ratio=100, noise=(4 * s, 16 * o))
    assert np.abs(other - by_pair).mean() > 1e-4


def test_tiles_and_threads_do_not_change_the_result(dark, spc):
    """Tiles of 160 (overlap 64) against one whole tile: the seamless blend keeps the result
    within 50 dB PSNR of one pass (docs/guide.md, "Tiling"); two threads calling one model at
    once get the one-thread result exactly."""
    packed, meta = pgrf.read(dark, clip=False)
    crop = np.ascontiguousarray(packed[:, 0:160, 0:400])
    whole = spc.restore(crop, ratio=100, noise=meta.noise_profile)
    tiled = spc.restore(crop, ratio=100, noise=meta.noise_profile, tile=160, overlap=64)
    mse = float(np.mean((whole.astype(np.float64) - tiled) ** 2))
    print("tiles of 160 against one pass: max", np.abs(whole - tiled).max(), "PSNR", -10 * np.log10(mse))
    assert 0 < mse and -10 * np.log10(mse) > 50
    results = [None, None]

    def work(i):
        results[i] = spc.restore(crop, ratio=100, noise=meta.noise_profile)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(np.array_equal(r, whole) for r in results)


def test_the_model_says_what_it_is(spc):
    pg = pgrf.Model.load("builtin:pgrf")
    assert "SID U-Net" in spc.description and "one pass" in spc.description
    assert pg.method == "pgrf" and pg.nfe == 2
    # The built-in file's searched t2 (0.1 since the search keeps the smallest within 0.01 dB).
    assert re.search(r"t2 = 0\.1\b", pg.description), pg.description
    assert re.search(r"t2 = 0\.5\b", pgrf.Model.load("builtin:pgrf", t2=0.5).description)
    assert spc.record["arch"] == "sid-unet" and pg.record["arch"] == "sr3-prior"
    assert pgrf.Model.load("builtin:pgrf", sampler="one-step").nfe == 1


@pytest.mark.parametrize(
    "kwargs,needle",
    [
        (dict(packed=np.zeros((3, 8, 8), np.float32)), r"shape \(4, H/2, W/2\)"),
        (dict(packed=np.zeros((4, 8), np.float32)), "3 dimensions"),
        (dict(noise=None), "noise-aware"),
        (dict(ratio=0.0), "ratio"),
        (dict(ratio=float("inf")), "ratio"),
        (dict(noise=(-1e-5, 1e-7)), "S must be positive"),
        (dict(noise=(1e-5, 1e-7, 3.0)), r"\(S, O\)"),
        (dict(packed=np.full((4, 16, 16), np.nan, np.float32)), "not finite"),
        (dict(tile=3), "tile"),
    ],
)
def test_bad_calls_are_refused(spc, kwargs, needle):
    args = dict(packed=np.full((4, 16, 16), 0.01, np.float32), ratio=10.0, noise=(1e-5, 1e-7))
    args.update(kwargs)
    packed = args.pop("packed")
    with pytest.raises(ValueError, match=needle):
        spc.restore(packed, **args)


def test_meta_of_another_size_is_refused(dark, spc):
    packed, meta = pgrf.read(dark, clip=False)
    with pytest.raises(ValueError, match="packs to"):
        spc.restore(packed[:, :64, :64], ratio=100, meta=meta)


def test_bad_models_are_refused(tmp_path):
    with pytest.raises(ValueError, match="no such built-in model"):
        pgrf.Model.load("builtin:nope")
    with pytest.raises(OSError, match="nope.safetensors"):
        pgrf.Model.load(tmp_path / "nope.safetensors")
    junk = tmp_path / "junk.safetensors"
    junk.write_bytes(b"\x00" * 64)
    with pytest.raises(ValueError, match="junk.safetensors"):
        pgrf.Model.load(junk)
    with pytest.raises(ValueError, match="sampler"):
        pgrf.Model.load("builtin:pgrf", sampler="heun")
    with pytest.raises(ValueError, match="device"):
        pgrf.Model.load("builtin:spc", device="tpu")


def test_the_gil_is_released_while_the_network_runs(dark, spc):
    """While one thread restores the whole frame, Python code in another keeps running through
    the middle half of the call."""
    import time

    packed, meta = pgrf.read(dark, clip=False)
    span, done = [], threading.Event()

    def work():
        t0 = time.perf_counter()
        spc.restore(packed, ratio=100, noise=meta.noise_profile)
        span.extend([t0, time.perf_counter()])
        done.set()

    t = threading.Thread(target=work)
    t.start()
    stamps = []
    while not done.is_set():
        stamps.append(time.perf_counter())
        time.sleep(0.001)
    t.join()
    t0, t1 = span
    mid = [s for s in stamps if t0 + 0.25 * (t1 - t0) < s < t0 + 0.75 * (t1 - t0)]
    assert t1 - t0 > 0.05 and len(mid) >= 10, (t1 - t0, len(mid))
