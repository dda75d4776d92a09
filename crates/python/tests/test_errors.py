"""Bad input raises ValueError or OSError with pgrf's message; nothing crashes the interpreter."""

import numpy as np
import pytest

import pgrf

A7S2 = pgrf.Profile.builtin("sony-a7s2")


def test_a_missing_file_is_an_os_error(tmp_path):
    with pytest.raises(OSError, match="nope.dng"):
        pgrf.read(tmp_path / "nope.dng")


def test_a_file_that_is_no_raw_is_a_value_error(tmp_path):
    bad = tmp_path / "notes.dng"
    bad.write_text("not a raw file\n" * 10)
    with pytest.raises(ValueError, match="notes.dng: cannot decode"):
        pgrf.read(bad)
    empty = tmp_path / "empty.dng"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match="file is empty"):
        pgrf.read(empty)


@pytest.mark.parametrize(
    "kwargs,needle",
    [
        (dict(ratio=0.0), "ratio"),
        (dict(ratio=float("nan")), "ratio"),
        (dict(model="gauss"), "model"),
        (dict(components="P,Z"), "Z"),
        (dict(dark_rate=-1.0), "dark-rate"),
        (dict(dark_law="cubic"), "dark_law"),
        (dict(exposure_s=-0.5), "exposure"),
    ],
)
def test_bad_settings_are_refused_before_work(kwargs, needle):
    with pytest.raises(ValueError, match=needle):
        pgrf.synth(np.zeros((4, 8, 8), np.float32), A7S2, seed=1, **kwargs)


def test_bad_images_are_refused():
    with pytest.raises(ValueError, match=r"\(4, H/2, W/2\)"):
        pgrf.synth(np.zeros((3, 8, 8), np.float32), A7S2)
    with pytest.raises(ValueError, match="3 dimensions"):
        pgrf.synth(np.zeros((8, 8), np.float32), A7S2)
    img = np.zeros((4, 8, 8), np.float32)
    img[1, 2, 3] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        pgrf.synth(img, A7S2)
    with pytest.raises(ValueError, match="2 images but 3 seeds"):
        pgrf.synth_batch(np.zeros((2, 4, 8, 8), np.float32), A7S2, seeds=[1, 2, 3])
    with pytest.raises(ValueError, match="seed"):
        pgrf.synth(np.zeros((4, 8, 8), np.float32), A7S2, seed=-1)


def test_profiles_name_what_exists(tmp_path):
    with pytest.raises(ValueError, match="sony-a7s2"):
        pgrf.Profile.builtin("sony-a9")
    with pytest.raises(ValueError):
        pgrf.Profile.load(str(tmp_path / "missing.json"))
    with pytest.raises(OSError, match="missing.safetensors"):
        pgrf.Profile.calibration(str(tmp_path / "missing.safetensors"))
    (tmp_path / "junk.safetensors").write_bytes(b"\x00" * 64)
    with pytest.raises(ValueError, match="junk.safetensors"):
        pgrf.Profile.calibration(str(tmp_path / "junk.safetensors"))
    with pytest.raises(TypeError):
        pgrf.synth(np.zeros((4, 8, 8), np.float32), 42)


def test_writing_refuses_a_mismatch(asset_dng, tmp_path):
    packed, meta = pgrf.read(asset_dng)
    with pytest.raises(ValueError, match="shape"):
        pgrf.write_dng(tmp_path / "x.dng", packed[:, :10], meta)
    from dataclasses import replace

    with pytest.raises(ValueError, match="differ from the file's"):
        pgrf.write_dng(tmp_path / "x.dng", packed, replace(meta, white=4095))
    with pytest.raises(ValueError, match="cfa"):
        pgrf.write_dng(tmp_path / "x.dng", packed, replace(meta, cfa="RGBW", header=None))
    nan = packed.copy()
    nan[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        pgrf.write_dng(tmp_path / "x.dng", nan, meta)
    assert not list(tmp_path.iterdir()), "nothing written"
    with pytest.raises(ValueError, match="meta"):
        pgrf.synth(packed[:, :10], A7S2, meta=meta)


def test_threads_are_bounded():
    with pytest.raises(ValueError, match="1024"):
        pgrf.set_threads(100000)
    pgrf.set_threads(None)


def test_a_stated_size_is_not_allocated_before_it_is_checked(tmp_path):
    """A Metadata stating a 65536 x 65536 frame (8 GiB of pixels) with a
    small array: refused by the shape check, nothing allocated for it."""
    meta = pgrf.Metadata(width=65536, height=65536, cfa="RGGB", black=(0.0,) * 4, white=4095, bits=12)
    small = np.zeros((4, 4, 4), np.float32)
    with pytest.raises(ValueError, match=r"packs to \(4, 32768, 32768\)"):
        pgrf.write_dng(tmp_path / "x.dng", small, meta)
    with pytest.raises(ValueError, match=r"packs to \(4, 32768, 32768\)"):
        pgrf.synth(small, A7S2, meta=meta)
    assert not list(tmp_path.iterdir())
