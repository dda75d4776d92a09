"""`pgrf.read` and `pgrf.write_dng` against numbers from the Rust side and LibRaw.

The built-in Canon 550D chart DNG (crates/cli/assets): its metadata and
per-plane means as `pgrf info --json` prints them, and the sum of its
visible raw values as LibRaw (rawpy 0.28, raw_image_visible) reads them,
committed as numbers.
"""

import numpy as np
import pytest

import pgrf

# pgrf info --json crates/cli/assets/canon550d_colorchart.dng
PLANE_MEANS = {"R": 2391.260353683505, "G1": 2778.507948100877, "B": 2583.230830170456, "G2": 2783.144464665573}
PLANE_MIN_MAX = {"R": (1968, 7226), "G1": (1958, 12066), "B": (1969, 8118), "G2": (1973, 12128)}
# rawpy: raw_image_visible.astype(int64).sum(), and [0, :6], [1, :6]
LIBRAW_SUM = 5279935496
LIBRAW_ROW0 = [2056, 2093, 2080, 2077, 2076, 2105]
LIBRAW_ROW1 = [2075, 2067, 2082, 2075, 2076, 2082]


def dn(packed, meta):
    """Packed normalised planes back to DN."""
    black = np.array(meta.black, dtype=np.float64)[:, None, None]
    return np.asarray(packed, dtype=np.float64) * (meta.white - black) + black


def test_metadata_is_the_files(asset_dng):
    packed, meta = pgrf.read(asset_dng)
    assert (meta.width, meta.height, meta.cfa, meta.white, meta.bits) == (1734, 1156, "RGGB", 15000, 14)
    assert meta.black == (2056.0, 2056.0, 2056.0, 2056.0)
    assert (meta.make, meta.model, meta.iso, meta.exposure_s) == ("Canon", "EOS Kiss X4", None, None)
    assert meta.wb == pytest.approx((2.477, 1.0, 1.6942544), abs=1e-6)
    assert meta.color_matrices[0][0] == "D65"
    assert meta.color_matrices[0][1][0] == pytest.approx([0.6461, -0.1164, -0.0857], abs=1e-6)
    assert packed.dtype == np.float32 and packed.shape == (4, 578, 867) == meta.packed_shape
    assert packed.flags["C_CONTIGUOUS"]


def test_pixels_match_the_rust_side_and_libraw(asset_dng):
    packed, meta = pgrf.read(asset_dng, clip=False)
    values = np.rint(dn(packed, meta)).astype(np.int64)
    for p, name in enumerate(["R", "G1", "B", "G2"]):
        assert values[p].mean() == pytest.approx(PLANE_MEANS[name], rel=1e-12)
        assert (values[p].min(), values[p].max()) == PLANE_MIN_MAX[name]
    assert values.sum() == LIBRAW_SUM
    # RGGB: row 0 alternates R, G1; row 1 alternates G2, B.
    row0 = np.stack([values[0, 0, :3], values[1, 0, :3]], axis=1).ravel()
    row1 = np.stack([values[3, 0, :3], values[2, 0, :3]], axis=1).ravel()
    assert row0.tolist() == LIBRAW_ROW0 and row1.tolist() == LIBRAW_ROW1


def test_clipping_is_asked_for(asset_dng):
    clipped, _ = pgrf.read(asset_dng)
    raw, _ = pgrf.read(asset_dng, clip=False)
    assert clipped.min() >= 0.0 and raw.min() < 0.0
    assert np.array_equal(clipped, np.clip(raw, 0.0, 1.0))


def test_a_dng_written_reads_back_exactly(asset_dng, tmp_path):
    packed, meta = pgrf.read(asset_dng, clip=False)
    out = tmp_path / "copy.dng"
    pgrf.write_dng(out, packed, meta)
    again, meta2 = pgrf.read(out, clip=False)
    assert np.array_equal(again, packed)
    assert (meta2.width, meta2.height, meta2.cfa, meta2.black, meta2.white) == (
        meta.width, meta.height, meta.cfa, meta.black, meta.white)
    assert not list(tmp_path.glob("*.tmp*")), "no temporary file left"


def test_a_described_frame_round_trips(tmp_path):
    """A frame made in Python (no header): RGGB, 64 x 48, 14-bit levels."""
    rng = np.random.default_rng(5)
    meta = pgrf.Metadata(width=64, height=48, cfa="GRBG", black=(512.0,) * 4, white=16383, bits=14,
                         iso=800, exposure_s=0.01, make="Test", model="Cam")
    steps = rng.integers(0, 16383 - 512, size=meta.packed_shape)
    packed = (steps / (16383 - 512)).astype(np.float32)
    pgrf.write_dng(tmp_path / "f.dng", packed, meta)
    back, m = pgrf.read(tmp_path / "f.dng")
    assert np.array_equal(np.rint(back * (16383 - 512)).astype(np.int64), steps)
    assert (m.cfa, m.iso, m.exposure_s, m.make, m.model) == ("GRBG", 800, pytest.approx(0.01), "Test", "Cam")


def test_photos_read_as_srgb(tmp_path):
    """A 4 x 2 PNG written byte by byte (no imaging library needed)."""
    import struct
    import zlib

    w, h = 4, 2
    pixels = bytes(range(0, 24 * 10, 10))  # 8 RGB pixels, values 0..230
    raw = b"".join(b"\x00" + pixels[r * w * 3:(r + 1) * w * 3] for r in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
    (tmp_path / "p.png").write_bytes(png)
    photo = pgrf.read_photo(tmp_path / "p.png")
    assert photo.shape == (2, 4, 3) and photo.dtype == np.float32
    want = np.frombuffer(pixels, dtype=np.uint8).reshape(2, 4, 3) / 255.0
    assert np.allclose(photo, want, atol=1e-6)
