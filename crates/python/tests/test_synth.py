"""`pgrf.synth` and `pgrf.synth_batch`: statistics against the
Poisson-Gaussian theory, seeds, thread independence, batches equal to
single calls, and byte equality with `pgrf synth` for the same seed."""

import numpy as np
import pytest

import pgrf

A7S2 = pgrf.Profile.builtin("sony-a7s2")


def flat(level, side=128):
    return np.full((4, side, side), level, dtype=np.float32)


def test_poisson_gaussian_mean_and_variance_follow_theory():
    """Flat x = 0.3 at ratio 10: the dark capture has mean x / 10 and, in
    DN of the profile's range R, variance K mu + sigma^2 (shot and read).
    4 x 128 x 128 values: the mean within 5 standard errors, the variance
    within 4 % (its standard error is about 0.6 %)."""
    x, ratio = 0.3, 10.0
    cap = pgrf.synth(flat(x), A7S2, ratio=ratio, iso=1600, model="pg", seed=11)
    R = A7S2.dn_range
    d = cap.dark.astype(np.float64) * R
    mu = x / ratio * R
    want_var = cap.k * mu + cap.read_dn ** 2
    se = np.sqrt(want_var / d.size)
    assert abs(d.mean() - mu) < 5 * se, (d.mean(), mu, se)
    assert d.var(ddof=1) / want_var == pytest.approx(1.0, abs=0.04)
    assert cap.ratio == ratio and cap.iso == 1600 and cap.k > 0
    # The brightened form is the dark one x ratio, clipped to [0, 1].
    assert np.allclose(cap.brightened, np.clip(cap.dark * ratio, 0, 1), atol=1e-6)


def test_read_noise_alone_at_black():
    """A black frame through P-G: no shot noise, variance sigma^2 (within 4 %)."""
    cap = pgrf.synth(flat(0.0), A7S2, ratio=100, iso=3200, model="pg", seed=2)
    d = cap.dark.astype(np.float64) * A7S2.dn_range
    assert abs(d.mean()) < 5 * cap.read_dn / np.sqrt(d.size)
    assert d.var(ddof=1) / cap.read_dn ** 2 == pytest.approx(1.0, abs=0.04)


def test_seeds_decide_everything():
    rng = np.random.default_rng(1)
    clean = rng.random((4, 64, 48), dtype=np.float32)
    a = pgrf.synth(clean, A7S2, ratio=150, iso=1600, seed=5)
    b = pgrf.synth(clean, A7S2, ratio=150, iso=1600, seed=5)
    c = pgrf.synth(clean, A7S2, ratio=150, iso=1600, seed=6)
    assert np.array_equal(a.dark, b.dark) and np.array_equal(a.brightened, b.brightened)
    assert not np.array_equal(a.dark, c.dark)
    # Without a ratio, the seed draws it from U(100, 300).
    r = {pgrf.synth(clean, A7S2, iso=1600, seed=s).ratio for s in range(6)}
    assert len(r) == 6 and all(100 <= v <= 300 for v in r)


@pytest.mark.parametrize("model", ["pg", "eld", "pgrf"])
def test_the_same_arrays_from_one_and_four_threads(model):
    rng = np.random.default_rng(3)
    clean = rng.random((4, 96, 80), dtype=np.float32)
    batch = rng.random((3, 4, 32, 40), dtype=np.float32)
    out = []
    try:
        for n in (1, 4):
            pgrf.set_threads(n)
            assert pgrf.get_threads() == n
            cap = pgrf.synth(clean, A7S2, ratio=200, iso=6400, model=model, seed=9)
            b = pgrf.synth_batch(batch, A7S2, seeds=[4, 5, 6], iso=6400, model=model)
            out.append((cap.dark, cap.brightened, b.dark, b.brightened))
    finally:
        pgrf.set_threads(None)
    for one, four in zip(*out):
        assert np.array_equal(one, four)


def test_a_batch_is_its_items():
    rng = np.random.default_rng(4)
    clean = rng.random((3, 4, 40, 40), dtype=np.float32)
    seeds = [10, 20, 30]
    b = pgrf.synth_batch(clean, A7S2, seeds, iso=1600, model="eld")
    assert b.dark.shape == clean.shape and len(b.info) == 3
    for i, s in enumerate(seeds):
        one = pgrf.synth(clean[i], A7S2, iso=1600, model="eld", seed=s)
        assert np.array_equal(b.dark[i], one.dark)
        assert np.array_equal(b.brightened[i], one.brightened)
        assert b.info[i]["ratio"] == one.ratio
    assert np.array_equal(b.ratio, np.array([i["ratio"] for i in b.info], dtype=np.float32))


@pytest.mark.parametrize("model,brightened", [("pgrf", False), ("eld", False), ("pg", False), ("pgrf", True)])
def test_byte_equal_to_the_command(asset_dng, run_pgrf, tmp_path, model, brightened):
    """`pgrf synth FILE --seed 7` and `pgrf.synth(read(FILE), seed=7)` then
    `write_dng` give the same DNG, byte for byte."""
    cli = tmp_path / "cli.dng"
    args = ["synth", asset_dng, "--profile", "sony-a7s2", "--ratio", "50", "--iso", "1600",
            "--model", model, "--seed", "7", "-o", cli]
    if brightened:
        args.append("--brightened")
    run_pgrf(*args)
    clean, meta = pgrf.read(asset_dng)
    cap = pgrf.synth(clean, A7S2, ratio=50, iso=1600, model=model, seed=7, meta=meta)
    mine = tmp_path / "py.dng"
    if brightened:
        pgrf.write_dng(mine, cap.brightened, cap.brightened_meta)
    else:
        pgrf.write_dng(mine, cap.dark, cap.meta)
    a, b = cli.read_bytes(), mine.read_bytes()
    assert len(a) == len(b) and a == b
    if not brightened:
        # Every capture states its noise in the DNG, one pair per colour
        # plane: S = K / R and O = (read^2 + row^2) / R^2 of the Gaussian
        # read noise drawn (ELD's heavy-tailed read noise is reported by its
        # Tukey scale, so only S is checked there).
        R = A7S2.dn_range
        np_ = cap.meta.noise_profile
        assert len(np_) == 3 and np_[0] == np_[1] == np_[2]
        assert np_[0][0] == pytest.approx(cap.k / R, rel=1e-12)
        if model != "eld":
            o = (cap.read_dn ** 2 + cap.row_dn ** 2) / R ** 2
            assert np_[0][1] == pytest.approx(o, rel=1e-9)


def test_the_gil_is_released_while_pgrf_works():
    """While one thread synthesises a large frame (one call), Python code in
    another thread keeps running: it logs times all through the middle half
    of the call, which it could not do with the GIL held there."""
    import threading
    import time

    clean = np.full((4, 1024, 1536), 0.2, np.float32)
    span, done = [], threading.Event()

    def work():
        t0 = time.perf_counter()
        pgrf.synth(clean, A7S2, ratio=100, iso=1600, model="pgrf", seed=1)
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
    assert t1 - t0 > 0.02 and len(mid) >= 3, (t1 - t0, len(mid))


def test_noise_bank_draws_are_the_commands(run_pgrf, tmp_path):
    """With a calibration's noise bank (its bias frames' residuals), `pgrf.synth(...,
    noise_bank=True)` written with write_dng is `pgrf synth --calib C --noise-bank`, byte for
    byte; without a calibration it is refused."""
    vs = tmp_path / "vs"
    run_pgrf("simulate-sensor", "--width", "64", "--height", "48", "--frames", "4",
             "--stacks", "bias,flat", "--read-tails", "-0.2", "-o", vs)
    cal = tmp_path / "cal.safetensors"
    run_pgrf("calibrate", "--bias", vs / "bias", "--flat", vs / "flat", "-o", cal)
    src = vs / "flat" / "flat_8000e_0000.dng"
    cli = tmp_path / "cli.dng"
    run_pgrf("synth", src, "--profile", "sony-a7s2", "--calib", cal, "--noise-bank",
             "--ratio", "10", "--seed", "4", "-o", cli)
    clean, meta = pgrf.read(src)
    profile = pgrf.Profile.calibration(str(cal))
    cap = pgrf.synth(clean, profile, ratio=10, seed=4, meta=meta, noise_bank=True)
    mine = tmp_path / "py.dng"
    pgrf.write_dng(mine, cap.dark, cap.meta)
    assert cli.read_bytes() == mine.read_bytes()
    plain = pgrf.synth(clean, profile, ratio=10, seed=4, meta=meta)
    assert not np.array_equal(plain.dark, cap.dark)
    with pytest.raises(ValueError, match="noise-bank"):
        pgrf.synth(clean, A7S2, ratio=10, seed=4, meta=meta, noise_bank=True)
