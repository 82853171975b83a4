//! Batch manifests: the TOML that lists a batch's jobs, and its check and expansion into the
//! files each job writes. Everything here is read and checked before anything is rendered, so
//! that a typo in the last job is reported before the first job's minutes are spent.
//!
//! ```toml
//! [defaults]                     # any job key but name, scene, volume and mesh
//! views = ["anterior", "right"]
//! sizes = [[640, 480]]
//! annotate = "all"
//!
//! [[job]]
//! name = "shoulder"
//! scene = "../scenes/shoulder.toml"
//! contents = ["all", "meshes"]   # with and without the volumes
//!
//! [[job]]
//! name = "ct-small"
//! volume = "data:dicom/CT_small.dcm"
//! preset = "ct-bone"
//! ```

use std::collections::HashMap;
use std::path::{Component, Path, PathBuf};

use serde::{Deserialize, Serialize};

use splatscene::order::Ordering;
use splatscene::scene::file::{CameraSpec, MeshSpec, SceneFile, VolumeSpec};
use splatscene::scene::patient::NamedView;
use splatscene::scene::slice_spec::SliceSpec;

use splatscene::scene::file::apply_transfer;

/// A manifest as written.
#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Keys every job takes unless it sets them itself.
    #[serde(default)]
    pub defaults: JobSpec,
    /// The jobs, in the order they run.
    #[serde(default, rename = "job")]
    pub jobs: Vec<JobSpec>,
}

/// A volume given by its path alone, or as a scene file's `[[volume]]` table.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(untagged)]
pub enum VolumeInput {
    /// A volume file or DICOM folder.
    Path(String),
    /// A scene file's volume table (transfer function, raw placement, series...).
    Table(Box<VolumeSpec>),
}

/// A view: a named view of the patient, `scene` for the scene's own camera, or a camera.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(untagged)]
pub enum ViewEntry {
    /// `anterior`, `anterolateral-right`... or `scene`.
    Named(String),
    /// A camera of its own, with a name for the output files.
    Camera(NamedCamera),
}

/// A camera view of a job.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct NamedCamera {
    /// The name that `{view}` in output names becomes.
    pub name: String,
    /// Eye position (world millimetres).
    pub eye: Option<[f64; 3]>,
    /// Look-at point; the scene centre by default.
    pub target: Option<[f64; 3]>,
    /// Up on screen; the patient's superior axis by default.
    pub up: Option<[f64; 3]>,
    /// Viewing direction to fit the scene along, instead of `eye`.
    pub view_from: Option<[f64; 3]>,
    /// Vertical field of view in degrees.
    pub fov: Option<f64>,
    /// Visible height in millimetres: an orthographic camera.
    pub orthographic_height: Option<f64>,
}

/// `annotate = true`, `false` or a list of parts (`"marker,scale"`).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(untagged)]
pub enum AnnotateValue {
    /// Every part, or none.
    All(bool),
    /// The parts named, as `render --annotate` takes them.
    Parts(String),
}

/// One job, or the defaults: every key optional here, checked and merged in [`plan`].
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct JobSpec {
    /// The job's name, `{job}` in output names; the scene's or volume's file stem by default.
    pub name: Option<String>,
    /// A scene file.
    pub scene: Option<String>,
    /// A volume file or DICOM folder (instead of `scene`).
    pub volume: Option<VolumeInput>,
    /// Meshes to add, as a scene file's `[[mesh]]` tables.
    #[serde(rename = "mesh")]
    pub meshes: Option<Vec<MeshSpec>>,
    /// Transfer function preset for every volume.
    pub preset: Option<String>,
    /// Value window `[low, high]` (stretches the preset, or a ramp without one).
    pub window: Option<[f32; 2]>,
    /// Moves the transfer function along the value axis.
    pub shift: Option<f32>,
    /// The views, `{view}` in output names.
    pub views: Option<Vec<ViewEntry>>,
    /// Image sizes `[width, height]`, `{size}` in output names.
    pub sizes: Option<Vec<[u32; 2]>>,
    /// Orderings, `{ordering}` in output names.
    pub orderings: Option<Vec<String>>,
    /// What is drawn: `all`, `meshes` (the volumes left out) or `volumes` (the meshes left
    /// out); `{content}` in output names.
    pub contents: Option<Vec<String>>,
    /// Annotations, as `render --annotate`.
    pub annotate: Option<AnnotateValue>,
    /// A caption; `{job}`, `{view}`, `{content}`, `{ordering}` and `{size}` are replaced.
    pub caption: Option<String>,
    /// A transparent background.
    pub transparent: Option<bool>,
    /// The colour image's name, relative to the output folder.
    pub out: Option<String>,
    /// Also a depth image, named so (its calibration beside it, with `.json`).
    pub depth: Option<String>,
    /// `mesh` or `surface`, as `render --depth-mode`.
    pub depth_mode: Option<String>,
    /// The opacity that makes a volume's surface in surface depth images.
    pub surface_opacity: Option<f32>,
    /// Where the scene's measurements go as JSON, when it has any (`{job}-measurements.json`
    /// by default); `{job}` is replaced.
    pub measurements: Option<String>,
    /// With `true`, the contact of the job's first mesh with its volume (as `splatscene
    /// contact` gives it) is written to `{job}-contact.json` and into the index. Left out of
    /// the job's hash while unset, so that manifests without it keep their hashes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact: Option<bool>,
    /// Slices through the scene's camera target or the first mesh's pivot, as `render
    /// --slice` names them (`axial`, `implant-long`, `axial@-62.5`...), each written to
    /// `{job}-{slice}.png` with its calibration beside it (`.json`). Left out of the job's
    /// hash while unset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slices: Option<Vec<String>>,
}

impl JobSpec {
    /// This job's keys, the defaults' where it has none.
    fn merged(&self, d: &JobSpec) -> JobSpec {
        macro_rules! pick {
            ($($field:ident),*) => {
                JobSpec { $($field: self.$field.clone().or_else(|| d.$field.clone()),)* }
            };
        }
        pick!(
            name,
            scene,
            volume,
            meshes,
            preset,
            window,
            shift,
            views,
            sizes,
            orderings,
            contents,
            annotate,
            caption,
            transparent,
            out,
            depth,
            depth_mode,
            surface_opacity,
            measurements,
            contact,
            slices
        )
    }
}

/// What an output draws.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Content {
    /// Everything.
    All,
    /// The meshes alone.
    Meshes,
    /// The volumes alone.
    Volumes,
}

impl Content {
    /// The name in manifests and output names.
    pub fn name(self) -> &'static str {
        match self {
            Self::All => "all",
            Self::Meshes => "meshes",
            Self::Volumes => "volumes",
        }
    }
}

/// How a view's camera is made once the scene is loaded.
#[derive(Debug, Clone)]
pub enum ViewKind {
    /// The scene's own camera.
    Scene,
    /// A named view fitted to the scene.
    Named(NamedView),
    /// A camera of the manifest's.
    Camera(CameraSpec),
}

/// A view of a job, with its name in output names.
#[derive(Debug, Clone)]
pub struct PlannedView {
    /// `{view}`.
    pub name: String,
    /// The camera.
    pub kind: ViewKind,
}

/// One picture of a job and the files it writes.
#[derive(Debug, Clone)]
pub struct RenderItem {
    /// Index into the job's views.
    pub view: usize,
    /// What is drawn.
    pub content: Content,
    /// The ordering.
    pub ordering: Ordering,
    /// Image size.
    pub size: (u32, u32),
    /// The colour image, relative to the output folder.
    pub image: PathBuf,
    /// The depth image, relative to the output folder.
    pub depth: Option<PathBuf>,
    /// The caption, placeholders replaced.
    pub caption: Option<String>,
}

/// A job checked and expanded.
#[derive(Debug, Clone)]
pub struct PlannedJob {
    /// Position in the manifest, from 0.
    pub position: usize,
    /// The job's name.
    pub name: String,
    /// The scene to load, paths absolute.
    pub file: SceneFile,
    /// The scene file, or a description of the volume, for messages.
    pub source: PathBuf,
    /// The scene file read (hashed with the job), if any.
    pub scene_path: Option<PathBuf>,
    /// The views.
    pub views: Vec<PlannedView>,
    /// The pictures, those that draw volumes first (so that a volume is classified once).
    pub items: Vec<RenderItem>,
    /// Annotation parts, `None` for plain pictures.
    pub annotate: Option<String>,
    /// A transparent background.
    pub transparent: bool,
    /// The depth image's contents.
    pub depth_mode: Option<String>,
    /// The surface opacity of surface depth images.
    pub surface_opacity: f32,
    /// The measurements' JSON file, when the scene has measurements.
    pub measurements: Option<PathBuf>,
    /// The contact report's JSON file, when the job asks for it.
    pub contact: Option<PathBuf>,
    /// The slices, each with its figure (its calibration beside it, `.json`).
    pub slices: Vec<(SliceSpec, PathBuf)>,
    /// The merged spec, hashed with the inputs so that a changed key renders the job again.
    pub spec: JobSpec,
}

impl PlannedJob {
    /// Every file the job writes, relative to the output folder: the measurements, and per
    /// picture the image, the depth image and its calibration.
    pub fn outputs(&self) -> Vec<PathBuf> {
        let mut files: Vec<PathBuf> = self
            .measurements
            .iter()
            .chain(&self.contact)
            .cloned()
            .collect();
        for (_, figure) in &self.slices {
            files.push(figure.clone());
            files.push(figure.with_extension("json"));
        }
        for item in &self.items {
            files.push(item.image.clone());
            if let Some(d) = &item.depth {
                files.push(d.clone());
                files.push(super::super::render::sidecar_of(d));
            }
        }
        files
    }
}

/// A problem with a manifest: which job, which key, what.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// `job 3 (lidc2)`, `defaults` or `manifest`.
    pub job: String,
    /// The key.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}, key `{}`: {}", self.job, self.key, self.message)
    }
}

/// Names the output folder keeps for itself.
pub fn is_index_name(name: &str) -> bool {
    name == "index.json" || (name.starts_with("index-") && name.ends_with(".json"))
}

/// Largest image side, as in scene files.
const MAX_SIDE: u32 = splatscene::budget::MAX_SIDE;
/// Largest image, in pixels: 64 megapixels, about 1 GiB of frame and depth buffers.
const MAX_PIXELS: u64 = splatscene::budget::MAX_PIXELS;

/// Reads a manifest file (at most 4 MiB).
pub fn read(path: &Path) -> anyhow::Result<Manifest> {
    use anyhow::Context;
    let len = std::fs::metadata(path)
        .with_context(|| format!("{}: cannot read", path.display()))?
        .len();
    if len > 4 << 20 {
        anyhow::bail!(
            "{}: {len} bytes is too large for a manifest (4 MiB at most)",
            path.display()
        );
    }
    let text = splatscene::input::read_regular_text(path, 4 << 20)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    parse(&text).map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
}

/// Parses manifest TOML.
pub fn parse(text: &str) -> Result<Manifest, String> {
    let manifest = parse_only(text)?;
    // serde fills a fixed-size array from the first elements of a longer one and drops the
    // rest (`sizes = [[64, 64, 3]]`): the lengths are compared with what the file reads as,
    // as scene files do.
    let written: toml::Value = toml::from_str(text).map_err(|e| e.to_string())?;
    let read = toml::Value::try_from(&manifest).map_err(|e| e.to_string())?;
    if let Some(message) = splatscene::scene::file::extra_elements(&written, &read, "") {
        return Err(message);
    }
    Ok(manifest)
}

fn parse_only(text: &str) -> Result<Manifest, String> {
    toml::from_str(text).map_err(|e| {
        let message = e.to_string();
        if message.contains("did not match any variant") {
            format!(
                "{message}\n(a view is a name such as \"anterior\" or a table {{ name, eye, target, up, view_from, fov, orthographic_height }}; a volume is a path or a scene file's volume table; annotate is true, false or parts such as \"marker,scale\")"
            )
        } else {
            message
        }
    })
}

/// Checks every job of `manifest` (read from a file in `base`) and expands it into the files it
/// writes; all problems are returned together. Files are looked for but not loaded.
pub fn plan(manifest: &Manifest, base: &Path) -> Result<Vec<PlannedJob>, Vec<Problem>> {
    let mut problems = Vec::new();
    let d = &manifest.defaults;
    for (key, set) in [
        ("name", d.name.is_some()),
        ("scene", d.scene.is_some()),
        ("volume", d.volume.is_some()),
        ("mesh", d.meshes.is_some()),
    ] {
        if set {
            problems.push(Problem {
                job: "defaults".into(),
                key: key.into(),
                message: "belongs to a job, not to the defaults".into(),
            });
        }
    }
    if manifest.jobs.is_empty() {
        problems.push(Problem {
            job: "manifest".into(),
            key: "job".into(),
            message: "no [[job]] tables: nothing to render".into(),
        });
    }
    let mut jobs = Vec::new();
    let own_keys = |job: &JobSpec| match serde_json::to_value(job) {
        Ok(serde_json::Value::Object(map)) => map
            .into_iter()
            .filter(|(_, v)| !v.is_null())
            .map(|(k, _)| k)
            .collect(),
        _ => Vec::new(),
    };
    let default_keys = own_keys(d);
    for (position, job) in manifest.jobs.iter().enumerate() {
        let spec = job.merged(d);
        let own = own_keys(job);
        match plan_job(position, spec, base) {
            Ok(planned) => jobs.push(planned),
            Err(found) => {
                // A key the job takes from the defaults is reported once, as the defaults'.
                for mut p in found {
                    if default_keys.contains(&p.key) && !own.contains(&p.key) {
                        p.job = "defaults".into();
                    }
                    if !problems.contains(&p) {
                        problems.push(p);
                    }
                }
            }
        }
    }
    // Names given in the manifest are checked here, also for jobs with other problems;
    // names taken from file stems once the jobs are planned.
    let mut named: HashMap<&str, usize> = HashMap::new();
    for (position, job) in manifest.jobs.iter().enumerate() {
        if let Some(name) = job.name.as_deref()
            && let Some(first) = named.insert(name, position)
        {
            problems.push(Problem {
                job: label(position, Some(name)),
                key: "name".into(),
                message: format!(
                    "job {} has this name too; give each job its own `name`",
                    first + 1
                ),
            });
        }
    }
    check_names(&jobs, &mut problems);
    check_outputs(&jobs, &mut problems);
    if problems.is_empty() {
        Ok(jobs)
    } else {
        Err(problems)
    }
}

/// A job's label in messages before its name is known to be good.
fn label(position: usize, name: Option<&str>) -> String {
    match name {
        Some(n) => format!("job {} ({n})", position + 1),
        None => format!("job {}", position + 1),
    }
}

/// Checks one job's keys and expands it into its pictures. Every problem is collected, not the
/// first alone, so that a manifest is fixed in one pass: this is why the closed sets of a job
/// (orderings, contents, depth modes, annotation parts) are read here from their names rather
/// than by serde, which stops at the first bad value. Each group of keys has its helper below.
fn plan_job(position: usize, spec: JobSpec, base: &Path) -> Result<PlannedJob, Vec<Problem>> {
    let mut problems = Vec::new();
    let job = label(position, spec.name.as_deref());
    let mut problem = |key: &str, message: String| {
        problems.push(Problem {
            job: job.clone(),
            key: key.into(),
            message,
        })
    };
    // The input: a scene file, or a volume.
    let (file, source, scene_path) = match (&spec.scene, &spec.volume) {
        (Some(_), Some(_)) => {
            problem(
                "scene",
                "a job takes a scene or a volume, not both (add meshes with [[job.mesh]])".into(),
            );
            (None, PathBuf::new(), None)
        }
        (None, None) => {
            problem(
                "scene",
                "the job has neither a scene nor a volume to render".into(),
            );
            (None, PathBuf::new(), None)
        }
        (Some(scene), None) => {
            let path = base.join(scene);
            match SceneFile::read(&path) {
                Ok(file) => {
                    let folder = path.parent().unwrap_or(Path::new(".")).to_path_buf();
                    (
                        Some(file.with_paths_from(&folder)),
                        path.clone(),
                        Some(path),
                    )
                }
                Err(e) => {
                    problem("scene", e.to_string());
                    (None, path, None)
                }
            }
        }
        (None, Some(volume)) => {
            let mut volume = match volume {
                VolumeInput::Path(p) => VolumeSpec {
                    path: p.clone(),
                    ..VolumeSpec::default()
                },
                VolumeInput::Table(v) => (**v).clone(),
            };
            if volume.name.is_none() {
                volume.name = Path::new(&volume.path)
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned());
            }
            let source = PathBuf::from(&volume.path);
            let file = SceneFile {
                camera: Some(CameraSpec {
                    view: Some("anterior".into()),
                    ..CameraSpec::default()
                }),
                volumes: vec![volume],
                ..SceneFile::default()
            };
            (Some(file.with_paths_from(base)), source, None)
        }
    };
    let name = match &spec.name {
        Some(n) => n.clone(),
        None => {
            let stem = source
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            // `CT_small.dcm` and a folder `case-01` both give a usable name.
            stem.split('.').next().unwrap_or_default().to_owned()
        }
    };
    if let Err(e) = check_name(&name) {
        problem("name", e);
    }
    let mut file = file.unwrap_or_default();
    if let Some(meshes) = &spec.meshes {
        let mut added = SceneFile {
            meshes: meshes.clone(),
            ..SceneFile::default()
        }
        .with_paths_from(base);
        file.meshes.append(&mut added.meshes);
    }
    if let Some([lo, hi]) = spec.window
        && lo >= hi
    {
        problem(
            "window",
            format!("[{lo}, {hi}]: the low value must lie below the high one"),
        );
    }
    if spec.shift.is_some_and(|s| !s.is_finite()) {
        problem("shift", "must be a finite number".into());
    }
    if (spec.preset.is_some() || spec.window.is_some() || spec.shift.is_some())
        && file.volumes.is_empty()
        && (spec.scene.is_some() || spec.volume.is_some())
    {
        let key = if spec.preset.is_some() {
            "preset"
        } else if spec.window.is_some() {
            "window"
        } else {
            "shift"
        };
        problem(key, "the job has no volume for it to apply to".into());
    }
    for volume in &mut file.volumes {
        apply_transfer(volume, spec.preset.as_deref(), spec.window, spec.shift);
    }
    for missing in file.missing_files(base) {
        problem(
            if spec.scene.is_some() {
                "scene"
            } else {
                "volume"
            },
            missing,
        );
    }

    let views = plan_views(&spec, &mut problem);
    let sizes = plan_sizes(&spec, &file, &mut problem);
    let orderings = plan_orderings(&spec, &file, &mut problem);
    let has_meshes = !file.meshes.is_empty();
    let contents = plan_contents(&spec, &file, &mut problem);

    let (annotate, surface_opacity) = plan_annotations_and_depth(&spec, has_meshes, &mut problem);

    // Output names.
    let vary = |n: usize| n > 1;
    let out = spec.out.clone().unwrap_or_else(|| {
        let mut p = "{job}-{view}".to_owned();
        if vary(contents.len()) {
            p.push_str("-{content}");
        }
        if vary(orderings.len()) {
            p.push_str("-{ordering}");
        }
        if vary(sizes.len()) {
            p.push_str("-{size}");
        }
        p + ".png"
    });
    for (key, pattern) in [("out", Some(&out)), ("depth", spec.depth.as_ref())] {
        if let Some(pattern) = pattern
            && let Err(e) = check_pattern(pattern, true)
        {
            problem(key, e);
        }
    }
    // A depth image's calibration is written beside it with `.json`.
    if let Some(depth) = &spec.depth
        && super::super::render::sidecar_of(Path::new(depth))
            .file_name()
            .is_some_and(|n| is_index_name(&n.to_string_lossy()))
    {
        problem(
            "depth",
            format!(
                "{depth:?}: the depth image's calibration beside it (its name with .json) would take the name of the output folder's index"
            ),
        );
    }
    let measurements_out = spec
        .measurements
        .clone()
        .unwrap_or_else(|| "{job}-measurements.json".into());
    if let Err(e) = check_pattern(&measurements_out, false) {
        problem("measurements", e);
    } else if Path::new(&measurements_out)
        .extension()
        .is_none_or(|e| !e.eq_ignore_ascii_case("json"))
    {
        problem(
            "measurements",
            format!(
                "{measurements_out:?}: measurements are written as JSON; end the name with .json"
            ),
        );
    }
    if spec.contact == Some(true) && (file.meshes.is_empty() || file.volumes.is_empty()) {
        problem(
            "contact",
            "needs a mesh and a volume: the contact is the mesh's surface sampled in the volume"
                .into(),
        );
    }
    let mut slices = Vec::new();
    for text in spec.slices.iter().flatten() {
        match text.parse::<SliceSpec>() {
            Ok(slice) if slices.iter().any(|(s, _)| *s == slice) => {
                problem("slices", format!("{slice} is named twice"));
            }
            Ok(slice) => {
                let figure = PathBuf::from(format!("{name}-{slice}.png"));
                slices.push((slice, figure));
            }
            Err(e) => problem("slices", e.to_string()),
        }
    }
    if !slices.is_empty() && file.volumes.is_empty() {
        problem("slices", "needs a volume to slice".into());
    }
    if slices.iter().any(|(s, _)| s.kind.follows_implant()) && file.meshes.is_empty() {
        problem(
            "slices",
            "implant-long and implant-cross follow a mesh, and the job has none".into(),
        );
    }
    if spec.measurements.is_some() && file.measurements.is_empty() {
        problem(
            "measurements",
            "the scene has no [[measurement]] to write".into(),
        );
    }
    if let Some(caption) = &spec.caption
        && let Err(e) = check_placeholders(caption)
    {
        problem("caption", e);
    }
    if !problems.is_empty() {
        return Err(problems);
    }
    let mut items = Vec::new();
    for &content in &contents {
        for (v, view) in views.iter().enumerate() {
            for &ordering in &orderings {
                for &size in &sizes {
                    let fill = |pattern: &str| {
                        fill_pattern(pattern, &name, &view.name, content, ordering, size)
                    };
                    items.push(RenderItem {
                        view: v,
                        content,
                        ordering,
                        size,
                        image: PathBuf::from(fill(&out)),
                        depth: spec.depth.as_deref().map(|d| PathBuf::from(fill(d))),
                        caption: spec.caption.as_deref().map(fill),
                    });
                }
            }
        }
    }
    let measurements = (!file.measurements.is_empty())
        .then(|| PathBuf::from(measurements_out.replace("{job}", &name)));
    let contact =
        (spec.contact == Some(true)).then(|| PathBuf::from(format!("{name}-contact.json")));
    Ok(PlannedJob {
        position,
        measurements,
        contact,
        slices,
        name,
        file,
        source,
        scene_path,
        views,
        items,
        annotate,
        transparent: spec.transparent.unwrap_or(false),
        depth_mode: spec.depth_mode.clone(),
        surface_opacity,
        spec,
    })
}

/// The job's views (`views`, the scene's camera by default): named views, cameras, or
/// `scene`; none given twice.
fn plan_views(spec: &JobSpec, problem: &mut impl FnMut(&str, String)) -> Vec<PlannedView> {
    let mut views = Vec::new();
    let entries = spec
        .views
        .clone()
        .unwrap_or_else(|| vec![ViewEntry::Named("scene".into())]);
    if entries.is_empty() {
        problem("views", "is empty: give at least one view".into());
    }
    for entry in &entries {
        match entry {
            ViewEntry::Named(n) if n == "scene" => views.push(PlannedView {
                name: n.clone(),
                kind: ViewKind::Scene,
            }),
            ViewEntry::Named(n) => match NamedView::parse(n) {
                Ok(v) => views.push(PlannedView {
                    name: v.name.clone(),
                    kind: ViewKind::Named(v),
                }),
                Err(e) => problem(
                    "views",
                    format!("{e} (or \"scene\" for the scene's camera)"),
                ),
            },
            ViewEntry::Camera(c) => match camera_spec(c) {
                Ok(spec) => views.push(PlannedView {
                    name: c.name.clone(),
                    kind: ViewKind::Camera(spec),
                }),
                Err(e) => problem("views", format!("camera {:?}: {e}", c.name)),
            },
        }
    }
    for (i, v) in views.iter().enumerate() {
        if views[..i].iter().any(|w| w.name == v.name) {
            problem("views", format!("{:?} is given twice", v.name));
        }
    }
    views
}

/// The job's image sizes (`sizes`, the scene file's by default), each within the limits.
fn plan_sizes(
    spec: &JobSpec,
    file: &SceneFile,
    problem: &mut impl FnMut(&str, String),
) -> Vec<(u32, u32)> {
    let sizes = match &spec.sizes {
        Some(list) => list.iter().map(|&[w, h]| (w, h)).collect(),
        None => vec![file.output.size.map_or((800, 600), |[w, h]| (w, h))],
    };
    if sizes.is_empty() {
        problem(
            "sizes",
            "is empty: give at least one [width, height]".into(),
        );
    }
    for &(w, h) in &sizes {
        if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
            problem(
                "sizes",
                format!("[{w}, {h}]: each side must be between 1 and {MAX_SIDE} pixels"),
            );
        } else if u64::from(w) * u64::from(h) > MAX_PIXELS {
            problem(
                "sizes",
                format!("[{w}, {h}]: more than {MAX_PIXELS} pixels in one image"),
            );
        }
    }
    sizes
}

/// The job's orderings (`orderings`, the scene file's by default), by name.
fn plan_orderings(
    spec: &JobSpec,
    file: &SceneFile,
    problem: &mut impl FnMut(&str, String),
) -> Vec<Ordering> {
    let names = spec.orderings.clone().unwrap_or_else(|| {
        vec![
            file.output
                .ordering
                .unwrap_or(Ordering::IpPbtfImplicit)
                .name()
                .into(),
        ]
    });
    if names.is_empty() {
        problem("orderings", "is empty: give at least one ordering".into());
    }
    let mut orderings = Vec::new();
    for n in &names {
        match n.parse::<Ordering>() {
            Ok(o) => orderings.push(o),
            Err(e) => problem("orderings", e.to_string()),
        }
    }
    orderings
}

/// What the job's pictures draw (`contents`, `all` by default), those with volumes first; a
/// content the scene cannot show is a problem.
fn plan_contents(
    spec: &JobSpec,
    file: &SceneFile,
    problem: &mut impl FnMut(&str, String),
) -> Vec<Content> {
    let mut contents = Vec::new();
    let has_meshes = !file.meshes.is_empty();
    let has_volumes = !file.volumes.is_empty();
    for n in spec.contents.clone().unwrap_or_else(|| vec!["all".into()]) {
        let content = match n.as_str() {
            "all" => Content::All,
            "meshes" => Content::Meshes,
            "volumes" => Content::Volumes,
            other => {
                problem(
                    "contents",
                    format!("unknown content {other:?}: all, meshes or volumes"),
                );
                continue;
            }
        };
        if content == Content::Meshes && !has_meshes {
            problem("contents", "\"meshes\": the job has no meshes".into());
        }
        if content == Content::Volumes && !has_volumes {
            problem("contents", "\"volumes\": the job has no volumes".into());
        }
        if contents.contains(&content) {
            problem("contents", format!("{n:?} is given twice"));
        }
        contents.push(content);
    }
    if contents.is_empty() && spec.contents.is_some() {
        problem("contents", "is empty: give all, meshes or volumes".into());
    }
    contents.sort_by_key(|c| *c == Content::Meshes);
    contents
}

/// The job's annotations (`annotate`, `caption`) and depth image settings (`depth_mode`,
/// `surface_opacity`): the annotation parts to draw, and the surface opacity.
fn plan_annotations_and_depth(
    spec: &JobSpec,
    has_meshes: bool,
    problem: &mut impl FnMut(&str, String),
) -> (Option<String>, f32) {
    let annotate = match &spec.annotate {
        None | Some(AnnotateValue::All(false)) => None,
        Some(AnnotateValue::All(true)) => Some("all".to_owned()),
        Some(AnnotateValue::Parts(p)) => match splatscene::annotate::Annotations::parse_parts(p) {
            Ok(_) => Some(p.clone()),
            Err(e) => {
                problem("annotate", e.to_string());
                None
            }
        },
    };
    if spec.caption.as_deref().is_some_and(|c| c.trim().is_empty()) {
        problem("caption", "is empty".into());
    }
    match spec.depth_mode.as_deref() {
        None | Some("mesh" | "surface") => {}
        Some(other) => problem("depth_mode", format!("{other:?}: mesh or surface")),
    }
    if spec.depth.is_none() {
        if spec.depth_mode.is_some() {
            problem("depth_mode", "has no effect without `depth`".into());
        }
        if spec.surface_opacity.is_some() {
            problem("surface_opacity", "has no effect without `depth`".into());
        }
    }
    if spec.depth_mode.as_deref() == Some("mesh") && !has_meshes && spec.depth.is_some() {
        problem(
            "depth_mode",
            "\"mesh\": the job has no meshes, so the depth image would be empty".into(),
        );
    }
    let surface_opacity = spec.surface_opacity.unwrap_or(0.3);
    if !(surface_opacity > 0.0 && surface_opacity <= 1.0) {
        problem(
            "surface_opacity",
            format!("{surface_opacity}: must lie in (0, 1]"),
        );
    }
    (annotate, surface_opacity)
}

/// A job or view name goes into file names: letters, digits, `.`, `_` and `-`.
fn check_name(name: &str) -> Result<(), String> {
    let good = !name.is_empty()
        && name.len() <= 100
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'));
    if good {
        Ok(())
    } else {
        Err(format!(
            "{:?}: a name goes into file names: 1 to 100 letters, digits, '.', '_' or '-', not starting with '.'",
            splatscene::scene::file::shortened(name)
        ))
    }
}

/// A manifest camera as a scene file's camera spec, checked.
fn camera_spec(c: &NamedCamera) -> Result<CameraSpec, String> {
    check_name(&c.name)?;
    if c.name == "scene" {
        return Err("\"scene\" names the scene's own camera".into());
    }
    let finite = |v: &Option<[f64; 3]>| v.is_none_or(|v| v.iter().all(|x| x.is_finite()));
    if !(finite(&c.eye) && finite(&c.target) && finite(&c.up) && finite(&c.view_from)) {
        return Err("eye, target, up and view_from must be finite".into());
    }
    let zero = |v: &Option<[f64; 3]>| v.is_some_and(|v| v.iter().all(|x| *x == 0.0));
    if zero(&c.up) || zero(&c.view_from) {
        return Err("up and view_from must not be zero".into());
    }
    if c.eye.is_some() && c.view_from.is_some() {
        return Err("give eye or view_from, not both".into());
    }
    if c.eye.is_none() && c.view_from.is_none() {
        return Err("give eye or view_from".into());
    }
    if let (Some(e), Some(t)) = (c.eye, c.target)
        && e == t
    {
        return Err("eye and target are the same point".into());
    }
    if let Some(fov) = c.fov
        && !(fov > 0.0 && fov < 180.0)
    {
        return Err(format!("fov {fov} is not between 0 and 180 degrees"));
    }
    if let Some(h) = c.orthographic_height
        && !(h > 0.0 && h.is_finite())
    {
        return Err(format!("orthographic_height {h} must be positive"));
    }
    if c.fov.is_some() && c.orthographic_height.is_some() {
        return Err("give fov or orthographic_height, not both".into());
    }
    Ok(CameraSpec {
        eye: c.eye,
        target: c.target,
        up: c.up,
        view: None,
        view_from: c.view_from,
        fov: c.fov,
        orthographic_height: c.orthographic_height,
        near: None,
    })
}

const PLACEHOLDERS: [&str; 5] = ["job", "view", "content", "ordering", "size"];

fn check_placeholders(text: &str) -> Result<(), String> {
    let mut rest = text;
    while let Some(open) = rest.find('{') {
        let after = &rest[open + 1..];
        let Some(close) = after.find('}') else {
            return Err(format!("{text:?}: a '{{' without its '}}'"));
        };
        let name = &after[..close];
        if !PLACEHOLDERS.contains(&name) {
            return Err(format!(
                "{text:?}: unknown placeholder {{{name}}}; known: {{job}}, {{view}}, {{content}}, {{ordering}}, {{size}}"
            ));
        }
        rest = &after[close + 1..];
    }
    Ok(())
}

/// An output name: relative, inside the output folder, a PNG.
fn check_pattern(pattern: &str, png: bool) -> Result<(), String> {
    check_placeholders(pattern)?;
    let path = Path::new(pattern);
    for component in path.components() {
        match component {
            Component::Normal(_) | Component::CurDir => {}
            _ => {
                return Err(format!(
                    "{pattern:?}: output names are relative to the output folder and stay inside it (no leading /, no ..)"
                ));
            }
        }
    }
    if png
        && path
            .extension()
            .is_none_or(|e| !e.eq_ignore_ascii_case("png"))
    {
        return Err(format!(
            "{pattern:?}: images are written as PNG; end the name with .png"
        ));
    }
    if path
        .file_name()
        .is_some_and(|n| is_index_name(&n.to_string_lossy()))
    {
        return Err(format!(
            "{pattern:?}: the output folder's index has this name"
        ));
    }
    Ok(())
}

fn fill_pattern(
    pattern: &str,
    job: &str,
    view: &str,
    content: Content,
    ordering: Ordering,
    size: (u32, u32),
) -> String {
    pattern
        .replace("{job}", job)
        .replace("{view}", view)
        .replace("{content}", content.name())
        .replace("{ordering}", ordering.name())
        .replace("{size}", &format!("{}x{}", size.0, size.1))
}

fn check_names(jobs: &[PlannedJob], problems: &mut Vec<Problem>) {
    let mut seen: HashMap<&str, &PlannedJob> = HashMap::new();
    for job in jobs {
        // Two names given in the manifest were compared already.
        if let Some(first) = seen.insert(&job.name, job)
            && (job.spec.name.is_none() || first.spec.name.is_none())
        {
            problems.push(Problem {
                job: label(job.position, Some(&job.name)),
                key: "name".into(),
                message: format!(
                    "job {} has this name too (a job without `name` is named after its file); give each job its own `name`",
                    first.position + 1
                ),
            });
        }
    }
}

/// Every file of every job, each written by one job and one picture only.
fn check_outputs(jobs: &[PlannedJob], problems: &mut Vec<Problem>) {
    let mut owners: HashMap<PathBuf, (usize, String)> = HashMap::new();
    for job in jobs {
        if let Some(file) = &job.measurements {
            let what = format!("{} measurements", job.name);
            match owners.get(&normal(file)) {
                Some((_, other)) => problems.push(Problem {
                    job: label(job.position, Some(&job.name)),
                    key: "measurements".into(),
                    message: format!(
                        "{} is written by {other} and by {what}; put {{job}} in the name",
                        file.display()
                    ),
                }),
                None => {
                    owners.insert(normal(file), (job.position, what));
                }
            }
        }
        for item in &job.items {
            let mut files = vec![("out", normal(&item.image))];
            if let Some(d) = &item.depth {
                files.push(("depth", normal(d)));
                files.push(("depth", normal(&super::super::render::sidecar_of(d))));
            }
            for (key, file) in files {
                let what = format!(
                    "{} view {} ({}, {}, {}x{})",
                    job.name,
                    job.views[item.view].name,
                    item.content.name(),
                    item.ordering.name(),
                    item.size.0,
                    item.size.1
                );
                match owners.get(&file) {
                    Some((_, other)) => problems.push(Problem {
                        job: label(job.position, Some(&job.name)),
                        key: key.into(),
                        message: format!(
                            "{} is written by {other} and by {what}; put the placeholders that differ ({{job}}, {{view}}, {{content}}, {{ordering}}, {{size}}) in the name",
                            file.display()
                        ),
                    }),
                    None => {
                        owners.insert(file, (job.position, what));
                    }
                }
            }
        }
    }
}

/// `a/./b.png` and `a/b.png` name one file; names are compared without case, since the
/// output folder may lie on a file system that ignores it.
fn normal(path: &Path) -> PathBuf {
    let text: PathBuf = path
        .components()
        .filter(|c| !matches!(c, Component::CurDir))
        .collect();
    PathBuf::from(text.to_string_lossy().to_lowercase())
}

#[cfg(test)]
mod tests;
