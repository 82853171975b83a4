//! Where text goes on a picture: every mark takes a rectangle, and a label is placed in the
//! first free spot around its point, inside the picture, or left out.

/// A rectangle `[x0, y0, x1, y1]` in pixels, `x0 <= x1` and `y0 <= y1`.
pub type Rect = [f32; 4];

/// The rectangles taken on a picture of `width` by `height` pixels.
#[derive(Debug, Clone)]
pub struct Layout {
    width: f32,
    height: f32,
    taken: Vec<Rect>,
}

/// Whether two rectangles share any area.
pub fn overlaps(a: Rect, b: Rect) -> bool {
    a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]
}

/// The rectangle grown by `by` pixels on every side.
pub fn grown(r: Rect, by: f32) -> Rect {
    [r[0] - by, r[1] - by, r[2] + by, r[3] + by]
}

/// Where a label was put: its rectangle, and whether it sits away from its point (and so
/// wants a leader line to it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placed {
    /// The label's rectangle.
    pub rect: Rect,
    /// Whether it was moved off the first ring around its point.
    pub leader: bool,
}

impl Layout {
    /// Nothing taken yet on a picture of this size.
    pub fn new(width: f32, height: f32) -> Self {
        Self {
            width,
            height,
            taken: Vec::new(),
        }
    }

    /// Marks `r` as taken.
    pub fn take(&mut self, r: Rect) {
        self.taken.push(r);
    }

    /// Whether `r` lies inside the picture and clear of everything taken.
    pub fn fits(&self, r: Rect) -> bool {
        r[0] >= 0.0
            && r[1] >= 0.0
            && r[2] <= self.width
            && r[3] <= self.height
            && !self.taken.iter().any(|t| overlaps(*t, r))
    }

    /// The first free place for a label of `size` (width, height) near the point `at`: above
    /// right of it, then above left, below right, below left, right, left, above and below,
    /// each a gap of `gap` pixels away, then the same on rings further out (those want a
    /// leader line). `None` when no place is free within four rings.
    pub fn place_label(&self, at: [f32; 2], size: (f32, f32), gap: f32) -> Option<Placed> {
        let (w, h) = size;
        let [x, y] = at;
        for ring in 0..4 {
            let d = gap * (1.0 + 2.5 * ring as f32);
            let corners = [
                (x + d, y - d - h),
                (x - d - w, y - d - h),
                (x + d, y + d),
                (x - d - w, y + d),
                (x + d, y - h / 2.0),
                (x - d - w, y - h / 2.0),
                (x - w / 2.0, y - d - h),
                (x - w / 2.0, y + d),
            ];
            for (left, top) in corners {
                let rect = [left, top, left + w, top + h];
                if self.fits(rect) {
                    return Some(Placed {
                        rect,
                        leader: ring > 0,
                    });
                }
            }
        }
        None
    }
}

/// The point of `r` nearest to `p`: where a leader line from `p` meets the label.
pub fn nearest_on(r: Rect, p: [f32; 2]) -> [f32; 2] {
    [p[0].clamp(r[0], r[2]), p[1].clamp(r[1], r[3])]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_go_to_the_first_free_place_inside_the_picture() {
        let mut layout = Layout::new(200.0, 100.0);
        let first = layout
            .place_label([100.0, 50.0], (40.0, 10.0), 4.0)
            .unwrap();
        assert_eq!(first.rect, [104.0, 36.0, 144.0, 46.0]);
        assert!(!first.leader);
        layout.take(first.rect);
        // The same point again: above left, not over the first.
        let second = layout
            .place_label([100.0, 50.0], (40.0, 10.0), 4.0)
            .unwrap();
        assert_eq!(second.rect, [56.0, 36.0, 96.0, 46.0]);
        layout.take(second.rect);
        // A point at the right edge: never outside the picture.
        let edge = layout
            .place_label([199.0, 50.0], (40.0, 10.0), 4.0)
            .unwrap();
        assert!(edge.rect[2] <= 200.0 && !overlaps(edge.rect, first.rect));
        // A picture full up: none.
        let mut full = Layout::new(50.0, 20.0);
        full.take([0.0, 0.0, 50.0, 20.0]);
        assert_eq!(full.place_label([25.0, 10.0], (10.0, 5.0), 2.0), None);
        // Far from free space nearby: a leader line.
        let mut crowded = Layout::new(400.0, 400.0);
        crowded.take([180.0, 180.0, 220.0, 220.0]);
        let far = crowded
            .place_label([200.0, 200.0], (20.0, 10.0), 4.0)
            .unwrap();
        assert!(far.leader && !overlaps(far.rect, [180.0, 180.0, 220.0, 220.0]));
        assert_eq!(
            nearest_on([10.0, 10.0, 20.0, 15.0], [0.0, 30.0]),
            [10.0, 15.0]
        );
    }
}
