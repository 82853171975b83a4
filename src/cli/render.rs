//! `splatscene render`: figures of a scene, with annotations and calibrated depth, and what
//! every command that writes images shares (output names, depth files, refusing to write
//! over an input).

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use serde_json::Value;

use splatscene::annotate::{Annotations, Label, colour_bar};
use splatscene::figure::{Measured, context_for, depth_distances, fill_caption, measured};
use splatscene::order::Ordering;
use splatscene::pick::contact::Classes;
use splatscene::pick::paint::{paint, value_colour};
use splatscene::render::{
    Compositor, DepthImage, DepthMode, FrameOptions, FrameReport, GpuContext, LevelOfDetail,
    Renderer, encode_png,
};
use splatscene::scene::file::SceneFile;
use splatscene::scene::{Scene, SceneCamera};
use splatscene::slice::draw::colour8;

use super::args::parse_opacity;
use super::files::write_replacing;
use super::input::{View, ViewArgs};
use super::slice::{Layout, SliceArgs, compose_quad, run_slices, sidecar, window, write_figure};
use splatscene::slice::PlaneKind;
use splatscene::slice::draw::quad_panes;

/// `splatscene render`.
#[derive(clap::Args)]
pub struct RenderArgs {
    #[command(flatten)]
    view: ViewArgs,
    /// Output PNG; with several --view, a name holding {view} (shoulder-{view}.png), which
    /// each view's name replaces.
    #[arg(long)]
    out: PathBuf,
    /// Splat ordering: btf, wbtf, pbtf, ip-pbtf, exact, bucketed, pyramid, rows...
    #[arg(long)]
    ordering: Option<Ordering>,
    /// Also write the depth as a 16-bit PNG (near black, far white, 65535 where nothing was
    /// hit), its near and far distances in millimetres in the PNG's text chunks and in a JSON
    /// file beside it (the PNG's name with .json).
    #[arg(long)]
    depth: Option<PathBuf>,
    /// What the depth image holds: `mesh` (meshes only; the default when the scene has
    /// meshes) or `surface` (also each volume's first surface, where the opacity accumulated
    /// along the pixel's ray reaches --surface-opacity; the default for a scene of volumes
    /// only).
    #[arg(long, value_parser = ["mesh", "surface"])]
    depth_mode: Option<String>,
    /// The accumulated opacity that makes a volume's surface in the depth image (0 to 1).
    #[arg(long, default_value_t = 0.3, value_parser = parse_opacity)]
    surface_opacity: f32,
    /// Who composites the splats: gpu (the splat pass), cpu (the tile compositor, meshes
    /// still on the GPU), gpu-tiles (the tile compositor as GPU compute passes), or auto: the
    /// CPU where the GPU adapter is itself a CPU (lavapipe), and where there is no adapter at
    /// all for a scene without meshes, else the splat pass.
    #[arg(long, default_value = "auto")]
    compositor: Compositor,
    /// Level of detail: `on` draws each volume from the level of its pyramid (2x2x2 voxels a
    /// splat a level; an axis along the view halved once more) whose voxels are about a pixel
    /// apart on the screen where it is drawn largest, or, where its voxels are more than 1.5
    /// pixels apart, from its field on a grid refined until they are not, each 16^3-voxel
    /// brick at the detail its own distance calls for (with every compositor); `volume` draws
    /// each volume at one detail, the one its nearest brick calls for; `off` from its own
    /// grid, every voxel a splat; `auto` as `on`, but a level of the pyramid is made only
    /// where the drawing it saves in these few pictures outweighs its making (else a finer
    /// level made or the own grid is drawn there), while grids coarser than the pixels are
    /// still refined
    #[arg(long, default_value = "auto")]
    lod: LevelOfDetail,
    /// Transparent background (the PNG's alpha is the coverage).
    #[arg(long)]
    transparent: bool,
    /// Paint a mesh (the one named, else the first) with the volume's value under its surface,
    /// a colour bar beside: the contact map. The colours (viridis) span --window, else the
    /// volume's window, else for CT -100 to 1000 HU (soft tissue dark, cancellous bone blue to
    /// green, cortical bone yellow; the CT classes' edges 200 and 700 HU marked), else the
    /// values' range; grey where the surface lies outside the volume.
    #[arg(long, num_args = 0..=1, default_missing_value = "", value_name = "MESH")]
    contact: Option<String>,
    #[command(flatten)]
    annotate: AnnotateArgs,
    #[command(flatten)]
    slices: SliceArgs,
}

/// Annotations drawn onto the image for report figures.
#[derive(clap::Args)]
pub struct AnnotateArgs {
    /// Annotate the figure: an orientation marker, patient-direction letters at the edges, a
    /// scale bar (at the target's depth in perspective views) and measurement values; or only
    /// the parts listed (marker, letters, scale, measurements).
    #[arg(long, num_args = 0..=1, default_missing_value = "all", value_name = "PARTS")]
    annotate: Option<String>,
    /// A caption along the top of the image (implies --annotate for the caption alone when
    /// --annotate is not given); {view}, {size} and {ordering} are replaced (and {slice} in
    /// slice figures).
    #[arg(long)]
    caption: Option<String>,
}

impl AnnotateArgs {
    /// The annotations asked for, or `None` for a plain image.
    pub(crate) fn parts(&self) -> Result<Option<Annotations>> {
        let mut parts = match &self.annotate {
            Some(list) => {
                Annotations::parse_parts(list).map_err(|e| anyhow::anyhow!("--annotate: {e}"))?
            }
            None if self.caption.is_some() => {
                Annotations::parse_parts("none").map_err(anyhow::Error::msg)?
            }
            None => return Ok(None),
        };
        parts.caption = self.caption.clone();
        if parts
            .caption
            .as_deref()
            .is_some_and(|c| c.trim().is_empty())
        {
            bail!("--caption is empty");
        }
        Ok(Some(parts))
    }
}

/// The image of a screenshot, annotated when asked, with what was drawn said on stderr.
pub(crate) fn figure(
    shot: &splatscene::render::Screenshot,
    scene: &Scene,
    camera: &SceneCamera,
    parts: Option<&Annotations>,
    labels: &[Label],
) -> Result<image::RgbaImage> {
    let (image, drawn) = figure_image(shot, scene, camera, parts, labels)?;
    if let Some(drawn) = drawn {
        let mut said = Vec::new();
        if drawn.edge_letters.iter().any(|l| !l.is_empty()) {
            let [l, r, t, b] = &drawn.edge_letters;
            said.push(format!("left {l}, right {r}, top {t}, bottom {b}"));
        }
        if let Some(scale) = drawn.scale {
            said.push(format!("scale bar {scale}"));
        }
        if drawn.marker {
            said.push("orientation marker".into());
        }
        if !said.is_empty() {
            eprintln!("annotated: {}", said.join("; "));
        }
    }
    Ok(image)
}

/// The image of a screenshot, annotated when asked (with the patient frame of `scene`), and
/// what the annotation drew; what was left out for want of room said on stderr.
pub(crate) fn figure_image(
    shot: &splatscene::render::Screenshot,
    scene: &Scene,
    camera: &SceneCamera,
    parts: Option<&Annotations>,
    labels: &[Label],
) -> Result<(image::RgbaImage, Option<splatscene::annotate::Drawn>)> {
    let (image, drawn) = splatscene::figure::figure_image(shot, scene, camera, parts, labels)?;
    say_dropped(drawn.as_ref(), parts);
    Ok((image, drawn))
}

/// A note on stderr for each label, and the marker, left out of a figure for want of room.
pub(crate) fn say_dropped(
    drawn: Option<&splatscene::annotate::Drawn>,
    parts: Option<&Annotations>,
) {
    let Some(drawn) = drawn else {
        return;
    };
    for text in &drawn.dropped {
        eprintln!("note: the label {text:?} was left out: no free place near its point");
    }
    if parts.is_some_and(|p| p.orientation_marker) && !drawn.marker {
        eprintln!("note: the orientation marker was left out: no free corner for it");
    }
}

pub fn run_render(args: RenderArgs) -> Result<()> {
    let View {
        loaded,
        cameras,
        size,
        file,
    } = args.view.load()?;
    let layout = args.slices.layout(&file)?;
    if let Layout::Slices(wanted) = &layout {
        if args.depth.is_some()
            || args.depth_mode.is_some()
            || args.transparent
            || args.contact.is_some()
        {
            bail!(
                "--depth, --depth-mode, --transparent and --contact are for the 3D view; slices outline the meshes instead"
            );
        }
        if args.view.size_given() {
            bail!(
                "--size has no effect on slices: their pixels are --slice-mm-per-pixel millimetres covering the section (with --layout quad, --size is the figure's)"
            );
        }
        if args.ordering.is_some() {
            bail!("--ordering has no effect on slices: they draw no splats");
        }
        let [(_, camera)] = cameras.as_slice() else {
            bail!("slices go through one camera's target: give one --view with --slice");
        };
        let parts = args.annotate.parts()?;
        return run_slices(
            &loaded.scene,
            &file,
            camera.target,
            wanted,
            &args.out,
            parts.as_ref(),
        );
    }
    let quad = match layout {
        Layout::Quad(at) => {
            if args.depth.is_some() {
                bail!(
                    "--depth is for the 3D view alone; --layout quad writes a calibration of its slices instead"
                );
            }
            if size.0 < 64 || size.1 < 64 {
                bail!("--layout quad needs at least 64x64 pixels for its four panes");
            }
            Some(at)
        }
        _ => None,
    };
    // The quad's 3D pane takes a quarter of the figure.
    let render_size = if quad.is_some() {
        (size.0 / 2, size.1 / 2)
    } else {
        size
    };
    let outputs = output_names(&args.out, &cameras)?;
    let depths = match &args.depth {
        Some(depth) => output_names(depth, &cameras)?
            .into_iter()
            .map(Some)
            .collect(),
        None => vec![None; cameras.len()],
    };
    check_distinct(&outputs, &depths)?;
    let quad_sidecars = match quad {
        Some(_) => outputs
            .iter()
            .map(|o| sidecar(o))
            .collect::<Result<Vec<_>>>()?,
        None => Vec::new(),
    };
    refuse_inputs(
        outputs
            .iter()
            .chain(depths.iter().flatten())
            .cloned()
            .chain(depths.iter().flatten().map(|d| sidecar_of(d)))
            .chain(quad_sidecars.iter().cloned()),
    )?;
    let options = FrameOptions {
        ordering: args.ordering.or(loaded.ordering),
        background: if args.transparent {
            None
        } else {
            loaded.background
        },
        measure: true,
        preview: 0,
        volume_divisor: 1,
    };
    let parts = args.annotate.parts()?;
    let has_meshes = loaded.scene.meshes().next().is_some();
    let depth_mode = match args.depth_mode.as_deref() {
        Some("surface") => DepthMode::Surface,
        Some(_) => DepthMode::Mesh,
        None => splatscene::figure::default_depth_mode(&loaded.scene),
    };
    if args.depth.is_some() && depth_mode == DepthMode::Mesh && !has_meshes {
        bail!(
            "--depth-mode mesh: the scene has no meshes, so the depth image would be empty; use --depth-mode surface for the volumes' surface"
        );
    }
    // The scene's measurements are drawn in, their values written beside them unless the
    // annotations asked for leave them out.
    let mut drawn = loaded.scene.clone();
    let contact_map = match &args.contact {
        Some(name) => Some(paint_contact(&mut drawn, &file, name)?),
        None => None,
    };
    let Measured {
        scene: drawn,
        labels,
        parts: label_parts,
    } = measured(&drawn, parts.as_ref())?;
    let ctx = context_for(args.compositor, &drawn)?;
    // One renderer for every view: the volumes are classified once.
    let mut renderer = Renderer::with_compositor(args.compositor);
    renderer.set_lod(args.lod);
    let device = ctx
        .as_ref()
        .map_or("the CPU alone".into(), GpuContext::describe);
    for ((name, camera), (out, depth)) in cameras.iter().zip(outputs.iter().zip(&depths)) {
        let shot = match &ctx {
            Some(ctx) => renderer.screenshot(ctx, &drawn, camera, render_size, &options)?,
            None => renderer.screenshot_without_gpu(&drawn, camera, render_size, &options)?,
        };
        // The caption's placeholders filled for this view.
        let view_name = name.as_deref().unwrap_or("scene");
        let parts_here = label_parts.clone().map(|mut p| {
            p.caption = p
                .caption
                .map(|c| fill_caption(&c, view_name, size, options.ordering));
            p
        });
        let mut image = figure(&shot, &loaded.scene, camera, parts_here.as_ref(), &labels)?;
        if let Some(map) = &contact_map {
            map.legend(&mut image)?;
        }
        match quad {
            Some(at) => {
                let point = quad_point(&loaded.scene, camera.target, at);
                let window = window(&loaded.scene, &file);
                let slices = quad_panes(
                    &loaded.scene,
                    point,
                    render_size,
                    window,
                    parts.as_ref(),
                    PlaneKind::Coronal,
                    None,
                )?;
                let (image, calibration) =
                    compose_quad(size, &image, &slices, window, point, &loaded.scene);
                write_figure(out, &image, &calibration)?;
            }
            None => write_replacing(out, &encode_png(&image)?)?,
        }
        if let Some(path) = depth {
            write_depth(path, &shot, &loaded.scene, depth_mode, args.surface_opacity)?;
        }
        let view = name
            .as_deref()
            .map_or(String::new(), |n| format!(" {n} view"));
        eprintln!(
            "{}x{}{view} on {device}: {}",
            size.0,
            size.1,
            describe(&shot.report)
        );
        eprintln!("wrote {}", out.display());
    }
    Ok(())
}

/// A contact map painted into a scene: what its colour bar says.
struct ContactMap {
    range: [f64; 2],
    ticks: Vec<(f64, String)>,
    title: String,
}

impl ContactMap {
    /// Draws the colour bar onto a figure.
    fn legend(&self, image: &mut image::RgbaImage) -> Result<()> {
        let range = self.range;
        colour_bar(
            image,
            |v| colour8(value_colour(v, range)),
            range,
            &self.ticks,
            &self.title,
        )?;
        Ok(())
    }
}

/// The values a contact map's colours span: the volume's window where it was given one, else
/// for CT -100 to 1000 HU (soft tissue to cortical bone), else the values' range.
fn contact_range(scene: &Scene, file: &SceneFile) -> [f64; 2] {
    let given = file
        .volumes
        .first()
        .is_some_and(|v| v.level_width.is_some() || v.window.is_some());
    match scene.volumes().next() {
        Some((_, v, _)) => {
            splatscene::pick::paint::contact_range(&v.volume, given.then(|| window(scene, file)))
        }
        None => [0.0, 1.0],
    }
}

/// Paints the mesh named `name` (the first where empty) in `scene` with the volume's value.
fn paint_contact(scene: &mut Scene, file: &SceneFile, name: &str) -> Result<ContactMap> {
    let range = contact_range(scene, file);
    let painted = paint(scene, (!name.is_empty()).then_some(name), range)
        .map_err(|e| anyhow::anyhow!("--contact: {e}"))?;
    painted.apply(scene)?;
    let hounsfield = scene
        .volumes()
        .next()
        .is_some_and(|(_, v, _)| Classes::for_volume(&v.volume) == Classes::ct());
    let fmt = |v: f64| format!("{v}");
    let mut ticks = vec![(range[0], fmt(range[0])), (range[1], fmt(range[1]))];
    if hounsfield {
        ticks.extend(
            [200.0, 700.0]
                .into_iter()
                .filter(|v| *v > range[0] && *v < range[1])
                .map(|v| (v, fmt(v))),
        );
    }
    let triangles: usize = painted
        .meshes
        .iter()
        .map(|(_, m)| m.mesh.triangle_count())
        .sum();
    eprintln!(
        "contact map: {triangles} triangles of at most {:.2} mm painted, {} to {}{}",
        painted.step_mm,
        range[0],
        range[1],
        if hounsfield { " HU" } else { "" }
    );
    Ok(ContactMap {
        range,
        ticks,
        title: if hounsfield {
            "HU at the surface"
        } else {
            "value at the surface"
        }
        .into(),
    })
}

/// The quad layout's point: `target` moved onto the axial, coronal and sagittal planes given
/// (`at`: their coordinates along S, A and R).
fn quad_point(scene: &Scene, target: glam::DVec3, at: [Option<f64>; 3]) -> glam::DVec3 {
    let patient = scene.patient_frame();
    let normals = [glam::DVec3::Z, glam::DVec3::Y, glam::DVec3::X].map(|d| patient.world(d));
    normals.iter().zip(at).fold(target, |p, (n, mm)| match mm {
        Some(mm) => p + *n * (mm - p.dot(*n)),
        None => p,
    })
}

/// Writes the depth image of `shot` and its calibration beside it.
fn write_depth(
    path: &Path,
    shot: &splatscene::render::Screenshot,
    scene: &Scene,
    mode: DepthMode,
    surface_opacity: f32,
) -> Result<()> {
    let (png, calibration) = depth_files(shot, scene, mode, surface_opacity)?;
    if calibration["near_mm"].is_null() {
        eprintln!(
            "warning: {}: nothing was hit, every pixel is 65535 (no depth)",
            path.display()
        );
    }
    write_replacing(path, &png)?;
    let sidecar = sidecar_of(path);
    write_replacing(
        &sidecar,
        serde_json::to_string_pretty(&calibration)?.as_bytes(),
    )?;
    eprintln!(
        "wrote {} ({} depth, {} to {} mm) and {}",
        path.display(),
        mode.name(),
        calibration["near_mm"],
        calibration["far_mm"],
        sidecar.display()
    );
    Ok(())
}

/// The depth image of `shot` as a 16-bit PNG, and its calibration (the JSON written beside it).
pub(crate) fn depth_files(
    shot: &splatscene::render::Screenshot,
    scene: &Scene,
    mode: DepthMode,
    surface_opacity: f32,
) -> Result<(Vec<u8>, Value)> {
    let view = &shot.view;
    let distances = depth_distances(shot, scene, mode, surface_opacity);
    let image = DepthImage {
        size: view.size,
        distances,
        mode,
        surface_opacity: (mode == DepthMode::Surface).then_some(surface_opacity),
    };
    Ok(image.encode_png(view)?)
}

/// The depth calibration's file beside the depth image `depth`: its name with `.json`.
pub(crate) fn sidecar_of(depth: &Path) -> PathBuf {
    depth.with_extension("json")
}

/// Refuses every output of a run that is one of the run's inputs, before anything is drawn
/// (the inputs have all been read by then; see [`splatscene::output::check_not_input`]).
pub(crate) fn refuse_inputs(outputs: impl IntoIterator<Item = PathBuf>) -> Result<()> {
    for path in outputs {
        splatscene::output::check_not_input(&path)?;
    }
    Ok(())
}

/// Refuses outputs that name one file, so that no image replaces another: colour images,
/// depth images and their calibration files.
fn check_distinct(outputs: &[PathBuf], depths: &[Option<PathBuf>]) -> Result<()> {
    for (d, out) in depths
        .iter()
        .flatten()
        .flat_map(|d| outputs.iter().map(move |o| (d, o)))
    {
        if same_file(d, out) {
            bail!(
                "--depth {}: the same file as --out {}; the depth image would replace the colour one",
                d.display(),
                out.display()
            );
        }
    }
    for d in depths.iter().flatten() {
        let sidecar = sidecar_of(d);
        if same_file(d, &sidecar) {
            bail!(
                "--depth {}: the depth calibration is written beside the image with .json, which is this name; end the depth image's name with .png",
                d.display()
            );
        }
        let taken = outputs
            .iter()
            .chain(depths.iter().flatten())
            .find(|o| same_file(o, &sidecar));
        if let Some(o) = taken {
            bail!(
                "--depth {}: its calibration {} is the name of another output ({}); choose names that differ in more than the extension",
                d.display(),
                sidecar.display(),
                o.display()
            );
        }
    }
    let sidecars: Vec<PathBuf> = depths.iter().flatten().map(|d| sidecar_of(d)).collect();
    for list in [
        outputs.iter().collect::<Vec<_>>(),
        depths.iter().flatten().collect(),
        sidecars.iter().collect(),
    ] {
        for (i, a) in list.iter().enumerate() {
            if let Some(b) = list[i + 1..].iter().find(|b| same_file(a, b)) {
                bail!(
                    "{} and {}: two views would write one file (is a view named twice?)",
                    a.display(),
                    b.display()
                );
            }
        }
    }
    Ok(())
}

/// The output file of each camera: `pattern` with `{view}` replaced by the view's name. Several
/// views need `{view}` in the name, so that no view's image replaces another's.
fn output_names(pattern: &Path, cameras: &[(Option<String>, SceneCamera)]) -> Result<Vec<PathBuf>> {
    let text = pattern.to_string_lossy();
    let has_view = text.contains("{view}");
    if cameras.len() > 1 && !has_view {
        bail!(
            "{}: several views need {{view}} in the output name (for example shoulder-{{view}}.png)",
            pattern.display()
        );
    }
    Ok(cameras
        .iter()
        .map(|(name, _)| match (has_view, name) {
            (true, Some(name)) => PathBuf::from(text.replace("{view}", name)),
            (true, None) => PathBuf::from(text.replace("{view}", "custom")),
            (false, _) => pattern.to_path_buf(),
        })
        .collect())
}

pub(crate) fn describe(r: &FrameReport) -> String {
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let splats = match r.tiles {
        Some(t) => format!(
            "splats on the CPU ({} drew pixels; {} projected, {} left out unprojected behind opaque pixels, {} off the image, {} splat-tile pairs composited, {} skipped behind opaque pixels, {} tiles opaque), project {:.1} ms, bin {:.1} ms, tiles {:.1} ms",
            t.drew,
            t.projected,
            t.culled,
            t.off_image,
            t.composited,
            t.skipped_opaque,
            t.tiles_opaque,
            ms(t.project),
            ms(t.bin),
            ms(t.tiles)
        ),
        None => format!("splat pass {:.1} ms", ms(r.timings.splat_pass)),
    };
    format!(
        "{} meshes ({} triangles), {} splats{}; classify {:.0} ms ({} classified){}{}{}, order {:.1} ms, upload {:.1} ms, mesh pass {:.1} ms, {splats}, readback {:.1} ms{}",
        r.meshes,
        r.triangles,
        r.splats,
        {
            // Halvings along each axis where they differ ("level of detail 0/1/0").
            let level = match r.levels {
                [x, y, z] if x != y || y != z => format!("{x}/{y}/{z} along x/y/z"),
                _ => r.level.to_string(),
            };
            let by_brick = if r.bricks_by_level > 0 {
                ", by brick"
            } else {
                ""
            };
            let short = if r.levels_short_of_memory {
                "; a coarser level not made, the memory left too little"
            } else {
                ""
            };
            match (r.level, r.refined) {
                (0, None) if r.levels_short_of_memory => {
                    " (own grid: the memory left holds no level of detail)".into()
                }
                (0, None) if r.levels_not_made => {
                    " (own grid: no level of detail pays for one picture; --lod on makes them)"
                        .into()
                }
                (0, None) => String::new(),
                (0, Some([x, y, z])) => format!(" (the grid refined {x}x{y}x{z}{by_brick})"),
                (_, None) => format!(" (level of detail {level}{by_brick}{short})"),
                (_, Some([x, y, z])) => format!(
                    " (level of detail {level}; a grid refined {x}x{y}x{z}{by_brick}{short})"
                ),
            }
        },
        ms(r.timings.classify),
        r.classified,
        if r.timings.levels.is_zero() {
            String::new()
        } else {
            format!(", levels {:.0} ms", ms(r.timings.levels))
        },
        if r.timings.texels.is_zero() {
            String::new()
        } else {
            format!(", texels {:.0} ms", ms(r.timings.texels))
        },
        if r.timings.seen.is_zero() {
            String::new()
        } else {
            format!(", bricks shown found in {:.0} ms", ms(r.timings.seen))
        },
        ms(r.timings.order),
        ms(r.timings.upload),
        ms(r.timings.mesh_pass),
        ms(r.timings.readback),
        if r.read_back == 0 {
            String::new()
        } else {
            format!(" ({} pixels of mesh layers)", r.read_back)
        }
    )
}

/// Whether two output paths name one file, also when reached two ways (`./`, `..`, links,
/// and links whose target does not exist yet, which writing would create).
fn same_file(a: &Path, b: &Path) -> bool {
    // Links followed as writing follows them; then the file itself where it exists, else its
    // folder's real path and its name.
    let resolve = |p: &Path| {
        let p = &splatscene::output::follow_links(p).ok()?;
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
