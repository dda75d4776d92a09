"""A DataLoader forks its workers after the parent may have used pgrf: a
forked child must not wait on the parent's threads (it has none of them)."""

import multiprocessing as mp
import sys

import numpy as np
import pytest

import pgrf

CLEAN = np.linspace(0, 1, 4 * 64 * 48, dtype=np.float32).reshape(4, 64, 48)


def capture():
    return pgrf.synth(CLEAN, "sony-a7s2", ratio=100, iso=1600, model="eld", seed=3).dark


@pytest.mark.skipif(sys.platform != "linux", reason="fork is the Linux DataLoader's default")
@pytest.mark.parametrize("threads", [None, 2])
# Python 3.12+ warns of exactly the case tested: fork() of a process with threads.
@pytest.mark.filterwarnings("ignore:This process .* is multi-threaded")
def test_a_forked_child_synthesises_what_the_parent_does(threads):
    pgrf.set_threads(threads)
    try:
        parent = capture()  # the parent's pool exists now
        with mp.get_context("fork").Pool(2) as pool:
            children = [r.get(timeout=120) for r in [pool.apply_async(capture) for _ in range(2)]]
    finally:
        pgrf.set_threads(None)
    for child in children:
        assert np.array_equal(child, parent)


def test_the_models_report_what_they_drew():
    pg = pgrf.synth(CLEAN, "sony-a7s2", ratio=100, iso=1600, model="pg", seed=1)
    eld = pgrf.synth(CLEAN, "sony-a7s2", ratio=100, iso=1600, model="eld", seed=1)
    full = pgrf.synth(CLEAN, "sony-a7s2", ratio=100, iso=1600, model="pgrf", components="P,G,Q", seed=1)
    assert (pg.components, pg.row_dn) == ("P,G", 0.0)
    assert eld.components == "P,G,H,Q,F" and eld.row_dn > 0
    assert (full.components, full.row_dn) == ("P,G,Q", 0.0)
    assert "dark=" not in repr(pg) and "ratio=100" in repr(pg)
