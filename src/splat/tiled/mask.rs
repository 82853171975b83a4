//! The image's opaque pixels, a bit each, against which splats are culled before projection.

use super::TILE;

/// Which pixels of the image are opaque, a bit each, in rows of 64-pixel words: splats are
/// tested against it before they are projected. A pixel each, not a tile or a square of
/// pixels, since along a silhouette and round a thin bone's open pixels whole squares never
/// turn opaque while most of their pixels do.
#[derive(Debug, Default)]
pub(super) struct OpaqueMask {
    /// Words in a row of the image.
    pub(super) words: usize,
    /// Bit `x % 64` of word `y * words + x / 64` for pixel `(x, y)`, set where opaque.
    pub(super) bits: Vec<u64>,
}

impl OpaqueMask {
    /// No pixel of a `w` by `h` image opaque.
    pub(super) fn reset(&mut self, w: usize, h: usize) {
        self.words = w.div_ceil(64);
        self.bits.clear();
        self.bits.resize(self.words * h, 0);
    }

    /// Takes the opaque pixels of the tile whose top-left pixel is `(x0, y0)` from its rows
    /// of open pixels (rows and columns past the image's edges are never read).
    pub(super) fn set_tile(&mut self, x0: usize, y0: usize, rows: &[u16; TILE]) {
        let (word, shift) = (x0 / 64, x0 % 64);
        for (ly, &open) in rows.iter().enumerate() {
            if let Some(bits) = self.bits.get_mut((y0 + ly) * self.words + word) {
                *bits = (*bits & !(0xffff << shift)) | u64::from(!open) << shift;
            }
        }
    }

    /// Whether every pixel from `(x0, y0)` to `(x1, y1)` (inclusive, on the image, `x0 <= x1`,
    /// `y0 <= y1`) is opaque.
    #[inline(always)]
    pub(super) fn covers(&self, x0: usize, x1: usize, y0: usize, y1: usize) -> bool {
        let (w0, w1) = (x0 / 64, x1 / 64);
        let first = u64::MAX << (x0 % 64);
        let last = u64::MAX >> (63 - x1 % 64);
        let Some(rows) = self.bits.get(y0 * self.words..(y1 + 1) * self.words) else {
            return false;
        };
        if w1 >= self.words {
            return false;
        }
        let mut rows = rows.chunks_exact(self.words);
        if w0 == w1 {
            let span = first & last;
            rows.all(|row| row[w0] & span == span)
        } else {
            rows.all(|row| {
                row[w0] & first == first
                    && row[w1] & last == last
                    && row[w0 + 1..w1].iter().all(|&b| b == u64::MAX)
            })
        }
    }

    /// [`OpaqueMask::covers`] for a splat's pixel rectangle as [`Projected`] holds it.
    #[inline(always)]
    pub(super) fn covers_rect(&self, [x0, y0, x1, y1]: [i32; 4]) -> bool {
        x0 <= x1 && y0 <= y1 && x0 >= 0 && y0 >= 0 && {
            let [x0, y0, x1, y1] = [x0, y0, x1, y1].map(|v| v as usize);
            self.covers(x0, x1, y0, y1)
        }
    }
}
