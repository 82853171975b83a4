//! Where a slice's pixels lie: the section of the volume (or of its crop box) by the plane,
//! covered by square pixels, and the calibration that maps pixels to world millimetres.

use glam::{DVec2, DVec3};

use super::{Plane, SliceError};
use crate::geometry::VolumeGeometry;
use crate::scene::{Projection, Scene, SceneCamera, placed_geometry};

/// The section of the volume by a plane, as a rectangle in the plane's image coordinates
/// (millimetres along `right` and `down` from the plane's point).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    /// Least and greatest millimetres along `right`.
    pub u: [f64; 2],
    /// Least and greatest millimetres along `down`.
    pub v: [f64; 2],
}

impl Extent {
    /// The section of the scene's first volume (cut by the crop box where the scene has one)
    /// by `plane`: the voxel centres' box, as the volume's bounds are.
    ///
    /// # Errors
    ///
    /// A scene without volumes, a volume that cannot be placed, or a plane that misses the
    /// volume (the error gives the volume's extent along the plane's normal).
    pub fn of(scene: &Scene, plane: &Plane) -> Result<Self, SliceError> {
        let geometry = first_geometry(scene)?;
        let dims = geometry.dims();
        let big = {
            let reach = (plane.point - geometry.centre_world()).length()
                + scene
                    .bounds()
                    .map_or(1.0, |(lo, hi)| (hi - lo).length().max(1.0));
            4.0 * reach
        };
        let mut polygon = vec![
            DVec2::new(-big, -big),
            DVec2::new(big, -big),
            DVec2::new(big, big),
            DVec2::new(-big, big),
        ];
        // Half-planes c + g . (u, v) >= 0: index coordinates within the grid's range...
        let at = |u: f64, v: f64| plane.point + plane.right * u + plane.down * v;
        let index = |u: f64, v: f64| geometry.world_to_index(at(u, v));
        let i0 = index(0.0, 0.0);
        let gu = index(1.0, 0.0) - i0;
        let gv = index(0.0, 1.0) - i0;
        for axis in 0..3 {
            let (lo, hi) = index_range(dims[axis]);
            let g = DVec2::new(gu[axis], gv[axis]);
            polygon = clip(&polygon, i0[axis] - lo, g);
            polygon = clip(&polygon, hi - i0[axis], -g);
        }
        // ...and world coordinates within the crop box.
        if let Some((lo, hi)) = scene.clipping.crop {
            for axis in 0..3 {
                let g = DVec2::new(plane.right[axis], plane.down[axis]);
                polygon = clip(&polygon, plane.point[axis] - lo[axis], g);
                polygon = clip(&polygon, hi[axis] - plane.point[axis], -g);
            }
        }
        if polygon.len() < 3 {
            return Err(misses(scene, plane, &geometry));
        }
        let (mut u, mut v) = (
            [f64::INFINITY, f64::NEG_INFINITY],
            [f64::INFINITY, f64::NEG_INFINITY],
        );
        for p in &polygon {
            u = [u[0].min(p.x), u[1].max(p.x)];
            v = [v[0].min(p.y), v[1].max(p.y)];
        }
        Ok(Self { u, v })
    }

    /// The millimetres a pixel that fits the extent into `width` x `height` pixels.
    pub fn fit_mm(&self, width: u32, height: u32) -> f64 {
        let mm = ((self.u[1] - self.u[0]) / f64::from(width.max(1)))
            .max((self.v[1] - self.v[0]) / f64::from(height.max(1)));
        if mm > 0.0 { mm } else { 1.0 }
    }
}

/// The index range of a grid axis of `n` voxels: the voxel centres, or half a voxel either
/// side of a single one.
pub(crate) fn index_range(n: u32) -> (f64, f64) {
    if n <= 1 {
        (-0.5, 0.5)
    } else {
        (0.0, f64::from(n - 1))
    }
}

/// The placed grid of the scene's first volume.
pub(crate) fn first_geometry(scene: &Scene) -> Result<VolumeGeometry, SliceError> {
    let (_, node, world) = scene.volumes().next().ok_or(SliceError::NoVolume)?;
    Ok(placed_geometry(&node.volume, world)?)
}

/// The error for a plane that misses the volume: the volume's extent along the normal.
fn misses(scene: &Scene, plane: &Plane, geometry: &VolumeGeometry) -> SliceError {
    let dims = geometry.dims();
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for corner in 0..8 {
        let index = DVec3::from(std::array::from_fn(|a| {
            let (l, h) = index_range(dims[a]);
            if corner >> a & 1 == 0 { l } else { h }
        }));
        let along = geometry.index_to_world_point(index).dot(plane.normal);
        lo = lo.min(along);
        hi = hi.max(along);
    }
    SliceError::Misses {
        plane: plane.spec.to_string(),
        at_mm: plane.offset(),
        extent: [lo, hi],
        cropped: scene.clipping.crop.is_some(),
    }
}

/// The part of a convex polygon where `c + g . (p - origin) >= 0` (Sutherland and Hodgman's
/// clipping against one half-plane; the polygon's points are relative to the plane's point,
/// where the half-plane's value is `c`).
fn clip(polygon: &[DVec2], c: f64, g: DVec2) -> Vec<DVec2> {
    let value = |p: DVec2| c + g.dot(p);
    let mut out = Vec::with_capacity(polygon.len() + 1);
    for (i, &p) in polygon.iter().enumerate() {
        let q = polygon[(i + 1) % polygon.len()];
        let (vp, vq) = (value(p), value(q));
        if vp >= 0.0 {
            out.push(p);
        }
        if (vp >= 0.0) != (vq >= 0.0) {
            out.push(p + (q - p) * (vp / (vp - vq)));
        }
    }
    out
}

/// A slice's pixels: `width` x `height` square pixels of `mm_per_pixel`, pixel (x, y) centred
/// on `origin + x * right * mm_per_pixel + y * down * mm_per_pixel`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SliceFrame {
    /// The plane.
    pub plane: Plane,
    /// Pixels across.
    pub width: u32,
    /// Pixels down.
    pub height: u32,
    /// The side of a pixel in millimetres.
    pub mm_per_pixel: f64,
    /// The world point at the centre of pixel (0, 0).
    pub origin: DVec3,
}

impl SliceFrame {
    /// Pixels of `mm_per_pixel` covering `extent`, centred on it: `size` pixels where given,
    /// else as many as the extent takes (at least one each way).
    ///
    /// # Errors
    ///
    /// A pixel size that is not a positive number, or an image larger than the renderer's
    /// budget allows.
    pub fn new(
        plane: Plane,
        extent: &Extent,
        mm_per_pixel: f64,
        size: Option<(u32, u32)>,
    ) -> Result<Self, SliceError> {
        if !(mm_per_pixel.is_finite() && mm_per_pixel > 0.0) {
            return Err(SliceError::BadPixelSize(mm_per_pixel));
        }
        let count = |span: f64| (span / mm_per_pixel).ceil().max(1.0);
        let (width, height) = match size {
            Some(size) => size,
            None => {
                let (w, h) = (
                    count(extent.u[1] - extent.u[0]),
                    count(extent.v[1] - extent.v[0]),
                );
                let too_large = SliceError::TooLarge {
                    plane: plane.spec.to_string(),
                    width: w,
                    height: h,
                    mm_per_pixel,
                };
                if w > f64::from(u32::MAX) || h > f64::from(u32::MAX) {
                    return Err(too_large);
                }
                (w as u32, h as u32)
            }
        };
        crate::budget::check_image(width.into(), height.into()).map_err(|_| {
            SliceError::TooLarge {
                plane: plane.spec.to_string(),
                width: f64::from(width),
                height: f64::from(height),
                mm_per_pixel,
            }
        })?;
        let centre_u = 0.5 * (extent.u[0] + extent.u[1]);
        let centre_v = 0.5 * (extent.v[0] + extent.v[1]);
        let u0 = centre_u - 0.5 * f64::from(width) * mm_per_pixel + 0.5 * mm_per_pixel;
        let v0 = centre_v - 0.5 * f64::from(height) * mm_per_pixel + 0.5 * mm_per_pixel;
        Ok(Self {
            plane,
            width,
            height,
            mm_per_pixel,
            origin: plane.point + plane.right * u0 + plane.down * v0,
        })
    }

    /// The world step of one pixel to the right.
    pub fn pixel_right(&self) -> DVec3 {
        self.plane.right * self.mm_per_pixel
    }

    /// The world step of one pixel down.
    pub fn pixel_down(&self) -> DVec3 {
        self.plane.down * self.mm_per_pixel
    }

    /// The world point at pixel coordinates `(x, y)` (integers at pixel centres).
    pub fn world(&self, x: f64, y: f64) -> DVec3 {
        self.origin + self.pixel_right() * x + self.pixel_down() * y
    }

    /// The pixel coordinates (integers at pixel centres) of `p` projected onto the plane.
    pub fn pixel(&self, p: DVec3) -> [f64; 2] {
        let d = p - self.origin;
        [
            d.dot(self.plane.right) / self.mm_per_pixel,
            d.dot(self.plane.down) / self.mm_per_pixel,
        ]
    }

    /// An orthographic camera that sees the slice as its image shows it (the plane's centre at
    /// the image's centre, its height the image's), for drawing annotations onto it.
    pub fn camera(&self) -> SceneCamera {
        let centre = self.world(
            0.5 * f64::from(self.width) - 0.5,
            0.5 * f64::from(self.height) - 0.5,
        );
        let forward = self.plane.right.cross(self.plane.down);
        let height = f64::from(self.height) * self.mm_per_pixel;
        SceneCamera {
            eye: centre - forward * (height + 100.0),
            target: centre,
            up: -self.plane.down,
            projection: Projection::Orthographic { height },
            near: None,
        }
    }
}
