//! The scene file's schema: the tables and keys a scene file may hold, as serde reads and
//! writes them, and reading a file into them.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{SceneFileError, validate};
use crate::measure::MeasureKind;
use crate::order::Ordering;
use crate::scene::Scene;
use crate::scene::patient::OrientationCode;
use crate::scene::slice_spec::SliceSpec;
use crate::volume::ScalarFormat;
use crate::volume::detect::{CoordinateFrame, NiftiTransform};

/// Serde for a key whose value is one of a closed set, written by name: read through the type's
/// `FromStr` (so that a wrong name is an error at its line in the file, listing the names
/// accepted) and written with its `Display`.
mod by_name {
    use std::fmt::Display;
    use std::str::FromStr;

    use serde::{Deserialize, Deserializer, Serializer, de::Error};

    pub fn serialize<T: Display, S: Serializer>(
        value: &Option<T>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        match value {
            Some(v) => s.serialize_some(&v.to_string()),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, T, D>(d: D) -> Result<Option<T>, D::Error>
    where
        T: FromStr,
        T::Err: Display,
        D: Deserializer<'de>,
    {
        Option::<String>::deserialize(d)?
            .map(|name| name.parse().map_err(D::Error::custom))
            .transpose()
    }
}

/// Where a mesh is seated before its transform.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Seat {
    /// In the built-in phantom's humerus (the built-in prosthesis's place).
    Phantom,
}

impl std::str::FromStr for Seat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "phantom" => Ok(Self::Phantom),
            _ => Err(format!("unknown seat {s:?} (phantom)")),
        }
    }
}

impl std::fmt::Display for Seat {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("phantom")
    }
}

/// The length unit of a mesh file's coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Units {
    /// Millimetres, the scene's unit.
    Mm,
    /// Centimetres.
    Cm,
    /// Metres (OpenSim, many STL exports).
    M,
}

impl Units {
    /// Millimetres in one unit.
    pub fn millimetres(self) -> f64 {
        match self {
            Self::Mm => 1.0,
            Self::Cm => 10.0,
            Self::M => 1000.0,
        }
    }
}

impl std::str::FromStr for Units {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "mm" => Ok(Self::Mm),
            "cm" => Ok(Self::Cm),
            "m" => Ok(Self::M),
            _ => Err(format!("units {s:?} is not mm, cm or m")),
        }
    }
}

impl std::fmt::Display for Units {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Mm => "mm",
            Self::Cm => "cm",
            Self::M => "m",
        })
    }
}

/// Output settings.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// Image width and height in pixels.
    pub size: Option<[u32; 2]>,
    /// Opaque background colour, linear RGB.
    pub background: Option<[f32; 3]>,
    /// A transparent background instead.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub transparent: bool,
    /// Ordering for every volume (btf, wbtf, pbtf, ip-pbtf, exact, bucketed...).
    #[serde(default, with = "by_name")]
    pub ordering: Option<Ordering>,
}

/// The camera; without `eye` the scene is fitted, seen along `view_from`.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Eye position (world).
    pub eye: Option<[f64; 3]>,
    /// Look-at point; the scene centre by default.
    pub target: Option<[f64; 3]>,
    /// Up vector on screen, and the scene's up that orbits turn about; the patient's superior
    /// axis by default (anterior for a view along it).
    pub up: Option<[f64; 3]>,
    /// A named view of the patient (`anterior`, `superior`, `anterolateral-right`...; see
    /// [`crate::scene::patient::NamedView`]), fitted to the scene; instead of `eye` and `view_from`.
    pub view: Option<String>,
    /// Viewing direction used to fit the scene when no eye is given.
    pub view_from: Option<[f64; 3]>,
    /// Vertical field of view in degrees (perspective).
    pub fov: Option<f64>,
    /// Visible height in world units: makes the camera orthographic.
    pub orthographic_height: Option<f64>,
    /// Near plane distance.
    pub near: Option<f64>,
}

/// A directional light.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LightSpec {
    /// Direction the light travels.
    pub direction: [f64; 3],
    /// Linear RGB times intensity.
    pub color: [f32; 3],
}

/// Lights; absent fields keep the defaults.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LightsSpec {
    /// Headlight intensity.
    pub headlight: Option<f32>,
    /// Ambient intensity.
    pub ambient: Option<f32>,
    /// Directional lights (replace the default one when given).
    pub directional: Option<Vec<LightSpec>>,
}

/// A node transform: scale, then rotation (degrees about x, y, z in that order), then
/// translation; or a full column-major matrix.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct TransformSpec {
    /// Translation.
    pub translate: Option<[f64; 3]>,
    /// Rotation in degrees about x, then y, then z.
    pub rotate_degrees: Option<[f64; 3]>,
    /// Per-axis scale.
    pub scale: Option<[f64; 3]>,
    /// A column-major 4x4 matrix (replaces the other fields).
    pub matrix: Option<[f64; 16]>,
}

/// A volume.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct VolumeSpec {
    /// Node name.
    pub name: Option<String>,
    /// A raw file (or the first of a slice stack ending in `.1`), or `builtin:shoulder-phantom`.
    pub path: String,
    /// Raw: grid size.
    pub dims: Option<[u32; 3]>,
    /// Raw: scalar type and byte order, such as `u8`, `i16le`, `u16be`, `f32`.
    #[serde(default, with = "by_name")]
    pub scalar: Option<ScalarFormat>,
    /// Raw: bytes to skip at the start of each file.
    pub header_bytes: Option<u64>,
    /// Raw: voxel spacing in millimetres.
    pub spacing: Option<[f64; 3]>,
    /// Raw: world position of the first voxel.
    pub origin: Option<[f64; 3]>,
    /// DICOM: the series to load from a folder holding several, by SeriesNumber or
    /// SeriesInstanceUID.
    pub series: Option<String>,
    /// DICOM: load the series without its files that cannot be read (said on stderr); by
    /// default such a file is an error naming it.
    pub skip_unreadable: Option<bool>,
    /// 4-D NIfTI: the 3-D frame to draw, from 0 (the first by default, said on stderr).
    pub frame: Option<u32>,
    /// NIfTI: which transform places the grid when both are set, `sform` (the default, as
    /// nibabel), `qform`, or `itk` (ITK's and 3D Slicer's rule: the sform only when its code
    /// is 1, scanner, else the qform).
    #[serde(default, with = "by_name")]
    pub nifti_transform: Option<NiftiTransform>,
    /// A file whose format states no patient frame (VTK `.vtk`/`.vti`, `.dat`, NRRD without
    /// an anatomical `space`): the frame its coordinates are in, `RAS` (the default) or `LPS`
    /// (what ITK-based tools write). Refused for a file that states its own.
    #[serde(default, with = "by_name")]
    pub coordinate_frame: Option<CoordinateFrame>,
    /// Raw: where the index axes run in the patient frame, one letter per axis naming the
    /// side it increases toward (`RAS`, the default, puts the grid along world +x, +y, +z;
    /// `LPS`, `LPI`...; see [`crate::scene::patient`]).
    #[serde(default, with = "by_name")]
    pub orientation: Option<OrientationCode>,
    /// Transfer function: a preset (`ct-bone`, the default, `ct-soft-tissue`, `ct-metal`,
    /// `mr-default`) or `ramp` (with `window` and `color`).
    pub transfer: Option<String>,
    /// Moves the transfer function along the value axis (after `level_width`).
    pub shift: Option<f32>,
    /// Stretches the transfer function over the window `[level, width]`.
    pub level_width: Option<[f32; 2]>,
    /// The transfer function's opacities hold for this many millimetres of tissue (1 by
    /// default, whatever the voxel size).
    pub opacity_reference_mm: Option<f64>,
    /// Headlight shading of the splats from 0 (flat) to 1.
    pub shading: Option<f32>,
    /// Shell mode: only voxels with a neighbour at or below this opacity become splats.
    pub shell: Option<f32>,
    /// Ramp: transparent at the first value, `color` at the second.
    pub window: Option<[f32; 2]>,
    /// Ramp: straight RGBA at the top of the window.
    pub color: Option<[f32; 4]>,
    /// Voxels at or below this opacity are left out.
    pub min_opacity: Option<f32>,
    /// The phantom only: remove the humeral head above the resection plane.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub resect_humeral_head: bool,
    /// The phantom only: cut away the bone in front of the humeral shaft within this many
    /// millimetres of its axis (the built-in scene uses 30), so that a stem shows in its canal.
    pub cut_away_anterior_humerus: Option<f64>,
    /// Node transform.
    #[serde(default)]
    pub transform: TransformSpec,
    /// Keep only what lies inside this box, in world millimetres (it cuts every volume of the
    /// scene; one crop box per scene).
    pub crop_box: Option<BoxSpec>,
    /// Whether the crop box cuts the meshes too (it cuts only the volumes by default).
    pub clip_meshes: Option<bool>,
}

/// A box in world millimetres.
#[derive(Debug, Clone, Copy, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    /// The low corner.
    pub min: [f64; 3],
    /// The high corner.
    pub max: [f64; 3],
}

/// A clip plane: through a point, cutting away the side its normal points to; volumes always,
/// meshes when `meshes` is true.
#[derive(Debug, Clone, Copy, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ClipSpec {
    /// A point of the plane (world millimetres).
    pub through: [f64; 3],
    /// Points to the side cut away.
    pub normal: [f64; 3],
    /// Whether the plane cuts the meshes too.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub meshes: bool,
}

/// A mesh file.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MeshSpec {
    /// Node name.
    pub name: Option<String>,
    /// A glTF, OBJ or STL file, or `builtin:prosthesis`.
    pub path: String,
    /// Base colour (RGB or RGBA, linear) replacing the file's; an alpha below 1 draws the
    /// mesh translucent.
    pub color: Option<Vec<f32>>,
    /// Opacity from 0 (exclusive) to 1, multiplying the colour's alpha: below 1 the mesh is
    /// drawn translucent, over the volume, so that what lies inside shows.
    pub opacity: Option<f32>,
    /// Roughness replacing the file's.
    pub roughness: Option<f32>,
    /// Metalness replacing the file's.
    pub metallic: Option<f32>,
    /// `phantom`: seat the prosthesis in the built-in phantom's humerus (before `transform`).
    #[serde(default, with = "by_name")]
    pub seat: Option<Seat>,
    /// Length unit of the file's coordinates: `mm` (the default), `cm` or `m` (OpenSim and
    /// many STL exports are in metres); scaled to millimetres before `transform`.
    #[serde(default, with = "by_name")]
    pub units: Option<Units>,
    /// Patient frame of the file's coordinates: `RAS` (the default, the scene's) or `LPS`
    /// (DICOM's, and 3D Slicer's model export); turned to RAS before `transform`.
    #[serde(default, with = "by_name")]
    pub frame: Option<CoordinateFrame>,
    /// Node transform.
    #[serde(default)]
    pub transform: TransformSpec,
}

/// A measurement of the plan: `kind = "distance" | "angle" | "line-angle" | "point"` and its
/// 2, 3, 4 or 1 `points`, in world millimetres or, with `node`, in that node's frame (so that
/// a landmark on an implant moves with it).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MeasurementSpec {
    /// What is measured.
    pub kind: MeasureKind,
    /// The points.
    pub points: Vec<[f64; 3]>,
    /// The name written beside the value.
    pub label: Option<String>,
    /// The name of the node (a mesh or volume) whose frame the points are in.
    pub node: Option<String>,
    /// Instead of `node`, for a measurement between things: the node each point moves with,
    /// one name a point, `""` for the world (`nodes = ["prosthesis", ""]`: an implant point
    /// and a bone point).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nodes: Option<Vec<String>>,
}

/// A slice `render` draws (`[[slice]]`): the CT reformatted on a plane, the meshes' outlines
/// on it (see `crate::slice`).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SliceFileSpec {
    /// `axial`, `coronal`, `sagittal`, `implant-long` or `implant-cross`, with `@MM` along
    /// its normal where wanted (`axial@-62.5`).
    #[serde(with = "by_name_required")]
    pub plane: SliceSpec,
    /// The mesh an implant plane follows (the first mesh by default); implant planes only.
    pub mesh: Option<String>,
    /// Square pixels of this many millimetres (the volume's finest spacing by default).
    pub mm_per_pixel: Option<f64>,
}

/// [`by_name`] for a key that must be given.
mod by_name_required {
    use std::fmt::Display;
    use std::str::FromStr;

    use serde::{Deserialize, Deserializer, Serializer, de::Error};

    pub fn serialize<T: Display, S: Serializer>(value: &T, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(&value.to_string())
    }

    pub fn deserialize<'de, T, D>(d: D) -> Result<T, D::Error>
    where
        T: FromStr,
        T::Err: Display,
        D: Deserializer<'de>,
    {
        String::deserialize(d)?.parse().map_err(D::Error::custom)
    }
}

/// A whole scene file.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Output settings.
    #[serde(default)]
    pub output: OutputSpec,
    /// The camera.
    pub camera: Option<CameraSpec>,
    /// The lights.
    #[serde(default)]
    pub lights: LightsSpec,
    /// Volumes.
    #[serde(default, rename = "volume")]
    pub volumes: Vec<VolumeSpec>,
    /// Meshes.
    #[serde(default, rename = "mesh")]
    pub meshes: Vec<MeshSpec>,
    /// Measurements.
    #[serde(default, rename = "measurement", skip_serializing_if = "Vec::is_empty")]
    pub measurements: Vec<MeasurementSpec>,
    /// Clip planes.
    #[serde(default, rename = "clip", skip_serializing_if = "Vec::is_empty")]
    pub clip: Vec<ClipSpec>,
    /// Slices `render` draws when the command line names none.
    #[serde(default, rename = "slice", skip_serializing_if = "Vec::is_empty")]
    pub slices: Vec<SliceFileSpec>,
}

/// A loaded scene with the output settings of its file.
#[derive(Debug, Clone)]
pub struct LoadedScene {
    /// The scene, its camera set.
    pub scene: Scene,
    /// Image size.
    pub size: Option<(u32, u32)>,
    /// Background; `None` is transparent.
    pub background: Option<[f32; 3]>,
    /// Ordering override.
    pub ordering: Option<Ordering>,
}

/// The longest scene file read: most are a few kilobytes of TOML, and a scene that places one
/// mesh file tens of thousands of times (screws, beads, a lattice) takes about 50 bytes a node.
pub const MAX_SCENE_BYTES: u64 = 16 << 20;

impl SceneFile {
    /// Reads and parses a scene file (at most [`MAX_SCENE_BYTES`]).
    pub fn read(path: &Path) -> Result<Self, SceneFileError> {
        Self::read_with_text(path).map(|(file, _)| file)
    }

    /// Reads and parses a scene file (at most [`MAX_SCENE_BYTES`]), with the text it was read
    /// from: [`SceneFile::to_toml_over`] writes an edited file over that text.
    pub fn read_with_text(path: &Path) -> Result<(Self, String), SceneFileError> {
        let io = |source| SceneFileError::Io {
            path: path.into(),
            source,
        };
        // The length comes from the file's metadata, which a named pipe or a device cannot
        // hold up.
        let len = std::fs::metadata(path).map_err(io)?.len();
        if len > MAX_SCENE_BYTES {
            return Err(SceneFileError::Invalid {
                path: path.into(),
                message: format!("{len} bytes is too large for a scene file (16 MiB at most)"),
            });
        }
        let text = crate::input::read_regular_text(path, MAX_SCENE_BYTES).map_err(io)?;
        Self::parse(&text, path).map(|file| (file, text))
    }

    /// Parses scene TOML; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, SceneFileError> {
        let error = |message: String| SceneFileError::Parse {
            path: path.into(),
            message,
        };
        let file: Self = toml::from_str(text).map_err(|e| error(e.to_string()))?;
        // serde fills a fixed-size array from the first elements of a longer one and drops the
        // rest without a word (`size = [160, 120, 999]`): the lengths are compared with what
        // the file reads as.
        let written: toml::Value = toml::from_str(text).map_err(|e| error(e.to_string()))?;
        let read = toml::Value::try_from(&file).map_err(|e| error(e.to_string()))?;
        if let Some(message) = validate::extra_elements(&written, &read, "") {
            return Err(error(message));
        }
        Ok(file)
    }
}
