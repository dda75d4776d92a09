//! Which mosaic pixels a front-to-back painter has covered so far.
//!
//! The dead-leaves pass draws some ten discs for every one that ends up
//! visible: once most of the image is covered, almost every new disc lands
//! on pixels that are already taken. Coverage is therefore kept as one 64-bit
//! word per 8x8 tile, so a hidden disc is rejected by comparing a few words
//! with all-ones, before any square root, and a visible one is rasterised a
//! tile at a time with bit masks.
//!
//! Rounding uses local floor/ceil built on truncating casts: the library
//! versions are function calls on baseline x86-64 and dominated the profile,
//! and these give the same bits everywhere.

/// Largest integer <= x, for |x| < 2^63.
#[inline]
pub(super) fn floor64(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// Smallest integer >= x, for |x| < 2^63.
#[inline]
pub(super) fn ceil64(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t < x {
        t + 1.0
    } else {
        t
    }
}

/// Largest integer <= x, for |x| < 2^31.
#[inline]
pub(super) fn floor32(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

pub(super) struct Coverage {
    width: usize,
    height: usize,
    tiles_x: usize,
    /// Bit `8 * (row % 8) + col % 8` of tile `(row / 8, col / 8)`; pixels
    /// beyond the image edge start covered, so a full tile is `!0`.
    tiles: Vec<u64>,
    remaining: usize,
    /// Per-row spans of the disc being painted (reused allocation).
    spans: Vec<(i32, i32)>,
}

impl Coverage {
    pub(super) fn new(width: usize, height: usize) -> Self {
        let (tiles_x, tiles_y) = (width.div_ceil(8), height.div_ceil(8));
        let mut tiles = vec![0u64; tiles_x * tiles_y];
        if !width.is_multiple_of(8) {
            let row_bits = (0xFFu64 << (width % 8)) & 0xFF;
            let mask = row_bits * 0x0101_0101_0101_0101;
            for ty in 0..tiles_y {
                tiles[ty * tiles_x + tiles_x - 1] |= mask;
            }
        }
        if !height.is_multiple_of(8) {
            let mask = !0u64 << (8 * (height % 8));
            for t in &mut tiles[(tiles_y - 1) * tiles_x..] {
                *t |= mask;
            }
        }
        Coverage {
            width,
            height,
            tiles_x,
            tiles,
            remaining: width * height,
            spans: Vec::new(),
        }
    }

    pub(super) fn remaining(&self) -> usize {
        self.remaining
    }

    /// Cover the not yet covered pixels whose centres (col, row) lie within
    /// distance `r` of (cx, cy) and inside rows `clip[0]..=clip[1]`, columns
    /// `clip[2]..=clip[3]`, appending their (row, col) to `out` in a fixed
    /// order; returns how many there were.
    pub(super) fn paint(
        &mut self,
        cx: f64,
        cy: f64,
        r: f64,
        clip: [usize; 4],
        out: &mut Vec<[u32; 2]>,
    ) -> usize {
        if self.remaining == 0 {
            return 0;
        }
        let [ya, yb, xa, xb] = clip.map(|v| v as f64);
        let (wmax, hmax) = ((self.width - 1) as f64, (self.height - 1) as f64);
        let (y0, y1) = (ceil64(cy - r).max(ya), floor64(cy + r).min(yb).min(hmax));
        let (x0, x1) = (ceil64(cx - r).max(xa), floor64(cx + r).min(xb).min(wmax));
        if y0 > y1 || x0 > x1 {
            return 0;
        }
        let (x0, x1, y0, y1) = (x0 as usize, x1 as usize, y0 as usize, y1 as usize);
        let (tx0, tx1, ty0, ty1) = (x0 / 8, x1 / 8, y0 / 8, y1 / 8);
        let tx_n = self.tiles_x;
        let hidden = (ty0..=ty1).all(|ty| {
            self.tiles[ty * tx_n + tx0..=ty * tx_n + tx1]
                .iter()
                .all(|&t| t == !0)
        });
        if hidden {
            return 0;
        }

        let r2 = r * r;
        self.spans.clear();
        self.spans.extend((y0..=y1).map(|row| {
            let dy = row as f64 - cy;
            let rem = r2 - dy * dy;
            if rem < 0.0 {
                return (1, 0);
            }
            let half = rem.sqrt();
            (
                ceil64(cx - half).max(x0 as f64) as i32,
                floor64(cx + half).min(x1 as f64) as i32,
            )
        }));

        let spans = &self.spans;
        let tiles = &mut self.tiles;
        let mut count = 0usize;
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                let tile = &mut tiles[ty * tx_n + tx];
                if *tile == !0 {
                    continue;
                }
                let c0 = (tx * 8) as i32;
                let mut mask = 0u64;
                for row in (ty * 8).max(y0)..=(ty * 8 + 7).min(y1) {
                    let (xa, xb) = spans[row - y0];
                    let (lo, hi) = (xa.max(c0), xb.min(c0 + 7));
                    if lo <= hi {
                        let bits = (0xFFu64 >> (7 - (hi - lo))) << (lo - c0);
                        mask |= bits << (8 * (row % 8));
                    }
                }
                let mut new = mask & !*tile;
                if new == 0 {
                    continue;
                }
                *tile |= new;
                count += new.count_ones() as usize;
                let (r0, c0) = ((ty * 8) as u32, (tx * 8) as u32);
                while new != 0 {
                    let b = new.trailing_zeros();
                    out.push([r0 + b / 8, c0 + b % 8]);
                    new &= new - 1;
                }
            }
        }
        self.remaining -= count;
        count
    }

    /// Whether the pixel at (row, col) is covered.
    #[inline]
    pub(super) fn is_covered(&self, row: u32, col: u32) -> bool {
        let (row, col) = (row as usize, col as usize);
        let tile = self.tiles[(row / 8) * self.tiles_x + col / 8];
        tile >> (8 * (row % 8) + col % 8) & 1 == 1
    }

    /// (row, col) of every uncovered pixel, tile by tile.
    pub(super) fn uncovered(&self) -> Vec<[u32; 2]> {
        let mut out = Vec::with_capacity(self.remaining);
        for (t, &tile) in self.tiles.iter().enumerate() {
            let mut free = !tile;
            let (r0, c0) = ((t / self.tiles_x * 8) as u32, (t % self.tiles_x * 8) as u32);
            while free != 0 {
                let b = free.trailing_zeros();
                out.push([r0 + b / 8, c0 + b % 8]);
                free &= free - 1;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn local_rounding_matches_std() {
        for i in -2000..2000 {
            let x = i as f64 * 0.37 + 0.001 * (i % 7) as f64;
            assert_eq!(floor64(x), x.floor(), "{x}");
            assert_eq!(ceil64(x), x.ceil(), "{x}");
            assert_eq!(floor32(x as f32), (x as f32).floor(), "{x}");
        }
        for x in [-1.0, 0.0, 1.0, -0.5, 0.5, 3.0, -3.0] {
            assert_eq!(floor64(x), f64::floor(x));
            assert_eq!(ceil64(x), f64::ceil(x));
        }
    }

    #[test]
    fn paint_covers_exactly_the_disc_once() {
        // Odd sizes exercise the partial edge tiles.
        let (w, h) = (37, 21);
        let mut cov = Coverage::new(w, h);
        let all = [0, h - 1, 0, w - 1];
        let mut owner = vec![0u32; w * h];
        let discs = [
            (10.3, 7.7, 6.2),
            (30.0, 18.0, 9.0),
            (-2.0, 0.5, 4.5),
            (20.0, 10.0, 1.5),
        ];
        for (k, &(cx, cy, r)) in discs.iter().enumerate() {
            let mut out = Vec::new();
            let n = cov.paint(cx, cy, r, all, &mut out);
            assert_eq!(n, out.len());
            for [row, col] in out {
                let i = row as usize * w + col as usize;
                assert_eq!(owner[i], 0, "pixel {i} painted twice");
                assert!(cov.is_covered(row, col));
                owner[i] = k as u32 + 1;
            }
        }
        for row in 0..h {
            for col in 0..w {
                // The first disc (in order) containing the pixel owns it.
                let want = discs
                    .iter()
                    .position(|&(cx, cy, r)| {
                        let (dx, dy) = (col as f64 - cx, row as f64 - cy);
                        dx * dx + dy * dy <= r * r
                    })
                    .map_or(0, |k| k as u32 + 1);
                assert_eq!(owner[row * w + col], want, "({row}, {col})");
            }
        }
        let left = owner.iter().filter(|&&o| o == 0).count();
        assert_eq!(cov.remaining(), left);
        // A disc over already covered pixels only is rejected whole.
        let mut out = Vec::new();
        assert_eq!(cov.paint(10.3, 7.7, 3.0, all, &mut out), 0);
        assert!(out.is_empty());
        // Clipping keeps a disc inside its window.
        let mut clipped = Vec::new();
        cov.paint(5.0, 15.0, 20.0, [12, 14, 3, 6], &mut clipped);
        assert!(!clipped.is_empty());
        for &[row, col] in &clipped {
            assert!((12..=14).contains(&row) && (3..=6).contains(&col));
            owner[row as usize * w + col as usize] = 50;
        }
        let left = left - clipped.len();
        // The uncovered list is exactly the pixels no disc owns.
        let free = cov.uncovered();
        assert_eq!(free.len(), left);
        for [row, col] in free {
            assert_eq!(owner[row as usize * w + col as usize], 0);
            assert!(!cov.is_covered(row, col));
        }
    }
}
