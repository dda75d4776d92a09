"""`pgrf.calibrate` on pgrf's virtual sensor (`pgrf simulate-sensor`, A7S2
at ISO 1600, known per-pixel truth): the figures against the truth, and the
maps equal to what `pgrf calibrate` writes from the same frames."""

import json
import struct

import numpy as np
import pytest

import pgrf


def read_safetensors(path):
    """A safetensors file read with the format's own rules (8-byte header
    length, JSON header, raw little-endian tensors): pgrf's files must read
    in any safetensors reader, not only pgrf."""
    data = path.read_bytes()
    (n,) = struct.unpack("<Q", data[:8])
    header = json.loads(data[8:8 + n])
    meta = header.pop("__metadata__", {})
    body = data[8 + n:]
    out = {}
    for name, t in header.items():
        assert t["dtype"] == "F32", (name, t["dtype"])
        a, b = t["data_offsets"]
        out[name] = np.frombuffer(body[a:b], dtype="<f4").reshape(t["shape"])
    return meta, out


@pytest.fixture(scope="module")
def sensor(tmp_path_factory, run_pgrf):
    d = tmp_path_factory.mktemp("vs")
    run_pgrf("simulate-sensor", "--frames", "16", "--width", "128", "--height", "96", "-o", d / "vs")
    return d


def test_calibration_finds_the_truth_and_equals_the_command(sensor, run_pgrf):
    vs = sensor / "vs"
    files = {k: sorted((vs / k).iterdir()) for k in ("bias", "flat", "dark")}
    cal = pgrf.calibrate(bias=files["bias"], flat=files["flat"], dark=files["dark"])
    truth_meta, truth = read_safetensors(vs / "truth.safetensors")
    t = next(json.loads(v) for v in truth_meta.values() if v.lstrip().startswith("{"))
    r = cal.record
    # K within 2 %; the per-pixel read noise's median within 2 % of the
    # truth's (16 frames, the small-sample corrected estimate).
    assert r["K"] == pytest.approx(t["K"], rel=0.02)
    assert r["read_sigma_median"] == pytest.approx(t["read_sigma_median"], rel=0.02)
    assert (r["width"], r["height"], r["iso"]) == (128, 96, 1600)
    m = cal.maps
    assert m["sigma_read"].shape == (4, 48, 64) and m["sigma_read"].dtype == np.float32
    rel = np.median(np.abs(m["sigma_read"] / truth["sigma_read"] - 1))
    assert rel < 0.25, rel  # 16 samples per pixel: sd of a sd estimate is about 18 %
    assert all(np.isfinite(a).all() for a in m.values())

    # The command's file holds the same maps, to the bit, and the package's save() the same bytes.
    run_pgrf("calibrate", "--bias", vs / "bias", "--dark", vs / "dark", "--flat", vs / "flat",
             "-o", sensor / "cli.safetensors")
    cli = pgrf.Calibration.load(sensor / "cli.safetensors")
    assert sorted(cli.maps) == sorted(m)
    for name in m:
        assert np.array_equal(cli.maps[name], m[name]), name
    cal.save(sensor / "py.safetensors")
    _, saved = read_safetensors(sensor / "py.safetensors")
    assert np.array_equal(saved["sigma_read"], m["sigma_read"])

    # A calibrated profile drives the PGRF model: its K is the calibration's.
    prof = pgrf.Profile.calibration(str(sensor / "py.safetensors"))
    assert prof.calibrated
    cap = pgrf.synth(np.full((4, 48, 64), 0.2, np.float32), prof, ratio=20, seed=1)
    assert cap.k == pytest.approx(r["K"]) and cap.iso == 1600


def test_calibration_refuses_missing_frames(tmp_path):
    with pytest.raises(ValueError):
        pgrf.calibrate(bias=[], flat=[])
    with pytest.raises(OSError):
        pgrf.calibrate(bias=[tmp_path / "b1.dng", tmp_path / "b2.dng"], flat=[tmp_path / "f1.dng", tmp_path / "f2.dng"])
