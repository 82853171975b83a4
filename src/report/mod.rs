//! The orderings report: every ordering's run time against its image error, along a camera
//! path (an orbit and a fly-in that ends inside the volume) and at fixed views of each case.

mod plot;

pub use plot::{PlotError, plot_error_against_time, register_font};

use std::time::Instant;

use glam::DVec3;

use crate::camera::Camera;
use crate::classify::{Classified, view_step_mm};
use crate::order::{
    CaseKind, OrderError, OrderOptions, Orderer, Ordering, ViewCase, VolumeGeometry,
};
use crate::render::{FrameOptions, GpuContext, RenderError, Renderer};
use crate::scene::{Projection, Scene, SceneCamera};
use crate::splat::reference::{
    CompositeError, FragmentStats, Frame, ImageDifference, SplatStyle, SplatVolume,
    check_frame_size, compare, composite,
};

/// Settings of a report run.
#[derive(Debug, Clone, PartialEq)]
pub struct ReportSettings {
    /// Views on the orbit.
    pub orbit_views: usize,
    /// Views on the fly-in.
    pub fly_in_views: usize,
    /// Image width and height in pixels.
    pub size: (u32, u32),
    /// Vertical field of view in degrees.
    pub fov_y_degrees: f64,
    /// Splat shape.
    pub style: SplatStyle,
    /// Near plane, in units of the largest voxel spacing: splats nearer to the eye are left
    /// out, as a renderer's near clip would (a splat half a voxel from the eye covers the whole
    /// image).
    pub near_voxels: f64,
    /// Orderings to compare (the exact order is always computed as the reference).
    pub orderings: Vec<Entry>,
}

/// One ordering as the report runs it: the ordering and, for the bucketed order, the bucket
/// width (world units; `None` is the default width), so that a report can set several widths
/// of the bucketed order side by side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Entry {
    /// The ordering.
    pub ordering: Ordering,
    /// Bucket width of [`Ordering::Bucketed`]; ignored by the other orderings.
    pub bucket_width: Option<f64>,
}

impl Entry {
    /// The bucketed order with buckets `width` wide (world units).
    pub fn bucketed(width: f64) -> Self {
        Self {
            ordering: Ordering::Bucketed,
            bucket_width: Some(width),
        }
    }

    /// The order options of this entry, leaving out voxels behind the eye as every view of the
    /// report does.
    fn options(&self) -> OrderOptions {
        OrderOptions {
            cull_behind_eye: true,
            bucket_width: self.bucket_width,
        }
    }
}

impl From<Ordering> for Entry {
    fn from(ordering: Ordering) -> Self {
        Self {
            ordering,
            bucket_width: None,
        }
    }
}

/// The ordering's name, followed by the bucket width where one is set (`bucketed 0.7`).
impl std::fmt::Display for Entry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.ordering, self.bucket_width) {
            (Ordering::Bucketed, Some(width)) => write!(f, "{} {width}", self.ordering),
            (ordering, _) => write!(f, "{ordering}"),
        }
    }
}

impl Default for ReportSettings {
    fn default() -> Self {
        Self {
            orbit_views: 16,
            fly_in_views: 8,
            size: (192, 192),
            fov_y_degrees: 50.0,
            style: SplatStyle::default(),
            near_voxels: 2.0,
            orderings: Ordering::ALL.map(Entry::from).to_vec(),
        }
    }
}

/// Why a report could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// An ordering failed.
    #[error(transparent)]
    Order(#[from] OrderError),
    /// Compositing failed.
    #[error(transparent)]
    Composite(#[from] CompositeError),
    /// Rendering on the GPU failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// The GPU compositor draws each ordering as the renderer does, with the default bucket
    /// width.
    #[error(
        "the GPU compositor draws the bucketed order at its default width only; leave out the bucket width ({0})"
    )]
    BucketWidthOnGpu(f64),
}

/// Where the report composites its frames.
pub enum Compositor<'a> {
    /// The CPU reference compositor ([`crate::splat::reference`]): no GPU needed, and it also counts
    /// adjacent inversions.
    Cpu,
    /// The renderer on a GPU adapter: `scene` holds the volume (placed at the identity, with
    /// its splat settings) and is drawn once per ordering with a transparent background, so
    /// that the error is measured on GPU images. Inversions are not counted.
    Gpu {
        /// The adapter and device.
        ctx: &'a GpuContext,
        /// The renderer, kept across views.
        renderer: &'a mut Renderer,
        /// The scene to draw.
        scene: &'a Scene,
    },
}

/// One view of the path: where the eye was, which case it made, and per ordering the order
/// time, the image difference against the exact order and the fragment statistics.
#[derive(Debug, Clone)]
pub struct ViewResult {
    /// Name of the view ("orbit 3", "fly-in 7", "face-on close").
    pub name: String,
    /// The view case.
    pub kind: CaseKind,
    /// Per ordering, in the order of [`ReportSettings::orderings`].
    pub per_ordering: Vec<OrderingResult>,
}

/// One ordering at one view.
#[derive(Debug, Clone, Copy)]
pub struct OrderingResult {
    /// The ordering.
    pub entry: Entry,
    /// Order time in seconds (on the CPU, with either compositor).
    pub order_seconds: f64,
    /// The image against the exact order's.
    pub difference: ImageDifference,
    /// Adjacent inversions, counted by the CPU compositor only.
    pub fragments: Option<FragmentStats>,
    /// The GPU's splat pass for this order in seconds (the GPU compositor only): orders that
    /// scatter consecutive splats across the volume draw slower.
    pub draw_seconds: Option<f64>,
}

/// A named camera placement.
#[derive(Debug, Clone, Copy)]
pub struct View {
    /// Display name.
    pub name: &'static str,
    /// Index of the view on its path (0 for fixed views).
    pub index: usize,
    /// Eye in world space.
    pub eye: DVec3,
    /// Target in world space.
    pub target: DVec3,
}

/// The camera path: an orbit around the volume at twice its bounding radius, rising and
/// falling in elevation, then a fly-in from outside to a point inside the volume.
pub fn camera_path(
    geometry: &VolumeGeometry,
    orbit_views: usize,
    fly_in_views: usize,
) -> Vec<View> {
    let centre = geometry.centre_world();
    let radius = bounding_radius(geometry);
    let mut views = Vec::with_capacity(orbit_views + fly_in_views);
    for i in 0..orbit_views {
        let t = i as f64 / orbit_views.max(1) as f64;
        let azimuth = std::f64::consts::TAU * t + 0.3;
        let elevation = 0.5 * (std::f64::consts::TAU * t).sin();
        let dir = DVec3::new(
            azimuth.cos() * elevation.cos(),
            azimuth.sin() * elevation.cos(),
            elevation.sin(),
        );
        views.push(View {
            name: "orbit",
            index: i,
            eye: centre + dir * (2.0 * radius),
            target: centre,
        });
    }
    let start = centre + DVec3::new(0.8, -1.9, 0.6).normalize() * (2.5 * radius);
    let end = centre + DVec3::new(0.13, -0.21, 0.17) * radius;
    for i in 0..fly_in_views {
        let t = (i as f64 + 1.0) / fly_in_views.max(1) as f64;
        let eye = start.lerp(end, t);
        views.push(View {
            name: "fly-in",
            index: i,
            eye,
            target: eye + (centre - start).normalize(),
        });
    }
    views
}

/// Fixed views of the four cases, close enough that splats cover several pixels: first each
/// case looking at the centre of the grid (oblique to every grid axis), then face-on, edge-on
/// and volume-on looking straight along the grid's z axis, as a standard axial view of a
/// scan does. Every ordering that nests the grid axes (all but the distance orders) draws a
/// whole slab of its slowest axis before the next, which is wrong for neighbouring voxels
/// wherever a viewing ray makes more than 45 degrees with that axis (cubic voxels); the two
/// sets show how much of each ordering's error comes from that rather than from the split
/// planes.
pub fn case_views(geometry: &VolumeGeometry) -> Vec<View> {
    let dims = geometry.dims().map(f64::from);
    let index = |x: f64, y: f64, z: f64| DVec3::new(x * dims[0], y * dims[1], z * dims[2]);
    let centre = geometry.centre_world();
    let toward_centre = |name, at: DVec3| View {
        name,
        index: 0,
        eye: geometry.index_to_world_point(at),
        target: centre,
    };
    let along_z = |name, at: DVec3| View {
        name,
        index: 0,
        eye: geometry.index_to_world_point(at),
        target: geometry.index_to_world_point(at + DVec3::Z),
    };
    vec![
        toward_centre("face-on close", index(0.43, 0.56, -0.35)),
        toward_centre("edge-on", index(0.47, -0.45, -0.4)),
        toward_centre("volume-on", index(0.41, 0.37, 0.45)),
        toward_centre("corner-on", index(-0.6, -0.5, -0.45)),
        along_z("face-on along z", index(0.43, 0.56, -0.35)),
        along_z("edge-on along z", index(0.47, 1.05, -0.45)),
        along_z("volume-on along z", index(0.41, 0.37, 0.25)),
    ]
}

/// Radius of the sphere around the grid's centre that holds every voxel centre.
pub fn bounding_radius(geometry: &VolumeGeometry) -> f64 {
    let centre = geometry.centre_world();
    let dims = geometry.dims();
    (0..8)
        .map(|c| {
            let k = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
                if c >> a & 1 == 0 {
                    0.0
                } else {
                    f64::from(dims[a] - 1)
                }
            }));
            geometry.index_to_world_point(k).distance(centre)
        })
        .fold(0.0, f64::max)
}

/// Orders and composites every ordering at each view on the CPU; `progress` is called after
/// each view.
pub fn measure_views(
    geometry: &VolumeGeometry,
    classified: &Classified,
    views: &[View],
    settings: &ReportSettings,
    progress: impl FnMut(),
) -> Result<Vec<ViewResult>, ReportError> {
    measure_views_with(
        geometry,
        classified,
        views,
        settings,
        &mut Compositor::Cpu,
        progress,
    )
}

/// Orders every ordering at each view (timed on the CPU) and composites it with
/// `compositor`; `progress` is called after each view.
pub fn measure_views_with(
    geometry: &VolumeGeometry,
    classified: &Classified,
    views: &[View],
    settings: &ReportSettings,
    compositor: &mut Compositor<'_>,
    mut progress: impl FnMut(),
) -> Result<Vec<ViewResult>, ReportError> {
    check_frame_size(settings.size.0, settings.size.1)?;
    if let Compositor::Gpu { .. } = compositor
        && let Some(width) = settings.orderings.iter().find_map(|e| e.bucket_width)
    {
        return Err(ReportError::BucketWidthOnGpu(width));
    }
    let near = settings.near_voxels * geometry.spacing().iter().copied().fold(0.0, f64::max);
    let mut orderer = Orderer::new();
    let mut list = Vec::new();
    let mut results = Vec::with_capacity(views.len());
    for view in views {
        let case = ViewCase::new(geometry, view.eye, view.target)?;
        let camera = Camera {
            up: Camera::safe_up(view.eye, view.target),
            fov_y_degrees: settings.fov_y_degrees,
            near,
            ..Camera::looking_at(view.eye, view.target, settings.size.0, settings.size.1)
        };
        let scene_camera = SceneCamera {
            eye: view.eye,
            target: view.target,
            up: camera.up,
            projection: Projection::Perspective {
                fov_y_degrees: settings.fov_y_degrees,
            },
            near: Some(near),
        };
        // The splats' opacities in this view (they follow the index step along the view).
        let step =
            view_step_mm(geometry.index_to_world().matrix3, view.target - view.eye).unwrap_or(0.0);
        let colors = classified.premultiplied(step as f32);
        let volume = SplatVolume {
            geometry,
            grid: &classified.grid,
            colors: &colors,
        };
        // The frame of the order in `list` (CPU), or of `ordering` as the renderer draws it
        // (with its splat pass timed).
        let mut draw = |ordering: Ordering, list: &[u32]| -> Result<Drawn, ReportError> {
            match compositor {
                Compositor::Cpu => {
                    let (frame, stats) = composite(&camera, &volume, list, &settings.style)?;
                    Ok((frame, Some(stats), None))
                }
                Compositor::Gpu {
                    ctx,
                    renderer,
                    scene,
                } => {
                    let options = FrameOptions {
                        ordering: Some(ordering),
                        background: None,
                        measure: true,
                        preview: 0,
                        volume_divisor: 1,
                    };
                    let shot =
                        renderer.screenshot(ctx, scene, &scene_camera, settings.size, &options)?;
                    let draw = shot.report.timings.splat_pass.as_secs_f64();
                    Ok((shot.frame, None, Some(draw)))
                }
            }
        };
        orderer.order(
            &classified.grid,
            &case,
            Ordering::Exact,
            &Entry::from(Ordering::Exact).options(),
            &mut list,
        )?;
        let (reference, ..) = draw(Ordering::Exact, &list)?;
        let mut per_ordering = Vec::with_capacity(settings.orderings.len());
        for &entry in &settings.orderings {
            let options = entry.options();
            let start = Instant::now();
            orderer.order(&classified.grid, &case, entry.ordering, &options, &mut list)?;
            let seconds = start.elapsed().as_secs_f64();
            let (frame, fragments, draw_seconds) = draw(entry.ordering, &list)?;
            per_ordering.push(OrderingResult {
                entry,
                order_seconds: seconds,
                difference: compare(&frame, &reference)?,
                fragments,
                draw_seconds,
            });
        }
        results.push(ViewResult {
            name: if view.index == 0 && view.name != "orbit" && view.name != "fly-in" {
                view.name.to_owned()
            } else {
                format!("{} {}", view.name, view.index)
            },
            kind: case.kind,
            per_ordering,
        });
        progress();
    }
    Ok(results)
}

/// A composited frame, its fragment statistics (CPU) and its splat pass time (GPU).
type Drawn = (Frame, Option<FragmentStats>, Option<f64>);

/// Per-ordering summary over a set of views.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Summary {
    /// The ordering.
    pub ordering: Entry,
    /// Order time in seconds: median, minimum, maximum over the views.
    pub time: [f64; 3],
    /// Mean image RMSE against the exact order.
    pub rmse: f64,
    /// Largest channel difference over all views.
    pub max_abs: f64,
    /// Mean share of pixels off by more than 4/255.
    pub bad_pixel_share: f64,
    /// Share of consecutive fragment pairs drawn nearer-before-farther, over all views
    /// (counted by the CPU compositor only).
    pub inversion_share: Option<f64>,
    /// The GPU's splat pass in seconds, median over the views (the GPU compositor only).
    pub draw_time: Option<f64>,
}

/// Summarises each ordering over `results`.
pub fn summarise(results: &[ViewResult]) -> Vec<Summary> {
    let Some(first) = results.first() else {
        return Vec::new();
    };
    let n = results.len() as f64;
    (0..first.per_ordering.len())
        .map(|i| {
            let ordering = first.per_ordering[i].entry;
            let median = |mut v: Vec<f64>| {
                v.sort_by(f64::total_cmp);
                [v[v.len() / 2], v[0], v[v.len() - 1]]
            };
            let time = median(
                results
                    .iter()
                    .map(|r| r.per_ordering[i].order_seconds)
                    .collect(),
            );
            let draws: Option<Vec<f64>> = results
                .iter()
                .map(|r| r.per_ordering[i].draw_seconds)
                .collect();
            let (mut rmse, mut max_abs, mut bad) = (0.0, 0.0f64, 0.0);
            let mut counts = Some(FragmentStats::default());
            for r in results {
                let OrderingResult {
                    difference: d,
                    fragments: s,
                    ..
                } = r.per_ordering[i];
                rmse += d.rmse / n;
                max_abs = max_abs.max(d.max_abs);
                bad += d.bad_pixel_share / n;
                counts = counts.zip(s).map(|(sum, s)| FragmentStats {
                    fragments: sum.fragments + s.fragments,
                    pairs: sum.pairs + s.pairs,
                    inversions: sum.inversions + s.inversions,
                });
            }
            Summary {
                ordering,
                time,
                rmse,
                max_abs,
                bad_pixel_share: bad,
                inversion_share: counts.map(|c| c.inversion_share()),
                draw_time: draws.map(|d| median(d)[0]),
            }
        })
        .collect()
}

/// The summary as a Markdown table, with a column for the GPU's splat pass where the frames
/// were drawn on a GPU.
pub fn summary_table(summaries: &[Summary]) -> String {
    let gpu = summaries.iter().any(|m| m.draw_time.is_some());
    let mut s = String::from(
        "| ordering | order time ms (median, min, max) | image RMSE | largest difference | bad pixels | adjacent inversions |",
    );
    s += if gpu {
        " GPU splat pass ms (median) |\n|---|---|---|---|---|---|---|\n"
    } else {
        "\n|---|---|---|---|---|---|\n"
    };
    for m in summaries {
        s += &format!(
            "| {} | {:.2} ({:.2}, {:.2}) | {:.4} | {:.3} | {:.2}% | {} |",
            m.ordering,
            m.time[0] * 1e3,
            m.time[1] * 1e3,
            m.time[2] * 1e3,
            m.rmse,
            m.max_abs,
            100.0 * m.bad_pixel_share,
            m.inversion_share
                .map_or("n/a".to_owned(), |x| format!("{:.3}%", 100.0 * x))
        );
        if gpu {
            s += &m
                .draw_time
                .map_or(" n/a |".to_owned(), |t| format!(" {:.2} |", t * 1e3));
        }
        s += "\n";
    }
    s
}

/// Image RMSE per view (rows) and ordering (columns), as a Markdown table, with the share of
/// bad pixels in brackets.
pub fn per_view_table(results: &[ViewResult]) -> String {
    let Some(first) = results.first() else {
        return String::new();
    };
    let mut s = String::from("| view | case |");
    for o in &first.per_ordering {
        s += &format!(" {} |", o.entry);
    }
    s += "\n|---|---|";
    s += &"---|".repeat(first.per_ordering.len());
    s += "\n";
    for r in results {
        s += &format!("| {} | {} |", r.name, r.kind.name());
        for o in &r.per_ordering {
            let d = o.difference;
            s += &format!(" {:.4} ({:.1}%) |", d.rmse, 100.0 * d.bad_pixel_share);
        }
        s += "\n";
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn case_views_make_the_case_they_name() {
        let geometry = VolumeGeometry::axis_aligned([112, 80, 112], [0.85, 0.85, 1.0], [5.0; 3])
            .expect("geometry");
        for view in case_views(&geometry) {
            let case = ViewCase::new(&geometry, view.eye, view.target).expect("view");
            assert!(
                view.name.starts_with(case.kind.name()),
                "{} is {}",
                view.name,
                case.kind.name()
            );
            if view.name.ends_with("along z") {
                let dir = geometry.world_dir_to_index(view.target - view.eye);
                assert!(dir.x == 0.0 && dir.y == 0.0 && dir.z > 0.0, "{}", view.name);
            }
        }
    }
}
