//! A plain CPU ray marcher: the reference that the compositors' pictures are checked against.
//!
//! It shares no code with them: its own camera rays, its own trilinear sampling and transfer
//! function interpolation, post-classification (the value is interpolated, then classified)
//! at a fine fixed step, the emission-absorption integral front to back with the opacity of
//! each step corrected for its length (`1 - (1 - a)^(step / reference)`), and the headlight
//! shading the splats use (`rgb * (1 - s + s |n . forward|)`, `n` the field's unit gradient).
//! It is slow and simple on purpose.

#![allow(dead_code)]

use glam::DVec3;

/// A pinhole camera: pixel `(i, j)`'s ray leaves `eye` through the pixel's centre.
#[derive(Debug, Clone, Copy)]
pub struct Pinhole {
    /// Eye position, world millimetres.
    pub eye: DVec3,
    /// A point on the view axis.
    pub target: DVec3,
    /// Roughly up on screen (not parallel to the view axis).
    pub up: DVec3,
    /// Vertical field of view in degrees.
    pub fov_y_degrees: f64,
    /// Image size in pixels.
    pub size: (u32, u32),
}

/// A scalar field sampled on an axis-aligned grid, read with trilinear interpolation; outside
/// the box of voxel centres it is `None` (no data, transparent).
#[derive(Debug, Clone)]
pub struct Grid<'a> {
    /// Voxels along x, y, z.
    pub dims: [u32; 3],
    /// Millimetres between voxel centres.
    pub spacing: [f64; 3],
    /// World position of voxel (0, 0, 0).
    pub origin: [f64; 3],
    /// Values, x fastest.
    pub values: &'a [f32],
}

impl Grid<'_> {
    /// The trilinear interpolation of the values at world point `p`.
    pub fn sample(&self, p: DVec3) -> Option<f64> {
        let mut base = [0usize; 3];
        let mut frac = [0.0f64; 3];
        for a in 0..3 {
            let t = (p[a] - self.origin[a]) / self.spacing[a];
            let n = f64::from(self.dims[a]);
            if !(t >= 0.0 && t <= n - 1.0) {
                return None;
            }
            let i = (t.floor() as usize).min(self.dims[a].saturating_sub(2) as usize);
            base[a] = i;
            frac[a] = t - i as f64;
        }
        let [nx, ny, _] = self.dims.map(|n| n as usize);
        let at = |x: usize, y: usize, z: usize| {
            let clamp = |v: usize, a: usize| v.min(self.dims[a] as usize - 1);
            f64::from(self.values[clamp(x, 0) + nx * (clamp(y, 1) + ny * clamp(z, 2))])
        };
        let mut sum = 0.0;
        for corner in 0..8 {
            let mut w = 1.0;
            let mut k = [0usize; 3];
            for a in 0..3 {
                let up = corner >> a & 1 == 1;
                k[a] = base[a] + usize::from(up);
                w *= if up { frac[a] } else { 1.0 - frac[a] };
            }
            if w != 0.0 {
                sum += w * at(k[0], k[1], k[2]);
            }
        }
        Some(sum)
    }
}

/// Straight RGBA of a piecewise-linear transfer function through `points` (sorted by
/// value), the end values held beyond them.
pub fn transfer(points: &[(f32, [f32; 4])], value: f64) -> [f64; 4] {
    let widen = |c: [f32; 4]| c.map(f64::from);
    let Some(first) = points.first() else {
        return [0.0; 4];
    };
    if value <= f64::from(first.0) {
        return widen(first.1);
    }
    for pair in points.windows(2) {
        let (v0, v1) = (f64::from(pair[0].0), f64::from(pair[1].0));
        if value <= v1 {
            let t = if v1 > v0 {
                (value - v0) / (v1 - v0)
            } else {
                1.0
            };
            let (c0, c1) = (widen(pair[0].1), widen(pair[1].1));
            return std::array::from_fn(|i| c0[i] + t * (c1[i] - c0[i]));
        }
    }
    widen(points[points.len() - 1].1)
}

/// What the marcher integrates.
pub struct Volume<'a> {
    /// The scalar at a world point (`None`: no data there).
    pub field: &'a (dyn Fn(DVec3) -> Option<f64> + Sync),
    /// The world box the rays are clipped to.
    pub bounds: (DVec3, DVec3),
    /// Transfer function points (straight RGBA, opacity per `reference_mm`).
    pub transfer: &'a [(f32, [f32; 4])],
    /// Millimetres the transfer function's opacities hold for.
    pub reference_mm: f64,
    /// Headlight shading strength, 0 to 1.
    pub shading: f64,
    /// Distance for the central differences of the gradient, millimetres.
    pub gradient_mm: f64,
}

/// Premultiplied RGBA per pixel, rows top to bottom, marched at `step_mm`.
pub fn march(volume: &Volume<'_>, camera: &Pinhole, step_mm: f64) -> Vec<[f32; 4]> {
    let forward = (camera.target - camera.eye).normalize();
    let right = forward.cross(camera.up).normalize();
    let up = right.cross(forward);
    let (w, h) = camera.size;
    let focal = 0.5 * f64::from(h) / (0.5 * camera.fov_y_degrees.to_radians()).tan();
    march_rays(volume, (w, h), forward, step_mm, |x, y| {
        (
            camera.eye,
            (forward * focal + right * x + up * y).normalize(),
        )
    })
}

/// A camera of parallel rays: pixel `(i, j)`'s ray runs along `target - eye` from the plane
/// through `eye` square to it, at the pixel centre's place on that plane.
#[derive(Debug, Clone, Copy)]
pub struct Parallel {
    /// A point of the plane the rays leave, world millimetres (in front of the volume).
    pub eye: DVec3,
    /// A point on the view axis.
    pub target: DVec3,
    /// Roughly up on screen (not parallel to the view axis).
    pub up: DVec3,
    /// The height the image spans, millimetres.
    pub height_mm: f64,
    /// Image size in pixels.
    pub size: (u32, u32),
}

/// [`march`] with parallel rays.
pub fn march_parallel(volume: &Volume<'_>, camera: &Parallel, step_mm: f64) -> Vec<[f32; 4]> {
    let forward = (camera.target - camera.eye).normalize();
    let right = forward.cross(camera.up).normalize();
    let up = right.cross(forward);
    let mm = camera.height_mm / f64::from(camera.size.1);
    march_rays(volume, camera.size, forward, step_mm, |x, y| {
        (camera.eye + (right * x + up * y) * mm, forward)
    })
}

/// Each pixel's ray as `ray_of` gives it (origin and unit direction) from the pixel centre's
/// offset from the image centre, in pixels (x right, y up), marched front to back.
fn march_rays(
    volume: &Volume<'_>,
    (w, h): (u32, u32),
    forward: DVec3,
    step_mm: f64,
    ray_of: impl Fn(f64, f64) -> (DVec3, DVec3) + Sync,
) -> Vec<[f32; 4]> {
    let ray_of = &ray_of;
    let rows: Vec<Vec<[f32; 4]>> = std::thread::scope(|scope| {
        let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                scope.spawn(move || {
                    (t..h as usize)
                        .step_by(threads)
                        .map(|j| {
                            (0..w)
                                .map(|i| {
                                    let x = f64::from(i) + 0.5 - 0.5 * f64::from(w);
                                    let y = 0.5 * f64::from(h) - (j as f64 + 0.5);
                                    let (origin, d) = ray_of(x, y);
                                    ray(volume, origin, d, forward, step_mm)
                                })
                                .collect::<Vec<_>>()
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        let parts: Vec<Vec<Vec<[f32; 4]>>> =
            handles.into_iter().map(|h| h.join().unwrap()).collect();
        let mut rows = vec![Vec::new(); h as usize];
        for (t, part) in parts.into_iter().enumerate() {
            for (k, row) in part.into_iter().enumerate() {
                rows[t + k * threads] = row;
            }
        }
        rows
    });
    rows.into_iter().flatten().collect()
}

/// The picture of `volume` from `camera` with each pixel formed as a splat's is: `rays` x
/// `rays` rays a pixel, and each pixel the mean of the rays within three standard deviations
/// of its centre, weighted by a Gaussian of `variance` square pixels (the screen low-pass
/// every splat is widened by, `SplatStyle::pixel_variance`). One ray a pixel, or a box filter,
/// aliases edges that the splats' low-pass blurs: on pictures of fine structures, that
/// difference alone is near the fidelity bar.
pub fn march_low_pass(
    volume: &Volume<'_>,
    camera: &Pinhole,
    step_mm: f64,
    rays: usize,
    variance: f64,
) -> Vec<[f32; 4]> {
    let (w, h) = (camera.size.0 as usize, camera.size.1 as usize);
    let fine_camera = Pinhole {
        size: ((rays * w) as u32, (rays * h) as u32),
        ..*camera
    };
    let fine = march(volume, &fine_camera, step_mm);
    let reach = 3.0 * variance.sqrt();
    // A ray's index along an axis to its position in pixels, and the rays within reach of a
    // pixel's centre `c` along that axis.
    let at = |f: usize| (f as f64 + 0.5) / rays as f64;
    let within = |c: f64, n: usize| {
        let lo = ((c - reach) * rays as f64 - 0.5).ceil().max(0.0) as usize;
        let hi = (((c + reach) * rays as f64 - 0.5).floor() as usize).min(rays * n - 1);
        lo..=hi
    };
    (0..w * h)
        .map(|i| {
            let c = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let (mut sum, mut total) = ([0.0f64; 4], 0.0);
            for fy in within(c.1, h) {
                for fx in within(c.0, w) {
                    let d2 = (at(fx) - c.0).powi(2) + (at(fy) - c.1).powi(2);
                    let weight = (-0.5 * d2 / variance).exp();
                    let p = fine[fy * rays * w + fx];
                    for k in 0..4 {
                        sum[k] += weight * f64::from(p[k]);
                    }
                    total += weight;
                }
            }
            sum.map(|v| (v / total) as f32)
        })
        .collect()
}

/// One ray from `origin` along unit `d`, front to back.
fn ray(volume: &Volume<'_>, origin: DVec3, d: DVec3, forward: DVec3, step: f64) -> [f32; 4] {
    // The ray's stretch inside the box (slabs).
    let (lo, hi) = volume.bounds;
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        if d[a].abs() < 1e-12 {
            if origin[a] < lo[a] || origin[a] > hi[a] {
                return [0.0; 4];
            }
            continue;
        }
        let (ta, tb) = ((lo[a] - origin[a]) / d[a], (hi[a] - origin[a]) / d[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    let mut color = [0.0f64; 3];
    let mut alpha = 0.0f64;
    let mut t = t0 + 0.5 * step;
    while t < t1 && alpha < 0.9995 {
        let p = origin + d * t;
        t += step;
        let Some(value) = (volume.field)(p) else {
            continue;
        };
        let [r, g, b, a] = transfer(volume.transfer, value);
        if a <= 0.0 {
            continue;
        }
        let a = 1.0 - (1.0 - a.min(1.0)).powf(step / volume.reference_mm);
        let mut shade = 1.0;
        if volume.shading > 0.0 {
            let e = volume.gradient_mm;
            let diff =
                |axis: DVec3| match ((volume.field)(p + axis * e), (volume.field)(p - axis * e)) {
                    (Some(u), Some(v)) => (u - v) / (2.0 * e),
                    _ => 0.0,
                };
            let grad = DVec3::new(diff(DVec3::X), diff(DVec3::Y), diff(DVec3::Z));
            if let Some(n) = grad.try_normalize() {
                shade = 1.0 - volume.shading + volume.shading * n.dot(forward).abs();
            }
        }
        let weight = (1.0 - alpha) * a;
        color[0] += weight * r * shade;
        color[1] += weight * g * shade;
        color[2] += weight * b * shade;
        alpha += weight;
    }
    [
        color[0] as f32,
        color[1] as f32,
        color[2] as f32,
        alpha as f32,
    ]
}
