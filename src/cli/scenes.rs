//! The commands that look at a scene: `render`, `pick` and `measure`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use glam::DVec3;
use serde_json::{Value, json};

use splatscene::camera::Camera;
use splatscene::order::Ordering;
use splatscene::pick::measure::{MarkerStyle, Measurement, annotate};
use splatscene::pick::{Hit, PickOptions, Picker};
use splatscene::render::{
    FrameOptions, FrameReport, GpuContext, Renderer, ViewSetup, depth_range, depth_to_luma16,
    encode_png, frame_to_rgba8,
};
use splatscene::scene::file::{LoadedScene, load_scene_file};
use splatscene::scene::shoulder::shoulder_scene;
use splatscene::scene::{Projection, Scene, SceneCamera};

use crate::{parse_f64x2, parse_f64x3, parse_opacity, parse_size, parse_u32x2, write_replacing};

/// The scene and the camera, shared by every scene command.
#[derive(clap::Args)]
pub struct ViewArgs {
    /// A TOML scene file; the built-in shoulder scene when absent.
    scene: Option<PathBuf>,
    /// Image size WxH (default: the scene file's, else 800x600).
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Eye position X,Y,Z in world millimetres.
    #[arg(long, value_parser = parse_f64x3, allow_hyphen_values = true)]
    eye: Option<[f64; 3]>,
    /// Look-at point X,Y,Z (default: the scene's camera target).
    #[arg(long, value_parser = parse_f64x3, allow_hyphen_values = true)]
    target: Option<[f64; 3]>,
    /// Turn the camera about its target: YAW,PITCH in degrees.
    #[arg(long, value_parser = parse_f64x2, allow_hyphen_values = true)]
    orbit: Option<[f64; 2]>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    fov: Option<f64>,
    /// Orthographic projection showing this height in world units.
    #[arg(long)]
    orthographic: Option<f64>,
}

/// A loaded scene with the camera and size the arguments ask for.
struct View {
    loaded: LoadedScene,
    camera: SceneCamera,
    size: (u32, u32),
}

impl ViewArgs {
    fn load(&self) -> Result<View> {
        let loaded = match &self.scene {
            Some(path) => load_scene_file(path)?,
            None => LoadedScene {
                scene: shoulder_scene()?,
                size: None,
                background: Some([0.06, 0.07, 0.09]),
                ordering: None,
            },
        };
        let mut camera = loaded.scene.camera.context("the scene has no camera")?;
        if let Some(eye) = self.eye {
            camera.eye = DVec3::from(eye);
        }
        if let Some(target) = self.target {
            camera.target = DVec3::from(target);
        }
        if self.eye.is_some() || self.target.is_some() {
            // Keep the scene's up vector unless the new view runs along it.
            let forward = (camera.target - camera.eye).normalize_or_zero();
            if forward.cross(camera.up.normalize_or_zero()).length() < 1e-6 {
                camera.up = Camera::safe_up(camera.eye, camera.target);
            }
        }
        if let Some([yaw, pitch]) = self.orbit {
            camera = camera.orbit(yaw, pitch);
        }
        if let Some(fov) = self.fov {
            camera.projection = Projection::Perspective { fov_y_degrees: fov };
        }
        if let Some(height) = self.orthographic {
            camera.projection = Projection::Orthographic { height };
        }
        let size = self.size.or(loaded.size).unwrap_or((800, 600));
        Ok(View {
            loaded,
            camera,
            size,
        })
    }
}

/// `splatscene render`.
#[derive(clap::Args)]
pub struct RenderArgs {
    #[command(flatten)]
    view: ViewArgs,
    /// Output PNG.
    #[arg(long)]
    out: PathBuf,
    /// Splat ordering: btf, wbtf, pbtf, ip-pbtf, exact, bucketed, pyramid, rows...
    #[arg(long)]
    ordering: Option<Ordering>,
    /// Also write the mesh depth as a 16-bit PNG (near black, far white).
    #[arg(long)]
    depth: Option<PathBuf>,
    /// Transparent background (the PNG's alpha is the coverage).
    #[arg(long)]
    transparent: bool,
}

/// `splatscene pick`.
#[derive(clap::Args)]
pub struct PickArgs {
    #[command(flatten)]
    view: ViewArgs,
    /// The pixel X,Y (0,0 is the top-left pixel).
    #[arg(long, value_parser = parse_u32x2)]
    pixel: [u32; 2],
    /// Opacity a voxel must exceed to be hit (0 to 1).
    #[arg(long, default_value_t = 0.1, value_parser = parse_opacity)]
    opacity: f32,
    /// Pick meshes only.
    #[arg(long)]
    meshes_only: bool,
}

/// `splatscene measure`.
#[derive(clap::Args)]
pub struct MeasureArgs {
    #[command(flatten)]
    view: ViewArgs,
    /// Pixels X,Y to pick, in order: two for a distance, three for the angle at the second,
    /// four for the angle between the lines through the first two and the last two.
    #[arg(long = "pixel", value_parser = parse_u32x2, required = true)]
    pixels: Vec<[u32; 2]>,
    /// World points X,Y,Z to measure instead of picking pixels.
    #[arg(long = "point", value_parser = parse_f64x3, allow_hyphen_values = true, conflicts_with = "pixels")]
    points: Vec<[f64; 3]>,
    /// Opacity a voxel must exceed to be hit (0 to 1).
    #[arg(long, default_value_t = 0.1, value_parser = parse_opacity)]
    opacity: f32,
    /// Also render the scene with the measurement drawn in, to this PNG.
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run_render(args: RenderArgs) -> Result<()> {
    if args.depth.as_ref().is_some_and(|d| same_file(d, &args.out)) {
        bail!(
            "--depth {}: the same file as --out; the depth image would replace the colour one",
            args.out.display()
        );
    }
    let View {
        loaded,
        camera,
        size,
    } = args.view.load()?;
    let options = FrameOptions {
        ordering: args.ordering.or(loaded.ordering),
        background: if args.transparent {
            None
        } else {
            loaded.background
        },
        measure: true,
        preview: false,
    };
    let ctx = GpuContext::headless()?;
    let shot = Renderer::new().screenshot(&ctx, &loaded.scene, &camera, size, &options)?;
    write_replacing(&args.out, &encode_png(&frame_to_rgba8(&shot.frame))?)?;
    if let Some(path) = &args.depth {
        let bounds = loaded.scene.bounds().unwrap_or((DVec3::ZERO, DVec3::ONE));
        let range = depth_range(&shot.view, bounds);
        write_replacing(
            path,
            &encode_png(&depth_to_luma16(&shot.depth, &shot.view, range))?,
        )?;
    }
    eprintln!(
        "{}x{} on {}: {}",
        size.0,
        size.1,
        ctx.describe(),
        describe(&shot.report)
    );
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

fn describe(r: &FrameReport) -> String {
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    format!(
        "{} meshes ({} triangles), {} splats; classify {:.0} ms, order {:.1} ms, upload {:.1} ms, mesh pass {:.1} ms, splat pass {:.1} ms, readback {:.1} ms",
        r.meshes,
        r.triangles,
        r.splats,
        ms(r.timings.classify),
        ms(r.timings.order),
        ms(r.timings.upload),
        ms(r.timings.mesh_pass),
        ms(r.timings.splat_pass),
        ms(r.timings.readback)
    )
}

/// A hit as JSON, with the name of the node it landed on.
fn hit_json(scene: &Scene, hit: &Hit) -> Result<Value> {
    let mut value = serde_json::to_value(hit)?;
    let node = match hit {
        Hit::Mesh(h) => h.node,
        Hit::Volume(h) => h.node,
    };
    if let (Some(object), Ok(n)) = (value.as_object_mut(), scene.node(node)) {
        object.insert("node_name".into(), json!(n.name));
    }
    Ok(value)
}

fn check_pixel(pixel: [u32; 2], size: (u32, u32)) -> Result<()> {
    if pixel[0] >= size.0 || pixel[1] >= size.1 {
        bail!(
            "pixel {},{} is outside the {}x{} image",
            pixel[0],
            pixel[1],
            size.0,
            size.1
        );
    }
    Ok(())
}

pub fn run_pick(args: PickArgs) -> Result<()> {
    let View {
        loaded,
        camera,
        size,
    } = args.view.load()?;
    check_pixel(args.pixel, size)?;
    let scene = &loaded.scene;
    let view = ViewSetup::new(&camera, size, scene.bounds())?;
    let options = PickOptions {
        opacity_threshold: args.opacity,
        volumes: !args.meshes_only,
    };
    let hit = Picker::new(scene).pick_pixel(scene, &view, args.pixel[0], args.pixel[1], &options);
    let hit = hit.map(|h| hit_json(scene, &h)).transpose()?;
    let out = json!({ "pixel": args.pixel, "size": [size.0, size.1], "hit": hit });
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}

pub fn run_measure(args: MeasureArgs) -> Result<()> {
    let View {
        mut loaded,
        camera,
        size,
    } = args.view.load()?;
    let scene = &loaded.scene;
    let view = ViewSetup::new(&camera, size, scene.bounds())?;
    let options = PickOptions {
        opacity_threshold: args.opacity,
        volumes: true,
    };
    let mut points = Vec::new();
    let mut hits = Vec::new();
    if args.points.is_empty() {
        let picker = Picker::new(scene);
        for &pixel in &args.pixels {
            check_pixel(pixel, size)?;
            let hit = picker
                .pick_pixel(scene, &view, pixel[0], pixel[1], &options)
                .with_context(|| {
                    format!("nothing to measure at pixel {},{}", pixel[0], pixel[1])
                })?;
            points.push(hit.point());
            hits.push(hit_json(scene, &hit)?);
        }
    } else {
        points.extend(args.points.iter().map(|p| DVec3::from(*p)));
    }
    let measurement = match points.as_slice() {
        [a, b] => Measurement::distance(*a, *b),
        [a, v, b] => {
            Measurement::angle(*a, *v, *b).context("an angle needs points apart from its vertex")?
        }
        [a0, a1, b0, b1] => Measurement::line_angle(*a0, *a1, *b0, *b1)
            .context("a line needs two distinct points")?,
        _ => bail!("give two, three or four points (got {})", points.len()),
    };
    let mut out = serde_json::to_value(&measurement)?;
    if let Some(object) = out.as_object_mut() {
        object.insert("hits".into(), Value::Array(hits));
    }
    println!("{}", serde_json::to_string_pretty(&out)?);
    if let Some(path) = &args.out {
        let radius = loaded
            .scene
            .bounds()
            .map_or(1.0, |(lo, hi)| (hi - lo).length() * 0.006);
        let style = MarkerStyle {
            point_radius: radius,
            line_radius: radius * 0.3,
            ..MarkerStyle::default()
        };
        annotate(&mut loaded.scene, &measurement, &style)?;
        let options = FrameOptions {
            background: loaded.background,
            ..FrameOptions::default()
        };
        let ctx = GpuContext::headless()?;
        let shot = Renderer::new().screenshot(&ctx, &loaded.scene, &camera, size, &options)?;
        write_replacing(path, &encode_png(&frame_to_rgba8(&shot.frame))?)?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// Whether two output paths name one file, also when reached two ways (`./`, `..`, links).
fn same_file(a: &Path, b: &Path) -> bool {
    // The file itself where it exists, else its folder's real path and its name.
    let resolve = |p: &Path| {
        std::fs::canonicalize(p).ok().or_else(|| {
            let dir = match p.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            Some(std::fs::canonicalize(dir).ok()?.join(p.file_name()?))
        })
    };
    a == b || matches!((resolve(a), resolve(b)), (Some(x), Some(y)) if x == y)
}

/// `splatscene view`.
#[derive(clap::Args)]
pub struct ViewerArgs {
    #[command(flatten)]
    view: ViewArgs,
    /// Folder for screenshots taken with the S key.
    #[arg(long, default_value = ".")]
    screenshots: PathBuf,
    /// Draw every frame in full, also while the camera moves (by default, where a full frame
    /// takes over 50 ms, a drag or a zoom draws the volumes at half resolution, about an eighth
    /// of the splats).
    #[arg(long)]
    no_preview: bool,
}

pub fn run_viewer(args: ViewerArgs) -> Result<()> {
    let View {
        mut loaded,
        camera,
        size,
    } = args.view.load()?;
    loaded.scene.camera = Some(camera);
    let options = splatscene::viewer::ViewerOptions {
        size,
        screenshot_dir: args.screenshots,
        background: loaded.background.unwrap_or([0.06, 0.07, 0.09]),
        preview_while_moving: !args.no_preview,
    };
    eprintln!(
        "keys: 1 BTF, 2 PBTF, 3 IP-PBTF, 4 exact, 5 bucketed, 6 pyramid, 7 rows, T transfer function, S screenshot, C clip plane ([ and ] move it), R reset, Q quit; drag to orbit (right: pan), wheel to zoom, click to pick"
    );
    splatscene::viewer::run(loaded.scene, options)?;
    Ok(())
}
