//! `splatscene render --slice` and `--layout quad`: slice figures of a scene, calibrated like
//! depth images (a JSON beside each figure and the PNG's text chunks), and the four-pane
//! figure of the 3D view with the three orthogonal slices through one point.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use glam::DVec3;
use image::RgbaImage;
use serde_json::{Value, json};

use splatscene::annotate::Annotations;
use splatscene::render::encode_png_with_text;
use splatscene::scene::Scene;
use splatscene::scene::file::SceneFile;
use splatscene::slice::draw::{Pane, figure};
use splatscene::slice::{Pixels, Plane, PlaneKind, Slice, SliceSpec, default_window};

use super::files::write_replacing;
use super::render::refuse_inputs;

/// Slices and layouts, for `render`.
#[derive(clap::Args)]
pub struct SliceArgs {
    /// Draw slices instead of the 3D view, comma-separated: the CT reformatted on each plane
    /// (trilinear), grey by --window (else the volume's window, else a bone window for CT),
    /// every mesh's cross-section outlined in its colour, the measurements on the plane drawn.
    /// Planes: axial, coronal, sagittal (through the camera's target, or @MM: the world
    /// coordinate along the plane's normal, as axial@-62.5), implant-long and implant-cross
    /// (through the mesh's pivot, along or across its long axis; @MM from the pivot along the
    /// normal). Several need {slice} in --out. A JSON beside each figure (its name with .json)
    /// and the PNG's text chunks calibrate its pixels in RAS millimetres. `none` draws the 3D
    /// view of a scene file that lists slices.
    #[arg(long, value_delimiter = ',', value_name = "PLANES")]
    slice: Vec<String>,
    /// The mesh the implant planes follow (default: the first).
    #[arg(long, value_name = "NAME")]
    slice_mesh: Option<String>,
    /// Square slice pixels of this many millimetres (default: the volume's finest spacing).
    #[arg(long, value_name = "MM", value_parser = parse_mm)]
    slice_mm_per_pixel: Option<f64>,
    /// `quad`: one figure of four panes, the 3D view (top right) and the axial (top left),
    /// sagittal (bottom left) and coronal (bottom right) slices through one point (the
    /// camera's target; --slice axial@Z,coronal@Y,sagittal@X moves it), lines where the
    /// planes meet; 3D Slicer's four-up layout and colours.
    #[arg(long, default_value = "single", value_parser = ["single", "quad"])]
    layout: String,
}

fn parse_mm(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{v} is not a positive number of millimetres"))
    }
}

/// One slice to draw: its plane, the mesh an implant plane follows, its pixel size.
#[derive(Debug, Clone)]
pub struct Wanted {
    /// The plane.
    pub spec: SliceSpec,
    /// The mesh an implant plane follows.
    pub mesh: Option<String>,
    /// Millimetres a pixel.
    pub mm_per_pixel: Option<f64>,
}

/// What `render` draws.
pub enum Layout {
    /// The 3D views.
    Views,
    /// These slices, a figure each.
    Slices(Vec<Wanted>),
    /// The four-pane figure through this point's coordinates given (S, A, R).
    Quad([Option<f64>; 3]),
}

impl SliceArgs {
    /// What to draw: the command line's slices, else the scene file's, else the views.
    pub fn layout(&self, file: &SceneFile) -> Result<Layout> {
        let none = self.slice.iter().any(|s| s.trim() == "none");
        if none && self.slice.len() > 1 {
            bail!("--slice none draws no slices, so it stands alone");
        }
        let given: Vec<SliceSpec> = if none {
            Vec::new()
        } else {
            self.slice
                .iter()
                .map(|s| s.parse().map_err(|e| anyhow::anyhow!("--slice: {e}")))
                .collect::<Result<_>>()?
        };
        if self.layout == "quad" {
            if self.slice_mesh.is_some() || self.slice_mm_per_pixel.is_some() {
                bail!(
                    "--slice-mesh and --slice-mm-per-pixel have no effect with --layout quad, whose panes show the axial, coronal and sagittal planes fitted to them"
                );
            }
            let mut at = [None; 3];
            for spec in &given {
                let axis = match spec.kind {
                    PlaneKind::Axial => 0,
                    PlaneKind::Coronal => 1,
                    PlaneKind::Sagittal => 2,
                    _ => bail!(
                        "--layout quad shows the axial, coronal and sagittal planes; {spec} is none of them"
                    ),
                };
                let Some(mm) = spec.at_mm else {
                    bail!(
                        "--slice {spec} with --layout quad: give where the plane lies ({spec}@MM), or leave it out to go through the camera's target"
                    );
                };
                if at[axis].replace(mm).is_some() {
                    bail!("--slice names the {} plane twice", spec.kind.name());
                }
            }
            return Ok(Layout::Quad(at));
        }
        let wanted: Vec<Wanted> = if !self.slice.is_empty() {
            given
                .into_iter()
                .map(|spec| Wanted {
                    spec,
                    mesh: self.slice_mesh.clone(),
                    mm_per_pixel: self.slice_mm_per_pixel,
                })
                .collect()
        } else {
            file.slices
                .iter()
                .map(|s| Wanted {
                    spec: s.plane,
                    mesh: s.mesh.clone().or_else(|| self.slice_mesh.clone()),
                    mm_per_pixel: self.slice_mm_per_pixel.or(s.mm_per_pixel),
                })
                .collect()
        };
        if wanted.is_empty() {
            if self.slice_mesh.is_some() || self.slice_mm_per_pixel.is_some() {
                bail!("--slice-mesh and --slice-mm-per-pixel need slices to draw (--slice)");
            }
            return Ok(Layout::Views);
        }
        if self.slice_mesh.is_some() && !wanted.iter().any(|w| w.spec.kind.follows_implant()) {
            bail!(
                "--slice-mesh has no effect: only the implant-long and implant-cross planes follow a mesh"
            );
        }
        Ok(Layout::Slices(wanted))
    }
}

/// The grey window of the scene's slices: the window the first volume was given (on the
/// command line or in the scene file), else [`default_window`].
pub fn window(scene: &Scene, file: &SceneFile) -> [f32; 2] {
    let given = file.volumes.first().and_then(|v| {
        v.level_width
            .map(|[level, width]| [level - 0.5 * width, level + 0.5 * width])
            .or(v.window)
    });
    match (given, scene.volumes().next()) {
        (Some(w), _) => w,
        (None, Some((_, node, _))) => default_window(&node.volume),
        (None, None) => [0.0, 1.0],
    }
}

/// The output file of each slice: `pattern` with `{slice}` replaced by the slice's name.
/// Several slices need `{slice}` in the name.
pub fn slice_outputs(pattern: &Path, wanted: &[Wanted]) -> Result<Vec<PathBuf>> {
    let text = pattern.to_string_lossy();
    if text.contains("{view}") {
        bail!(
            "{}: slices take {{slice}} in the output name, not {{view}}",
            pattern.display()
        );
    }
    let has = text.contains("{slice}");
    if wanted.len() > 1 && !has {
        bail!(
            "{}: several slices need {{slice}} in the output name (for example stem-{{slice}}.png)",
            pattern.display()
        );
    }
    let outputs: Vec<PathBuf> = wanted
        .iter()
        .map(|w| PathBuf::from(text.replace("{slice}", &w.spec.to_string())))
        .collect();
    for (i, a) in outputs.iter().enumerate() {
        if outputs[i + 1..].contains(a) {
            bail!(
                "{}: two slices would write one file (is a plane named twice?)",
                a.display()
            );
        }
    }
    Ok(outputs)
}

/// The calibration file beside a figure: its name with `.json`, refused where that is the
/// figure's own name.
pub fn sidecar(figure: &Path) -> Result<PathBuf> {
    let json = figure.with_extension("json");
    if json == figure {
        bail!(
            "{}: the calibration is written beside the figure with .json, which is this name; end the figure's name with .png",
            figure.display()
        );
    }
    Ok(json)
}

/// A slice of `scene` as an annotated figure with its calibration.
pub fn slice_figure(
    scene: &Scene,
    wanted: &Wanted,
    through: DVec3,
    window: [f32; 2],
    parts: Option<&Annotations>,
) -> Result<(RgbaImage, Value)> {
    let plane = Plane::of(scene, wanted.spec, through, wanted.mesh.as_deref())?;
    let slice = Slice::new(scene, plane, Pixels::Size(wanted.mm_per_pixel))?;
    let mut parts = label_parts(parts, &slice);
    if let Some(p) = &mut parts {
        p.caption = p
            .caption
            .take()
            .map(|c| c.replace("{slice}", &wanted.spec.to_string()));
    }
    let (image, drawn) = figure(&slice, scene, window, parts.as_ref())?;
    super::render::say_dropped(drawn.as_ref(), parts.as_ref());
    Ok((image, slice.calibration(scene, window)))
}

/// The annotations asked for, or the measurements' labels alone where none were and the slice
/// shows measurements (as 3D figures write their values).
fn label_parts(parts: Option<&Annotations>, slice: &Slice) -> Option<Annotations> {
    match parts {
        Some(p) => Some(p.clone()),
        None if !slice.measurements.is_empty() => Annotations::parse_parts("measurements").ok(),
        None => None,
    }
}

/// The calibration's keys that go into a PNG's text chunks: the pixels' placement, not the
/// lists of meshes, measurements and panes (which the JSON beside it holds).
pub fn calibration_chunks(calibration: &Value) -> Vec<(&str, &Value)> {
    calibration
        .as_object()
        .map(|o| {
            o.iter()
                .filter(|(k, _)| !matches!(k.as_str(), "meshes" | "measurements" | "panes"))
                .map(|(k, v)| (k.as_str(), v))
                .collect()
        })
        .unwrap_or_default()
}

/// Writes a figure, its calibration beside it and in its text chunks.
pub fn write_figure(out: &Path, image: &RgbaImage, calibration: &Value) -> Result<()> {
    let json_path = sidecar(out)?;
    let chunks = calibration_chunks(calibration);
    write_replacing(out, &encode_png_with_text(image, &chunks)?)?;
    write_replacing(
        &json_path,
        serde_json::to_string_pretty(calibration)?.as_bytes(),
    )?;
    Ok(())
}

/// Draws the slices `wanted` of `scene` to `pattern`'s files.
pub fn run_slices(
    scene: &Scene,
    file: &SceneFile,
    through: DVec3,
    wanted: &[Wanted],
    pattern: &Path,
    parts: Option<&Annotations>,
) -> Result<()> {
    let outputs = slice_outputs(pattern, wanted)?;
    let sidecars = outputs
        .iter()
        .map(|o| sidecar(o))
        .collect::<Result<Vec<_>>>()?;
    for (s, o) in sidecars.iter().zip(&outputs) {
        if outputs.contains(s) {
            bail!(
                "{}: its calibration {} is the name of another output",
                o.display(),
                s.display()
            );
        }
    }
    refuse_inputs(outputs.iter().chain(&sidecars).cloned())?;
    let window = window(scene, file);
    for (w, out) in wanted.iter().zip(&outputs) {
        let (image, calibration) = slice_figure(scene, w, through, window, parts)
            .with_context(|| format!("--slice {}", w.spec))?;
        write_figure(out, &image, &calibration)?;
        let meshes: Vec<String> = calibration["meshes"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|m| {
                format!(
                    "{} {:.1} mm around, {:.1} mm\u{b2}",
                    m["name"].as_str().unwrap_or("mesh"),
                    m["outline_mm"].as_f64().unwrap_or(0.0),
                    m["area_mm2"].as_f64().unwrap_or(0.0)
                )
            })
            .collect();
        eprintln!(
            "{} slice at {} mm, {}x{} pixels of {:.3} mm, window {} to {}{}",
            w.spec.kind.name(),
            calibration["at_mm"],
            calibration["size"][0],
            calibration["size"][1],
            calibration["mm_per_pixel"].as_f64().unwrap_or(0.0),
            window[0],
            window[1],
            if meshes.is_empty() {
                "; no mesh crosses it".to_owned()
            } else {
                format!("; {}", meshes.join("; "))
            }
        );
        eprintln!("wrote {} and {}", out.display(), sidecar(out)?.display());
    }
    Ok(())
}

/// The four panes put together (3D Slicer's four-up: axial top left, 3D top right, sagittal
/// bottom left, coronal bottom right), with the calibration of the whole figure: each slice
/// pane's rectangle and its pixels' world points in the figure's pixel coordinates.
pub fn compose_quad(
    size: (u32, u32),
    view3d: &RgbaImage,
    slices: &[Pane],
    window: [f32; 2],
    point: DVec3,
    scene: &Scene,
) -> (RgbaImage, Value) {
    let (pw, ph) = (size.0 / 2, size.1 / 2);
    let mut image = RgbaImage::from_pixel(size.0, size.1, image::Rgba([0, 0, 0, 255]));
    let at = |kind: Option<PlaneKind>| match kind {
        Some(PlaneKind::Axial) => (0, 0),
        None => (pw, 0),
        Some(PlaneKind::Sagittal) => (0, ph),
        _ => (pw, ph),
    };
    image::imageops::overlay(&mut image, view3d, i64::from(pw), 0);
    let mut panes = vec![json!({"name": "3d", "rect": [pw, 0, view3d.width(), view3d.height()]})];
    for pane in slices {
        let kind = pane.slice.frame.plane.spec.kind;
        let (x, y) = at(Some(kind));
        image::imageops::overlay(&mut image, &pane.image, i64::from(x), i64::from(y));
        let mut c = pane.slice.calibration(scene, window);
        // The origin moved to the figure's pixel (0, 0), so that every pixel of the pane maps
        // by the same vectors.
        let vector = |key: &str| -> DVec3 {
            let a = c[key].as_array().cloned().unwrap_or_default();
            DVec3::from(std::array::from_fn(|i| {
                a.get(i).and_then(Value::as_f64).unwrap_or(0.0)
            }))
        };
        let origin = vector("origin_mm")
            - vector("pixel_right_mm") * f64::from(x)
            - vector("pixel_down_mm") * f64::from(y);
        c["origin_mm"] = json!(origin.to_array());
        c["rect"] = json!([x, y, pane.image.width(), pane.image.height()]);
        c["name"] = json!(kind.name());
        for key in ["frame", "unit", "window", "volume"] {
            if let Some(o) = c.as_object_mut() {
                o.remove(key);
            }
        }
        panes.push(c);
    }
    let p = scene.patient_frame().patient(point);
    let calibration = json!({
        "layout": "quad",
        "frame": "RAS",
        "unit": "mm",
        "size": [size.0, size.1],
        "point_mm": [p.x, p.y, p.z],
        "window": window,
        "panes": panes,
    });
    (image, calibration)
}
