#!/usr/bin/env python3
"""ELD-style noisy/clean training pairs made on the fly with pgrf, as a
PyTorch Dataset.

Why on the fly: ELD (Wei et al., CVPR 2020) trains on clean long exposures
with synthetic low-light noise; drawing the noise per item instead of
storing noisy copies gives a fresh capture (gain, read-noise scale, ratio)
every epoch at no disk cost, and pgrf's synthesis is fast enough to keep a
GPU fed from a couple of DataLoader workers.

Sources: clean RAWs (`pgrf.read`, packed R, G1, B, G2 planes normalised to
[0, 1]) or ordinary photos (JPEG/PNG/TIFF: `pgrf.read_photo`, then
`pgrf.unprocess` takes the crop into the camera's RAW space, as Brooks et
al.'s unprocessing does).

Reproducibility: every random choice of an item (crop, flips, ratio, ISO,
unprocessing jitter, noise) comes from one seed derived from
(base_seed, epoch, index) by numpy's SeedSequence, never from a process-wide
generator, so item i of epoch e is the same whatever the worker count, the
batch size or the order the sampler asks in; pgrf's results do not depend on
its thread count either. Call `set_epoch(e)` before iterating an epoch (with
the default, non-persistent workers each epoch's workers get the new value).

Usage: python3 examples/python/torch_dataset.py [FOLDER] [--workers 2] ...
(no FOLDER: a few synthetic photos are written to a temporary folder).
Runs on the CPU; no GPU needed.
"""
import argparse
import os
import sys
import tempfile
import time

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

import pgrf

PHOTO_EXTS = {".jpg", ".jpeg", ".png", ".tif", ".tiff"}
RAW_EXTS = {".dng", ".arw", ".cr2", ".cr3", ".nef", ".nrw", ".raf", ".orf", ".rw2", ".pef", ".srw", ".erf", ".3fr", ".iiq"}


def worker_init_fn(worker_id):
    """Give each DataLoader worker one pgrf thread (and one torch thread):
    the workers are the parallelism, and N workers x all cores would only
    oversubscribe. (pgrf makes its thread pool anew in a forked worker, so
    this is for speed only; results do not depend on it.)"""
    pgrf.set_threads(1)
    torch.set_num_threads(1)


class LowLightPairs(Dataset):
    """(noisy_brightened, clean) pairs, float32 tensors of shape
    (4, patch, patch), from the images in `root`.

    patch       crop side in packed pixels (the mosaic area is 2 patch x 2 patch)
    profile     pgrf camera profile (builtin name) the noise and unprocessing use
    model       noise model: "pgrf", "eld" or "pg"
    ratio_range exposure ratio drawn uniformly (ELD: U(100, 300))
    iso_range   ISO drawn log-uniformly (each octave equally likely, as ELD
                draws the gain K), rounded to an integer; None: no ISO, pgrf
                draws the whole capture from the profile's ELD distribution
    augment     random flips/transpose of the packed clean crop (ELD/SID's
                augmentation), before the noise so row noise stays along rows
    repeat      items per file per epoch (several crops of one file)
    cache       keep decoded files in the worker's memory (ELD's `memorize`)
    base_seed   the run's seed
    """

    def __init__(self, root, patch=512, profile="sony-a7s2", model="eld", ratio_range=(100.0, 300.0),
                 iso_range=(800, 6400), augment=True, repeat=1, cache=False, base_seed=0):
        self.files = sorted(
            os.path.join(root, f) for f in os.listdir(root)
            if os.path.splitext(f)[1].lower() in PHOTO_EXTS | RAW_EXTS)
        if not self.files:
            raise FileNotFoundError(f"no photos ({', '.join(sorted(PHOTO_EXTS))}) or RAWs in {root}")
        if model not in ("pgrf", "eld", "pg"):
            raise ValueError(f"model '{model}' (pgrf, eld or pg)")
        self.patch, self.profile_name, self.model = int(patch), profile, model
        self.ratio_range, self.iso_range = ratio_range, iso_range
        self.augment, self.repeat, self.cache = augment, int(repeat), cache
        self.base_seed, self.epoch = int(base_seed), 0
        self._profile = None   # built lazily in each process (not pickled)
        self._decoded = {}

    def __getstate__(self):
        s = self.__dict__.copy()
        s["_profile"], s["_decoded"] = None, {}
        return s

    def set_epoch(self, epoch):
        """Items of a new epoch get new randomness (crops, noise...)."""
        self.epoch = int(epoch)

    def __len__(self):
        return len(self.files) * self.repeat

    @property
    def profile(self):
        if self._profile is None:
            self._profile = pgrf.Profile.builtin(self.profile_name)
        return self._profile

    def item_seed(self, index):
        """The one seed of item `index` this epoch: SeedSequence of
        (base_seed, epoch, index) (a hash, not a running generator)."""
        return np.random.SeedSequence([self.base_seed, self.epoch, int(index)])

    def _load(self, path):
        if self.cache and path in self._decoded:
            return self._decoded[path]
        if os.path.splitext(path)[1].lower() in PHOTO_EXTS:
            data = ("photo", pgrf.read_photo(path), None)
        else:
            packed, meta = pgrf.read(path)
            if packed.ndim != 3 or packed.shape[0] != 4:
                raise ValueError(f"{path}: expected 4 packed Bayer planes, got {packed.shape} (cfa {meta.cfa})")
            data = ("raw", packed, str(meta.cfa))
        if self.cache:
            self._decoded[path] = data
        return data

    def _clean_crop(self, path, rng, unprocess_seed):
        """A (4, patch, patch) float32 clean crop of `path`, and the CFA of
        its planes (None: unprocessed photo, pgrf's default layout)."""
        kind, img, cfa = self._load(path)
        p = self.patch
        if kind == "photo":
            h, w = img.shape[0] // 2, img.shape[1] // 2     # in packed pixels
        else:
            h, w = img.shape[1], img.shape[2]
        if h < p or w < p:
            raise ValueError(f"{path}: {2 * w}x{2 * h} is smaller than a {2 * p}x{2 * p} crop")
        y, x = int(rng.integers(0, h - p + 1)), int(rng.integers(0, w - p + 1))
        if kind == "photo":
            # Crop the photo first (even offsets keep the Bayer phase), then
            # unprocess only the crop: 2p x 2p pixels instead of the frame.
            crop = np.ascontiguousarray(img[2 * y:2 * (y + p), 2 * x:2 * (x + p)])
            clean = pgrf.unprocess(crop, camera=self.profile_name, seed=unprocess_seed)
        else:
            clean = img[:, y:y + p, x:x + p]
        return np.asarray(clean, dtype=np.float32), cfa

    def _synthesise(self, clean, ratio, iso, seed, cfa=None):
        """The brightened noisy input for `clean` (override to try another
        noise model; bench/python_synth.py does with ELD's numpy one). `cfa`
        tells pgrf which planes share a sensor row (row noise)."""
        cap = pgrf.synth(clean, self.profile, ratio=ratio, iso=iso, model=self.model, seed=seed, cfa=cfa)
        return np.asarray(cap.brightened, dtype=np.float32)

    def __getitem__(self, index):
        if not 0 <= index < len(self):
            raise IndexError(index)
        rng = np.random.default_rng(self.item_seed(index))
        ratio = float(rng.uniform(*self.ratio_range))
        iso = None
        if self.iso_range is not None:
            lo, hi = self.iso_range
            iso = int(round(float(np.exp(rng.uniform(np.log(lo), np.log(hi))))))
        flips = rng.integers(0, 2, size=3)
        unprocess_seed, noise_seed = (int(s) for s in rng.integers(0, 2 ** 63 - 1, size=2))
        clean, cfa = self._clean_crop(self.files[index // self.repeat], rng, unprocess_seed)
        if self.augment:
            if flips[0]:
                clean = clean[:, ::-1, :]
            if flips[1]:
                clean = clean[:, :, ::-1]
            if flips[2]:
                clean = clean.transpose(0, 2, 1)
        clean = np.ascontiguousarray(clean, dtype=np.float32)
        noisy = self._synthesise(clean, ratio, iso, noise_seed, cfa)
        return torch.from_numpy(np.ascontiguousarray(noisy)), torch.from_numpy(clean)


# --- synthetic photos, written without pgrf (numpy + PIL, else a plain TIFF) ---

def smooth_scene(h, w, rng):
    """A smooth random RGB scene in [0, 1]: bilinear-upsampled coarse noise,
    a lighting gradient and a few flat-coloured rectangles (edges)."""
    def upsample(coarse, h, w):
        ch, cw = coarse.shape[:2]
        ys, xs = np.linspace(0, ch - 1, h), np.linspace(0, cw - 1, w)
        y0, x0 = np.floor(ys).astype(int).clip(0, ch - 2), np.floor(xs).astype(int).clip(0, cw - 2)
        fy, fx = (ys - y0)[:, None, None], (xs - x0)[None, :, None]
        a, b = coarse[y0][:, x0], coarse[y0][:, x0 + 1]
        c, d = coarse[y0 + 1][:, x0], coarse[y0 + 1][:, x0 + 1]
        return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy
    img = 0.6 * upsample(rng.random((h // 150 + 2, w // 150 + 2, 3)), h, w)
    img += 0.3 * upsample(rng.random((h // 40 + 2, w // 40 + 2, 3)), h, w)
    img *= np.linspace(0.4, 1.0, w)[None, :, None]
    for _ in range(6):
        y0, x0 = int(rng.integers(0, h - 64)), int(rng.integers(0, w - 64))
        img[y0:y0 + int(rng.integers(32, h // 3)), x0:x0 + int(rng.integers(32, w // 3))] = rng.random(3)
    return img.clip(0, 1).astype(np.float32)


def _write_tiff(path, rgb8):
    """Minimal baseline TIFF (8-bit RGB, uncompressed, one strip)."""
    import struct
    h, w, _ = rgb8.shape
    data = rgb8.tobytes()
    entries = [(256, 4, 1, w), (257, 4, 1, h), (258, 3, 3, None), (259, 3, 1, 1), (262, 3, 1, 2),
               (273, 4, 1, None), (277, 3, 1, 3), (278, 4, 1, h), (279, 4, 1, len(data))]
    ifd_off = 8
    ifd_len = 2 + 12 * len(entries) + 4
    bps_off = ifd_off + ifd_len
    data_off = bps_off + 6
    out = [struct.pack("<2sHI", b"II", 42, ifd_off), struct.pack("<H", len(entries))]
    for tag, typ, n, val in entries:
        if tag == 258:
            out.append(struct.pack("<HHII", tag, typ, n, bps_off))
        elif tag == 273:
            out.append(struct.pack("<HHII", tag, typ, n, data_off))
        elif typ == 3:
            out.append(struct.pack("<HHIHH", tag, typ, n, val, 0))
        else:
            out.append(struct.pack("<HHII", tag, typ, n, val))
    out.append(struct.pack("<I", 0))
    out.append(struct.pack("<HHH", 8, 8, 8))
    out.append(data)
    with open(path, "wb") as f:
        f.write(b"".join(out))


def make_photos(folder, n=4, width=1600, height=1200, seed=0):
    """Write `n` seeded synthetic photos to `folder` (PNG with PIL when it is
    installed, else uncompressed TIFF); returns their paths."""
    try:
        from PIL import Image
    except ImportError:
        Image = None
    os.makedirs(folder, exist_ok=True)
    paths = []
    for i in range(n):
        rng = np.random.default_rng([seed, i])
        img = (smooth_scene(height, width, rng) * 255 + 0.5).astype(np.uint8)
        if Image is not None:
            path = os.path.join(folder, f"scene_{i:02d}.png")
            Image.fromarray(img).save(path, compress_level=1)
        else:
            path = os.path.join(folder, f"scene_{i:02d}.tif")
            _write_tiff(path, img)
        paths.append(path)
    return paths


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder", nargs="?", help="clean RAWs or photos (default: synthetic photos in a temp folder)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--batch", type=int, default=8)
    ap.add_argument("--patch", type=int, default=512)
    ap.add_argument("--batches", type=int, default=5, help="batches to time")
    ap.add_argument("--model", default="eld", choices=["pgrf", "eld", "pg"])
    ap.add_argument("--profile", default="sony-a7s2")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--epoch", type=int, default=0)
    a = ap.parse_args()

    tmp = None
    folder = a.folder
    if folder is None:
        tmp = tempfile.TemporaryDirectory(prefix="pgrf_photos_")
        folder = tmp.name
        make_photos(folder, n=4, seed=a.seed)
        print(f"wrote 4 synthetic 1600x1200 photos to {folder}")
    need = a.batch * a.batches
    n_files = len([f for f in os.listdir(folder) if os.path.splitext(f)[1].lower() in PHOTO_EXTS | RAW_EXTS])
    ds = LowLightPairs(folder, patch=a.patch, profile=a.profile, model=a.model,
                       repeat=max(1, -(-need // max(n_files, 1))), base_seed=a.seed)
    ds.set_epoch(a.epoch)
    loader = DataLoader(ds, batch_size=a.batch, shuffle=False, num_workers=a.workers,
                        worker_init_fn=worker_init_fn if a.workers > 0 else None)
    t0 = time.perf_counter()
    first_at, n, first = None, 0, None
    for b, (noisy, clean) in enumerate(loader):
        if b == 0:
            first_at, first = time.perf_counter(), (noisy[0].clone(), clean[0].clone())
            print(f"batch: noisy {tuple(noisy.shape)} {noisy.dtype}, clean {tuple(clean.shape)} {clean.dtype}; "
                  f"noisy in [{noisy.min():.3f}, {noisy.max():.3f}], clean mean {clean.mean():.4f}")
        n += noisy.shape[0]
        if b + 1 == a.batches:
            break
    t1 = time.perf_counter()
    # Rate over the whole run, worker start-up included (with prefetching, a
    # rate counted from the first batch would credit work done before it).
    print(f"{a.workers} workers, batch {a.batch}, {a.patch}x{a.patch} packed crops, model {a.model}: "
          f"first batch after {first_at - t0:.2f} s; {n} items in {t1 - t0:.2f} s = {n / (t1 - t0):.2f} items/s")
    # Item 0 again, in this process (all pgrf threads): the same tensors.
    noisy0, clean0 = ds[0]
    same = torch.equal(noisy0, first[0]) and torch.equal(clean0, first[1])
    print(f"item 0 recomputed in the main process equals the worker's: {same}")
    if tmp is not None:
        tmp.cleanup()
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
