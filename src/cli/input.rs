//! What a scene command looks at, shared by `render`, `pick`, `measure` and `view`: a scene
//! file, or a volume file or DICOM folder given straight on the command line (the format found
//! from the content), with meshes, a transfer function, raw-volume placement, the camera and
//! named views.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use glam::DVec3;
use serde::Deserialize;

use splatscene::figure::CameraChoice;
use splatscene::scene::file::{
    CameraSpec, LoadedScene, MeshSpec, SceneFile, TransformSpec, Units, VolumeSpec, apply_transfer,
};
use splatscene::scene::patient::NamedView;
use splatscene::scene::patient::OrientationCode;
use splatscene::scene::{Projection, SceneCamera};
use splatscene::volume::detect::{CoordinateFrame, NiftiTransform, detect_format};
use splatscene::volume::{ScalarFormat, VolumeError};

use super::args::{
    parse_f32x2, parse_f64x2, parse_f64x3, parse_finite_f32, parse_size, parse_u32x3,
};

/// How a volume file is read where its format leaves a choice: the DICOM series, the 4-D
/// NIfTI frame, the NIfTI transform, the frame of a format that states none. `render`,
/// `view`, `info` and the others that read a volume take them alike.
#[derive(clap::Args, Clone, Default)]
pub struct VolumeChoices {
    /// DICOM: the series to load from a folder holding several, by its number or its UID
    /// (without it, such a folder lists its series).
    #[arg(long)]
    pub series: Option<String>,
    /// DICOM: load the series without its files that cannot be read (a slice cut short),
    /// naming them on stderr; without it such a file is an error.
    #[arg(long)]
    pub skip_unreadable: bool,
    /// 4-D NIfTI: the 3-D frame, from 0 (default 0, said on stderr).
    #[arg(long)]
    pub frame: Option<u32>,
    /// NIfTI: the transform that places the grid when both are set: sform (default, as
    /// nibabel), qform, or itk (ITK's and 3D Slicer's rule: the sform only when its code is
    /// 1, scanner, else the qform).
    #[arg(long)]
    pub nifti_transform: Option<NiftiTransform>,
    /// VTK, .dat, or NRRD without an anatomical space: the patient frame of the file's
    /// coordinates, RAS (default) or LPS (as ITK-based tools write them).
    #[arg(long)]
    pub coordinate_frame: Option<CoordinateFrame>,
}

impl VolumeChoices {
    /// The loading options these flags make.
    pub fn options(&self) -> Result<splatscene::volume::detect::LoadOptions> {
        Ok(splatscene::volume::detect::LoadOptions {
            series: self
                .series
                .clone()
                .map(splatscene::volume::detect::SeriesChoice),
            skip_unreadable: self.skip_unreadable,
            frame: self.frame,
            nifti_transform: self.nifti_transform,
            coordinate_frame: self.coordinate_frame,
        })
    }
}

/// The input: a scene file or a volume, meshes added to it, and its transfer function.
#[derive(clap::Args)]
pub struct InputArgs {
    /// A scene file (TOML), a volume file (NRRD, NIfTI, DICOM, MetaImage, VTK, Voreen .dat; a raw file
    /// with --dims and --scalar) or a DICOM series folder, told apart by their content; the
    /// built-in shoulder scene when absent.
    pub input: Option<PathBuf>,
    /// A mesh to add (glTF, GLB, OBJ or STL); repeat for several.
    #[arg(long = "mesh")]
    pub(crate) meshes: Vec<PathBuf>,
    /// The transform of the meshes, in the syntax of scene files, for example
    /// '{ rotate_degrees = [0, -28, 180], translate = [26.7, 163.4, 16.7] }': given once it
    /// applies to every --mesh, else once per --mesh in their order.
    #[arg(long = "mesh-transform", allow_hyphen_values = true)]
    mesh_transforms: Vec<String>,
    /// Length unit of the mesh files: mm (default), cm or m; once, or once per --mesh.
    #[arg(long = "mesh-units")]
    mesh_units: Vec<Units>,
    /// Patient frame of the mesh files: RAS (default) or LPS (3D Slicer's export); once, or
    /// once per --mesh.
    #[arg(long = "mesh-frame")]
    mesh_frames: Vec<CoordinateFrame>,
    /// Transfer function preset for every volume: ct-bone, ct-soft-tissue, ct-metal,
    /// mr-default (default: chosen from the data, and said on stderr).
    #[arg(long)]
    preset: Option<String>,
    /// Value window LO,HI: with --preset the preset is stretched over it; alone, a ramp from
    /// transparent at LO to opaque at HI.
    #[arg(long, value_parser = parse_f32x2, allow_hyphen_values = true)]
    window: Option<[f32; 2]>,
    /// Move the transfer function along the value axis (in the volume's units, HU for CT).
    #[arg(long, value_parser = parse_finite_f32, allow_hyphen_values = true)]
    shift: Option<f32>,
    #[command(flatten)]
    choices: VolumeChoices,
    /// Raw volume: size NX,NY,NZ.
    #[arg(long, value_parser = parse_u32x3)]
    dims: Option<[u32; 3]>,
    /// Raw volume: scalar type (u8, i16le, u16be, f32...).
    #[arg(long)]
    scalar: Option<ScalarFormat>,
    /// Raw volume: bytes to skip at the start of the file.
    #[arg(long)]
    header_bytes: Option<u64>,
    /// Raw volume: voxel spacing SX,SY,SZ in millimetres (default 1,1,1).
    #[arg(long, value_parser = parse_f64x3)]
    spacing: Option<[f64; 3]>,
    /// Raw volume: world position of the first voxel, in millimetres (default 0,0,0).
    #[arg(long, value_parser = parse_f64x3, allow_hyphen_values = true)]
    origin: Option<[f64; 3]>,
    /// Raw volume: where its index axes run in the patient, one letter per axis naming the side
    /// it increases toward: RAS (default), LPS, LPI...
    #[arg(long)]
    orientation: Option<OrientationCode>,
}

/// What the input turned out to be.
enum Input<'a> {
    Builtin,
    Scene(&'a Path),
    Volume(&'a Path),
}

impl InputArgs {
    fn input(&self) -> Result<Input<'_>> {
        let Some(path) = &self.input else {
            return Ok(Input::Builtin);
        };
        if self.dims.is_some() || self.scalar.is_some() {
            return Ok(Input::Volume(path));
        }
        match detect_format(path) {
            Ok(_) => Ok(Input::Volume(path)),
            Err(VolumeError::NoHeader { .. }) => Ok(Input::Scene(path)),
            Err(VolumeError::Io { source, .. }) => {
                Err(source).with_context(|| format!("{}: cannot read", path.display()))
            }
            Err(e) => Err(e.into()),
        }
    }

    /// The scene file given as the input, if the input is one.
    pub fn scene_path(&self) -> Option<PathBuf> {
        match self.input() {
            Ok(Input::Scene(path)) => Some(path.to_path_buf()),
            _ => None,
        }
    }

    /// Where a plan of a scene that has no scene file is saved, and under what name: beside
    /// the volume given (a DICOM folder's parent), named after it (`ct.nii.gz` gives `ct`),
    /// else beside the first mesh; `None` for a scene file or the built-in scene.
    pub fn plan_place(&self) -> Option<(PathBuf, String)> {
        let path = match self.input() {
            Ok(Input::Volume(path)) => path,
            Ok(Input::Builtin) => self.meshes.first()?,
            _ => return None,
        };
        let name = path.file_name()?.to_string_lossy().into_owned();
        let stem = match name.trim_start_matches('.').split('.').next() {
            Some(s) if !s.is_empty() => s.to_owned(),
            _ => "splatscene".to_owned(),
        };
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        Some((dir, stem))
    }

    /// Loads the scene the arguments describe, with the scene file that describes it (relative
    /// paths made absolute, so that it can be saved anywhere: the viewer's screenshots do).
    pub fn load(&self) -> Result<(LoadedScene, SceneFile)> {
        if let Some([lo, hi]) = self.window
            && lo >= hi
        {
            bail!("--window {lo},{hi}: the low value must lie below the high one");
        }
        let input = self.input()?;
        let raw_given = [
            ("--dims", self.dims.is_some()),
            ("--scalar", self.scalar.is_some()),
            ("--header-bytes", self.header_bytes.is_some()),
            ("--spacing", self.spacing.is_some()),
            ("--origin", self.origin.is_some()),
            ("--orientation", self.orientation.is_some()),
            ("--series", self.choices.series.is_some()),
            ("--skip-unreadable", self.choices.skip_unreadable),
            ("--frame", self.choices.frame.is_some()),
            ("--nifti-transform", self.choices.nifti_transform.is_some()),
            (
                "--coordinate-frame",
                self.choices.coordinate_frame.is_some(),
            ),
        ];
        let (mut file, path, base) = match input {
            Input::Builtin | Input::Scene(_) => {
                if let Some((flag, _)) = raw_given.iter().find(|(_, g)| *g) {
                    bail!(
                        "{flag} describes a volume given as the input; {} is not a volume",
                        self.input
                            .as_deref()
                            .map_or("the built-in scene".into(), |p| p.display().to_string())
                    );
                }
                match input {
                    // The built-in scene through its scene file, so that meshes, presets and
                    // windows from the command line apply to it as to any other.
                    Input::Scene(path) => {
                        let file = SceneFile::read(path).map_err(|e| scene_or_volume(e, path))?;
                        let base = path.parent().unwrap_or(Path::new(".")).to_path_buf();
                        (file, path.to_path_buf(), base)
                    }
                    _ => (builtin_file()?, "the built-in scene".into(), ".".into()),
                }
            }
            Input::Volume(path) => (self.volume_scene(path)?, path.to_path_buf(), ".".into()),
        };
        for spec in &mut file.volumes {
            apply_transfer(spec, self.preset.as_deref(), self.window, self.shift);
        }
        file.meshes.extend(self.mesh_specs()?);
        let loaded = file.load(&path, &base)?;
        Ok((loaded, file.with_paths_from(&base)))
    }

    /// A scene file holding the volume at `path`, seen from the front.
    fn volume_scene(&self, path: &Path) -> Result<SceneFile> {
        let absolute = std::path::absolute(path)
            .with_context(|| format!("{}: cannot resolve", path.display()))?;
        let volume = VolumeSpec {
            name: path.file_name().map(|n| n.to_string_lossy().into_owned()),
            path: absolute.to_string_lossy().into_owned(),
            dims: self.dims,
            scalar: self.scalar,
            header_bytes: self.header_bytes,
            spacing: self.spacing,
            origin: self.origin,
            orientation: self.orientation,
            series: self.choices.series.clone(),
            skip_unreadable: self.choices.skip_unreadable.then_some(true),
            frame: self.choices.frame,
            nifti_transform: self.choices.nifti_transform,
            coordinate_frame: self.choices.coordinate_frame,
            ..VolumeSpec::default()
        };
        Ok(SceneFile {
            camera: Some(CameraSpec {
                view: Some("anterior".into()),
                ..CameraSpec::default()
            }),
            volumes: vec![volume],
            ..SceneFile::default()
        })
    }

    fn mesh_specs(&self) -> Result<Vec<MeshSpec>> {
        let n = self.meshes.len();
        fn per_mesh<T: Clone>(flag: &str, values: &[T], n: usize) -> Result<Vec<Option<T>>> {
            match values.len() {
                0 => Ok(vec![None; n]),
                _ if n == 0 => bail!("{flag} needs --mesh"),
                1 => Ok(vec![Some(values[0].clone()); n]),
                k if k == n => Ok(values.iter().cloned().map(Some).collect()),
                k => bail!(
                    "{flag} is given {k} times for {n} meshes: give it once, or once per --mesh"
                ),
            }
        }
        let transforms = per_mesh("--mesh-transform", &self.mesh_transforms, n)?;
        let units = per_mesh("--mesh-units", &self.mesh_units, n)?;
        let frames = per_mesh("--mesh-frame", &self.mesh_frames, n)?;
        let mut specs = Vec::with_capacity(n);
        for (i, path) in self.meshes.iter().enumerate() {
            let transform = match &transforms[i] {
                Some(text) => parse_transform(text)?,
                None => TransformSpec::default(),
            };
            let absolute = std::path::absolute(path)
                .with_context(|| format!("{}: cannot resolve", path.display()))?;
            specs.push(MeshSpec {
                name: path.file_name().map(|n| n.to_string_lossy().into_owned()),
                path: absolute.to_string_lossy().into_owned(),
                units: units[i],
                frame: frames[i],
                transform,
                ..MeshSpec::default()
            });
        }
        Ok(specs)
    }
}

/// The scene file of the built-in scene (`examples/scenes/shoulder.toml`, which a test keeps
/// equal to the scene `scene::shoulder::shoulder_scene` builds).
fn builtin_file() -> Result<SceneFile> {
    let text = include_str!("../../examples/scenes/shoulder.toml");
    Ok(SceneFile::parse(text, Path::new("the built-in scene"))?)
}

/// A scene file that does not parse may be a volume the sniffer could not recognise (a
/// headerless raw file): say both.
fn scene_or_volume(e: splatscene::scene::file::SceneFileError, path: &Path) -> anyhow::Error {
    use splatscene::scene::file::SceneFileError;
    match e {
        // A file that is not text (binary voxels) is no scene file either.
        SceneFileError::Io { ref source, .. }
            if source.kind() == std::io::ErrorKind::InvalidData =>
        {
            anyhow::anyhow!(
                "{} is neither a volume format splatscene recognises (NRRD, NIfTI, DICOM, MetaImage, VTK, Voreen .dat) nor a scene file (it is not text); a headerless raw volume needs --dims and --scalar (and --spacing, --origin, --orientation where they are not 1 mm, 0 and RAS)",
                path.display()
            )
        }
        SceneFileError::Parse { .. } | SceneFileError::Invalid { .. } => anyhow::anyhow!(
            "{e}\n{} is neither a volume format splatscene recognises (NRRD, NIfTI, DICOM, MetaImage, VTK, Voreen .dat) nor a valid scene file; a headerless raw volume needs --dims and --scalar",
            path.display()
        ),
        other => other.into(),
    }
}

/// `--mesh-transform`: a TOML inline table, as `transform` in scene files.
fn parse_transform(text: &str) -> Result<TransformSpec> {
    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Wrapper {
        transform: TransformSpec,
    }
    let wrapped: Wrapper = toml::from_str(&format!("transform = {text}")).map_err(|e| {
        anyhow::anyhow!(
            "--mesh-transform {text:?}: {}; expected a table such as '{{ rotate_degrees = [0, 0, 90], translate = [10, 0, 0] }}' (keys translate, rotate_degrees, scale, matrix)",
            e.message()
        )
    })?;
    Ok(wrapped.transform)
}

/// The input, the camera and the image size, shared by every scene command.
#[derive(clap::Args)]
pub struct ViewArgs {
    #[command(flatten)]
    pub input: InputArgs,
    /// Image size WxH (default: the scene file's, else 800x600).
    #[arg(long, value_parser = parse_size)]
    size: Option<(u32, u32)>,
    /// Named views of the patient, comma-separated: anterior, posterior, left, right,
    /// superior, inferior, or several joined by '-' (anterolateral-right), fitted to the scene;
    /// `scene` is the scene's own camera.
    #[arg(long, value_delimiter = ',')]
    view: Vec<String>,
    /// Eye position X,Y,Z in world millimetres.
    #[arg(long, value_parser = parse_f64x3, allow_hyphen_values = true)]
    eye: Option<[f64; 3]>,
    /// Look-at point X,Y,Z (default: the scene's camera target).
    #[arg(long, value_parser = parse_f64x3, allow_hyphen_values = true)]
    target: Option<[f64; 3]>,
    /// Turn the camera about its target and the scene's up (the patient's superior axis unless
    /// the scene sets one): YAW,PITCH in degrees.
    #[arg(long, value_parser = parse_f64x2, allow_hyphen_values = true)]
    orbit: Option<[f64; 2]>,
    /// Vertical field of view in degrees.
    #[arg(long, value_parser = parse_finite_f32)]
    fov: Option<f32>,
    /// Orthographic projection showing this height in world millimetres.
    #[arg(long, value_parser = parse_finite_f32, allow_hyphen_values = true)]
    orthographic: Option<f32>,
}

/// A loaded scene with the cameras and size the arguments ask for.
pub struct View {
    /// The scene and its output settings.
    pub loaded: LoadedScene,
    /// The scene file that describes it, with absolute paths.
    pub file: SceneFile,
    /// One camera per named view (named), or the one camera (no name).
    pub cameras: Vec<(Option<String>, SceneCamera)>,
    /// Image size.
    pub size: (u32, u32),
}

impl ViewArgs {
    /// Whether `--size` was given.
    pub fn size_given(&self) -> bool {
        self.size.is_some()
    }

    /// Loads the scene and makes its cameras.
    pub fn load(&self) -> Result<View> {
        // `scene` is the scene's own camera (as in batch manifests), any other name a view of
        // the patient.
        let views = self
            .view
            .iter()
            .map(|name| match name.trim() {
                "scene" => Ok(None),
                _ => NamedView::parse(name)
                    .map(Some)
                    .map_err(|e| anyhow::anyhow!("--view: {e}")),
            })
            .collect::<Result<Vec<_>>>()?;
        if !views.is_empty() && self.eye.is_some() {
            bail!("--view and --eye both place the camera: give one");
        }
        // The ranges scene files take (camera.fov, camera.orthographic_height).
        if let Some(fov) = self.fov
            && !(fov.is_finite() && (0.1..=170.0).contains(&fov))
        {
            bail!("--fov {fov} is not an angle from 0.1 to 170 degrees");
        }
        if let Some(h) = self.orthographic
            && !(h.is_finite() && h > 0.0)
        {
            bail!("--orthographic {h}: the visible height must be a positive number of mm");
        }
        if self.fov.is_some() && self.orthographic.is_some() {
            bail!("--fov has no effect with --orthographic: give one");
        }
        let (loaded, file) = self.input.load()?;
        let size = self.size.or(loaded.size).unwrap_or((800, 600));
        let aspect = f64::from(size.0) / f64::from(size.1);
        let base = loaded.scene.camera.context("the scene has no camera")?;
        let projection = match (self.orthographic, self.fov) {
            (Some(height), _) => Projection::Orthographic {
                height: f64::from(height),
            },
            (None, Some(fov)) => Projection::Perspective {
                fov_y_degrees: f64::from(fov),
            },
            (None, None) => base.projection,
        };
        let choice = |view: Option<NamedView>| CameraChoice {
            view,
            eye: self.eye.map(DVec3::from),
            target: self.target.map(DVec3::from),
            orbit: self.orbit,
            projection: Some(projection),
        };
        let cameras = if views.is_empty() {
            vec![(None, choice(None).camera(&loaded.scene, base, aspect))]
        } else {
            views
                .into_iter()
                .map(|v| {
                    let name = v.as_ref().map_or("scene".to_owned(), |v| v.name.clone());
                    (Some(name), choice(v).camera(&loaded.scene, base, aspect))
                })
                .collect()
        };
        Ok(View {
            loaded,
            file,
            cameras,
            size,
        })
    }
}

impl View {
    /// The one camera of a command that takes a single view.
    pub fn single_camera(&self) -> Result<SceneCamera> {
        match self.cameras.as_slice() {
            [(_, camera)] => Ok(*camera),
            _ => bail!("this command takes one --view"),
        }
    }
}
