//! Text and lines drawn onto RGBA images: one font, loaded once, rasterised by ab_glyph at the
//! size asked for (so labels are crisp at any image size), each mark with a dark halo so that it
//! reads over bright bone and dark background alike.

use std::sync::OnceLock;

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};
use image::RgbaImage;

/// Where the font is looked for (Debian's fonts-dejavu-core).
pub const FONT_PATHS: [&str; 2] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

/// No font was found to draw text with.
#[derive(Debug, Clone, thiserror::Error)]
#[error(
    "no font for labels: install Debian's fonts-dejavu-core (looked for {})",
    FONT_PATHS.join(", ")
)]
pub struct NoFont;

/// The bytes of the label font, read once per process.
pub fn font_bytes() -> Result<&'static [u8], NoFont> {
    static BYTES: OnceLock<Option<&'static [u8]>> = OnceLock::new();
    BYTES
        .get_or_init(|| {
            FONT_PATHS
                .iter()
                .find_map(|p| std::fs::read(p).ok())
                .map(|b| &*Box::leak(b.into_boxed_slice()))
        })
        .ok_or(NoFont)
}

fn font() -> Result<FontRef<'static>, NoFont> {
    FontRef::try_from_slice(font_bytes()?).map_err(|_| NoFont)
}

/// A coverage mask (0 to 1 per pixel) with its place in the image.
struct Mask {
    x0: i64,
    y0: i64,
    width: usize,
    height: usize,
    cover: Vec<f32>,
}

impl Mask {
    fn new(x0: i64, y0: i64, width: usize, height: usize) -> Self {
        Self {
            x0,
            y0,
            width,
            height,
            cover: vec![0.0; width * height],
        }
    }

    fn add(&mut self, x: i64, y: i64, c: f32) {
        let (i, j) = (x - self.x0, y - self.y0);
        if i >= 0 && j >= 0 && (i as usize) < self.width && (j as usize) < self.height {
            let cell = &mut self.cover[j as usize * self.width + i as usize];
            *cell = (*cell + c).min(1.0);
        }
    }

    /// The mask grown by `radius` pixels (a max filter over a disc): the halo.
    fn dilated(&self, radius: f32) -> Self {
        let r = radius.ceil() as i64;
        let mut out = Self::new(
            self.x0 - r,
            self.y0 - r,
            self.width + 2 * r as usize,
            self.height + 2 * r as usize,
        );
        let offsets: Vec<(i64, i64, f32)> = (-r..=r)
            .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
            .filter_map(|(dx, dy)| {
                let d = ((dx * dx + dy * dy) as f32).sqrt();
                let w = (radius + 0.5 - d).clamp(0.0, 1.0);
                (w > 0.0).then_some((dx, dy, w))
            })
            .collect();
        for j in 0..self.height {
            for i in 0..self.width {
                let c = self.cover[j * self.width + i];
                if c <= 0.0 {
                    continue;
                }
                for &(dx, dy, w) in &offsets {
                    let (x, y) = (i as i64 + r + dx, j as i64 + r + dy);
                    let cell = &mut out.cover[y as usize * out.width + x as usize];
                    *cell = cell.max(c * w);
                }
            }
        }
        out
    }

    /// Blends `color` over the image, weighted by the mask.
    fn paint(&self, image: &mut RgbaImage, color: [u8; 4]) {
        for j in 0..self.height {
            for i in 0..self.width {
                let (x, y) = (self.x0 + i as i64, self.y0 + j as i64);
                let c = self.cover[j * self.width + i];
                if c <= 0.0
                    || x < 0
                    || y < 0
                    || x >= image.width() as i64
                    || y >= image.height() as i64
                {
                    continue;
                }
                blend(image.get_pixel_mut(x as u32, y as u32), color, c);
            }
        }
    }
}

/// Straight-alpha "over" of `color` with coverage `c` onto `pixel`.
fn blend(pixel: &mut image::Rgba<u8>, color: [u8; 4], c: f32) {
    let a = c * f32::from(color[3]) / 255.0;
    let dst_a = f32::from(pixel[3]) / 255.0;
    let out_a = a + dst_a * (1.0 - a);
    for k in 0..3 {
        let src = f32::from(color[k]) / 255.0;
        let dst = f32::from(pixel[k]) / 255.0;
        let v = if out_a > 0.0 {
            (src * a + dst * dst_a * (1.0 - a)) / out_a
        } else {
            0.0
        };
        pixel[k] = (v * 255.0).round().clamp(0.0, 255.0) as u8;
    }
    pixel[3] = (out_a * 255.0).round().clamp(0.0, 255.0) as u8;
}

/// Where a text's anchor point lies on it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Anchor {
    /// The anchor is the text's top-left corner.
    TopLeft,
    /// The anchor is the middle of its top edge.
    TopCentre,
    /// The anchor is its centre.
    Centre,
    /// The anchor is its top-right corner.
    TopRight,
    /// The anchor is its bottom-left corner.
    BottomLeft,
    /// The anchor is its bottom-right corner.
    BottomRight,
    /// The anchor is the middle of its bottom edge.
    BottomCentre,
}

/// Draws text and lines onto an image, each with a dark halo.
pub struct Painter<'a> {
    image: &'a mut RgbaImage,
    font: FontRef<'static>,
    /// Text height in pixels.
    pub text_px: f32,
    /// Halo width in pixels.
    pub halo_px: f32,
}

/// Colour of the halo around every mark.
const HALO: [u8; 4] = [0, 0, 0, 190];

impl<'a> Painter<'a> {
    /// A painter whose text and strokes scale with the image: text a 32nd of the shorter side,
    /// at least 11 pixels.
    pub fn new(image: &'a mut RgbaImage) -> Result<Self, NoFont> {
        let short = image.width().min(image.height()) as f32;
        let text_px = (short / 32.0).max(11.0);
        Ok(Self {
            image,
            font: font()?,
            text_px,
            halo_px: (text_px / 9.0).max(1.2),
        })
    }

    /// Image width and height.
    pub fn size(&self) -> (f32, f32) {
        (self.image.width() as f32, self.image.height() as f32)
    }

    /// The width and height of `text` at the painter's text size, in pixels.
    pub fn measure(&self, text: &str) -> (f32, f32) {
        let scaled = self.font.as_scaled(PxScale::from(self.text_px));
        let mut width = 0.0;
        let mut previous = None;
        for c in text.chars() {
            let id = scaled.glyph_id(c);
            if let Some(p) = previous {
                width += scaled.kern(p, id);
            }
            width += scaled.h_advance(id);
            previous = Some(id);
        }
        (width, scaled.ascent() - scaled.descent())
    }

    /// Draws `text` in `color` with its `anchor` at `(x, y)`; returns its box
    /// `(x0, y0, x1, y1)`.
    pub fn text(&mut self, text: &str, x: f32, y: f32, anchor: Anchor, color: [u8; 4]) -> [f32; 4] {
        let (w, h) = self.measure(text);
        let (left, top) = match anchor {
            Anchor::TopLeft => (x, y),
            Anchor::TopCentre => (x - w / 2.0, y),
            Anchor::Centre => (x - w / 2.0, y - h / 2.0),
            Anchor::TopRight => (x - w, y),
            Anchor::BottomLeft => (x, y - h),
            Anchor::BottomRight => (x - w, y - h),
            Anchor::BottomCentre => (x - w / 2.0, y - h),
        };
        let scaled = self.font.as_scaled(PxScale::from(self.text_px));
        let pad = 2;
        let mut mask = Mask::new(
            left.floor() as i64 - pad,
            top.floor() as i64 - pad,
            w.ceil() as usize + 2 * pad as usize + 2,
            h.ceil() as usize + 2 * pad as usize + 2,
        );
        let mut caret = point(left, top + scaled.ascent());
        let mut previous = None;
        for c in text.chars() {
            let id = scaled.glyph_id(c);
            if let Some(p) = previous {
                caret.x += scaled.kern(p, id);
            }
            let glyph = id.with_scale_and_position(self.text_px, caret);
            caret.x += scaled.h_advance(id);
            previous = Some(id);
            if let Some(outline) = self.font.outline_glyph(glyph) {
                let bounds = outline.px_bounds();
                outline.draw(|gx, gy, cover| {
                    mask.add(
                        bounds.min.x as i64 + i64::from(gx),
                        bounds.min.y as i64 + i64::from(gy),
                        cover,
                    );
                });
            }
        }
        mask.dilated(self.halo_px).paint(self.image, HALO);
        mask.paint(self.image, color);
        [left, top, left + w, top + h]
    }

    /// Draws an anti-aliased line of `width` pixels from `a` to `b`, with a halo.
    pub fn line(&mut self, a: [f32; 2], b: [f32; 2], width: f32, color: [u8; 4]) {
        self.lines(&[(a, b)], width, color);
    }

    /// Draws several lines as one mark, so that their halos do not cover each other.
    pub fn lines(&mut self, segments: &[([f32; 2], [f32; 2])], width: f32, color: [u8; 4]) {
        let Some(mask) = segments_mask(segments, width) else {
            return;
        };
        mask.dilated(self.halo_px).paint(self.image, HALO);
        mask.paint(self.image, color);
    }
}

/// The coverage of round-capped segments `width` pixels wide, or `None` for no segments or
/// coordinates that are not finite.
fn segments_mask(segments: &[([f32; 2], [f32; 2])], width: f32) -> Option<Mask> {
    let finite = segments
        .iter()
        .all(|(a, b)| a.iter().chain(b).all(|v| v.is_finite() && v.abs() < 1e6));
    if segments.is_empty() || !finite {
        return None;
    }
    let half = width / 2.0;
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for (a, b) in segments {
        for k in 0..2 {
            lo[k] = lo[k].min(a[k]).min(b[k]);
            hi[k] = hi[k].max(a[k]).max(b[k]);
        }
    }
    let x0 = (lo[0] - half - 1.0).floor() as i64;
    let y0 = (lo[1] - half - 1.0).floor() as i64;
    let w = ((hi[0] + half + 1.0).ceil() as i64 - x0).max(1) as usize;
    let h = ((hi[1] + half + 1.0).ceil() as i64 - y0).max(1) as usize;
    let mut mask = Mask::new(x0, y0, w, h);
    // Each segment covers the pixels of its own box alone: the coverage `half + 0.5 - d`,
    // clamped, falls with the distance, so the most any segment gives a pixel is what the
    // nearest gives. (Taken over every segment for every pixel of the mark's box, a histogram's
    // curve of a thousand segments took a third of a second a frame.)
    for (a, b) in segments {
        let lo = |k: usize| (a[k].min(b[k]) - half - 1.0).floor() as i64;
        let hi = |k: usize| (a[k].max(b[k]) + half + 1.0).ceil() as i64;
        let (i0, i1) = ((lo(0) - x0).max(0) as usize, ((hi(0) - x0) as usize).min(w));
        let (j0, j1) = ((lo(1) - y0).max(0) as usize, ((hi(1) - y0) as usize).min(h));
        for j in j0..j1 {
            for i in i0..i1 {
                let p = [(x0 + i as i64) as f32 + 0.5, (y0 + j as i64) as f32 + 0.5];
                let c = (half + 0.5 - segment_distance(p, *a, *b)).clamp(0.0, 1.0);
                let cell = &mut mask.cover[j * w + i];
                *cell = cell.max(c);
            }
        }
    }
    Some(mask)
}

fn segment_distance(p: [f32; 2], a: [f32; 2], b: [f32; 2]) -> f32 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (ex, ey) = (a[0] + t * dx - p[0], a[1] + t * dy - p[1]);
    (ex * ex + ey * ey).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_lands_where_anchored_and_grows_with_the_size() {
        let Ok(_) = font_bytes() else {
            eprintln!("skipped: no DejaVu font (fonts-dejavu-core)");
            return;
        };
        let mut small = RgbaImage::from_pixel(200, 100, image::Rgba([40, 40, 40, 255]));
        let mut painter = Painter::new(&mut small).unwrap();
        let (w, h) = painter.measure("R 50 mm");
        assert!(w > 3.0 * h && h > 8.0, "{w}x{h}");
        let b = painter.text("R 50 mm", 100.0, 50.0, Anchor::Centre, [255, 255, 255, 255]);
        assert!((0.5 * (b[0] + b[2]) - 100.0).abs() < 0.5);
        // White ink inside the box, nothing far outside it.
        let inside = (b[0] as u32..b[2] as u32)
            .flat_map(|x| (b[1] as u32..b[3] as u32).map(move |y| (x, y)))
            .filter(|&(x, y)| small.get_pixel(x, y)[0] > 200)
            .count();
        assert!(inside > 20, "{inside} white pixels in the text box");
        assert_eq!(small.get_pixel(5, 5)[0], 40);
        let mut big = RgbaImage::new(2000, 1000);
        assert!(Painter::new(&mut big).unwrap().text_px > 2.0 * 11.0);
    }

    #[test]
    fn lines_cover_their_pixels_and_refuse_nonsense() {
        let mask = segments_mask(&[([2.0, 5.5], [20.0, 5.5])], 3.0).unwrap();
        let at = |x: i64, y: i64| {
            mask.cover[((y - mask.y0) as usize) * mask.width + (x - mask.x0) as usize]
        };
        assert_eq!(at(10, 5), 1.0);
        assert_eq!(at(10, 7), 0.0);
        assert!(segments_mask(&[([f32::NAN, 0.0], [1.0, 1.0])], 2.0).is_none());
        assert!(segments_mask(&[], 2.0).is_none());
    }

    #[test]
    fn many_segments_cover_each_pixel_as_their_nearest_does() {
        // A wavy polyline and a few long strokes across it: each pixel of the mark's box as the
        // distance to the nearest segment, over all of them, says.
        let mut segments: Vec<([f32; 2], [f32; 2])> = (0..200)
            .map(|i| {
                let y = |i: i32| 40.0 + 25.0 * (i as f32 * 0.13).sin();
                ([i as f32 * 0.7, y(i)], [(i + 1) as f32 * 0.7, y(i + 1)])
            })
            .collect();
        segments.push(([3.3, 90.2], [131.0, 2.5]));
        segments.push(([60.0, 10.0], [60.0, 10.0]));
        for width in [1.0, 1.5, 4.0] {
            let mask = segments_mask(&segments, width).unwrap();
            let half = width / 2.0;
            let mut lit = 0;
            for j in 0..mask.height {
                for i in 0..mask.width {
                    let (x, y) = ((mask.x0 + i as i64) as f32, (mask.y0 + j as i64) as f32);
                    // The distance to each segment sampled every twentieth of a pixel: the
                    // true one lies within half a step below the sampled one.
                    let (mut near_lo, mut near_hi) = (f32::INFINITY, f32::INFINITY);
                    for (a, b) in &segments {
                        let length = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
                        let steps = (length * 20.0).ceil().max(1.0) as usize;
                        let sampled = (0..=steps)
                            .map(|s| {
                                let t = s as f32 / steps as f32;
                                let q = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                                ((x + 0.5 - q[0]).powi(2) + (y + 0.5 - q[1]).powi(2)).sqrt()
                            })
                            .fold(f32::INFINITY, f32::min);
                        near_hi = near_hi.min(sampled);
                        near_lo = near_lo.min(sampled - length / steps as f32 / 2.0);
                    }
                    let cover = |d: f32| (half + 0.5 - d).clamp(0.0, 1.0);
                    let got = mask.cover[j * mask.width + i];
                    assert!(
                        got >= cover(near_hi) - 1e-4 && got <= cover(near_lo) + 1e-4,
                        "{width}: ({x}, {y}) {got} outside {} to {}",
                        cover(near_hi),
                        cover(near_lo)
                    );
                    lit += usize::from(got > 0.0);
                }
            }
            assert!(lit > 300, "{lit}");
        }
    }
}
