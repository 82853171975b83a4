//! What an implant's surface touches: the volume sampled on a mesh's surface (trilinear,
//! area-weighted), its area split by classes of value (for CT: soft tissue or air, cancellous
//! bone, cortical bone), and the least, mean and greatest value under it. 3D Slicer's "Probe
//! volume with model" colours a model by the volume under its vertices; this integrates over
//! the surface instead, so that the answer does not depend on how the mesh is tessellated.
//!
//! Each triangle is cut into `n x n` equal triangles, `n` its longest edge over the sample
//! spacing (half the volume's finest spacing, coarser where the surface would take more than
//! [`MAX_SAMPLES`] samples), and each small triangle weighs its area at its centroid's value.
//! Samples outside the volume's grid are counted apart (`outside_mm2`), never as a value.

use glam::DVec3;
use serde::Serialize;
use thiserror::Error;

use crate::geometry::{GeometryError, VolumeGeometry};
use crate::scene::{ObjectError, Scene, placed_geometry};
use crate::volume::CpuVolume;

/// The most samples one surface takes: 4M trilinear reads, a fraction of a second here.
pub const MAX_SAMPLES: u64 = 4 << 20;

/// Value classes: `edges` cut the values into `edges.len() + 1` classes, class `i` holding the
/// values from `edges[i - 1]` (inclusive) to `edges[i]` (exclusive), the first and last open.
#[derive(Debug, Clone, PartialEq)]
pub struct Classes {
    edges: Vec<f64>,
    names: Vec<String>,
}

impl Classes {
    /// CT in Hounsfield units: below 200 soft tissue or air, 200 to 700 cancellous bone, 700
    /// and above cortical bone (the thresholds planning tools commonly take for the humerus;
    /// cortical bone reads 700-2000 HU, cancellous 200-700).
    pub fn ct() -> Self {
        Self {
            edges: vec![200.0, 700.0],
            names: vec![
                "soft tissue or air".into(),
                "cancellous bone".into(),
                "cortical bone".into(),
            ],
        }
    }

    /// Classes cut at `edges`, named by their ranges (`below 200`, `200 to 700`, `700 and
    /// above`).
    ///
    /// # Errors
    ///
    /// When an edge is not finite, or the edges do not increase.
    pub fn from_edges(edges: &[f64]) -> Result<Self, ContactError> {
        if edges.is_empty()
            || edges.iter().any(|e| !e.is_finite())
            || edges.windows(2).any(|w| w[0] >= w[1])
        {
            return Err(ContactError::BadEdges(edges.to_vec()));
        }
        let mut names = vec![format!("below {}", edges[0])];
        names.extend(edges.windows(2).map(|w| format!("{} to {}", w[0], w[1])));
        names.push(format!("{} and above", edges[edges.len() - 1]));
        Ok(Self {
            edges: edges.to_vec(),
            names,
        })
    }

    /// The classes a volume gets by default: [`Classes::ct`] for CT (values in Hounsfield
    /// units, air at -1000), none for other data (whose values mean nothing fixed).
    pub fn for_volume(volume: &CpuVolume) -> Self {
        if crate::classify::is_hounsfield(&volume.values) {
            Self::ct()
        } else {
            Self::none()
        }
    }

    /// Whether there are no classes.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// No classes: the value under the surface alone.
    pub fn none() -> Self {
        Self {
            edges: Vec::new(),
            names: Vec::new(),
        }
    }

    /// The class of `value`, or `None` where there are no classes.
    fn of(&self, value: f64) -> Option<usize> {
        (!self.names.is_empty()).then(|| self.edges.partition_point(|&e| e <= value))
    }
}

/// Why a contact could not be measured.
#[derive(Debug, Error)]
pub enum ContactError {
    /// The mesh asked for is not in the scene, or there is none.
    #[error(transparent)]
    Mesh(#[from] ObjectError),
    /// The scene has no volume to sample.
    #[error("the scene has no volume to sample under the mesh")]
    NoVolume,
    /// Class edges that are not finite and increasing.
    #[error("class edges {0:?} must be finite and increasing")]
    BadEdges(Vec<f64>),
    /// The volume's placement has no inverse.
    #[error("the volume cannot be placed: {0}")]
    Geometry(#[from] GeometryError),
}

/// The surface area whose value falls in one class.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClassArea {
    /// The class's name.
    pub name: String,
    /// Its lowest value (inclusive); `None` for the first class.
    pub min: Option<f64>,
    /// Its highest value (exclusive); `None` for the last class.
    pub max: Option<f64>,
    /// The area in square millimetres.
    pub area_mm2: f64,
    /// The share of the whole surface (outside parts included).
    pub fraction: f64,
}

/// The least, area-weighted mean and greatest value under a surface.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ValueStats {
    /// The least value sampled.
    pub min: f64,
    /// The mean, weighted by area.
    pub mean: f64,
    /// The greatest value sampled.
    pub max: f64,
}

/// A mesh's contact with a volume.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Contact {
    /// The mesh's node name.
    pub mesh: String,
    /// The volume's node name.
    pub volume: String,
    /// The surface area in square millimetres.
    pub area_mm2: f64,
    /// The area lying outside the volume's grid.
    pub outside_mm2: f64,
    /// Its share of the surface.
    pub outside_fraction: f64,
    /// The area in each value class, in the classes' order.
    pub classes: Vec<ClassArea>,
    /// The value under the surface inside the volume; `None` where none of it is inside.
    pub value: Option<ValueStats>,
    /// How many points were sampled.
    pub samples: u64,
    /// The distance between samples along a triangle's longest edge, in millimetres.
    pub sample_mm: f64,
}

/// The contact of the mesh named `mesh` (a node holding meshes, itself or below it; the first
/// such top node where `None`) with the scene's first volume, split by `classes`.
///
/// # Errors
///
/// When the mesh or the volume is missing, or the volume cannot be placed.
pub fn contact(
    scene: &Scene,
    mesh: Option<&str>,
    classes: &Classes,
) -> Result<Contact, ContactError> {
    let (top, mesh_name) = scene.mesh_object(mesh)?;
    let (volume_id, node, world) = scene.volumes().next().ok_or(ContactError::NoVolume)?;
    let geometry = placed_geometry(&node.volume, world)?;
    let triangles = scene.object_triangles(top);
    let min_spacing = node.volume.finest_spacing();
    let mut step = 0.5 * min_spacing;
    let count = |step: f64| -> u64 { triangles.iter().map(|t| subdivisions(t, step).pow(2)).sum() };
    let wanted = count(step);
    if wanted > MAX_SAMPLES {
        // n^2 samples a triangle: a step sqrt(wanted / budget) times longer fits the budget
        // (a little over, from rounding n up; then once more).
        step *= (wanted as f64 / MAX_SAMPLES as f64).sqrt();
        while count(step) > MAX_SAMPLES {
            step *= 1.1;
        }
    }
    let mut sums = Sums::new(classes);
    for t in &triangles {
        sample_triangle(t, step, &node.volume, &geometry, classes, &mut sums);
    }
    let area = sums.inside + sums.outside;
    let share = |a: f64| if area > 0.0 { a / area } else { 0.0 };
    let class_areas = classes
        .names
        .iter()
        .enumerate()
        .map(|(i, name)| ClassArea {
            name: name.clone(),
            min: i.checked_sub(1).map(|j| classes.edges[j]),
            max: classes.edges.get(i).copied(),
            area_mm2: sums.classes[i],
            fraction: share(sums.classes[i]),
        })
        .collect();
    let value = (sums.inside > 0.0).then(|| ValueStats {
        min: sums.min,
        mean: sums.weighted / sums.inside,
        max: sums.max,
    });
    Ok(Contact {
        mesh: mesh_name,
        volume: scene
            .node(volume_id)
            .map_or_else(|_| "volume".into(), |n| n.name.clone()),
        area_mm2: area,
        outside_mm2: sums.outside,
        outside_fraction: share(sums.outside),
        classes: class_areas,
        value,
        samples: sums.samples,
        sample_mm: step,
    })
}

/// How many parts each edge of triangle `t` is cut into for samples `step` apart.
fn subdivisions(t: &[DVec3; 3], step: f64) -> u64 {
    let longest = [
        t[0].distance(t[1]),
        t[1].distance(t[2]),
        t[2].distance(t[0]),
    ]
    .into_iter()
    .fold(0.0, f64::max);
    if longest.is_finite() {
        ((longest / step).ceil() as u64).max(1)
    } else {
        1
    }
}

/// What the samples add up to.
struct Sums {
    inside: f64,
    outside: f64,
    weighted: f64,
    min: f64,
    max: f64,
    classes: Vec<f64>,
    samples: u64,
}

impl Sums {
    fn new(classes: &Classes) -> Self {
        Self {
            inside: 0.0,
            outside: 0.0,
            weighted: 0.0,
            min: f64::INFINITY,
            max: f64::NEG_INFINITY,
            classes: vec![0.0; classes.names.len()],
            samples: 0,
        }
    }
}

/// Samples triangle `t` at the centroids of its `n x n` equal parts.
fn sample_triangle(
    t: &[DVec3; 3],
    step: f64,
    volume: &CpuVolume,
    geometry: &VolumeGeometry,
    classes: &Classes,
    sums: &mut Sums,
) {
    let (u, v) = (t[1] - t[0], t[2] - t[0]);
    let area = 0.5 * u.cross(v).length();
    if !(area > 0.0 && area.is_finite()) {
        return;
    }
    let n = subdivisions(t, step);
    let part = area / (n * n) as f64;
    let nf = n as f64;
    let dims = geometry.dims().map(f64::from);
    let mut take = |a: f64, b: f64| {
        let p = t[0] + u * (a / nf) + v * (b / nf);
        let k = geometry.world_to_index(p);
        sums.samples += 1;
        // Inside the grid's box: half a voxel beyond the outer centres.
        let inside = (0..3).all(|i| k[i] >= -0.5 && k[i] <= dims[i] - 0.5);
        if !inside {
            sums.outside += part;
            return;
        }
        let value = f64::from(volume.trilinear(k.to_array()));
        sums.inside += part;
        sums.weighted += part * value;
        sums.min = sums.min.min(value);
        sums.max = sums.max.max(value);
        if let Some(c) = classes.of(value) {
            sums.classes[c] += part;
        }
    };
    // Parts pointing up, at (i + 1/3, j + 1/3); pointing down, at (i + 2/3, j + 2/3), in units
    // of an edge's n-th along u and v.
    for i in 0..n {
        for j in 0..n - i {
            let (a, b) = (i as f64, j as f64);
            take(a + 1.0 / 3.0, b + 1.0 / 3.0);
            if i + j + 1 < n {
                take(a + 2.0 / 3.0, b + 2.0 / 3.0);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn classes_are_cut_at_increasing_edges() {
        let c = Classes::from_edges(&[200.0, 700.0]).unwrap();
        assert_eq!(c.names, ["below 200", "200 to 700", "700 and above"]);
        assert_eq!(c.of(-1000.0), Some(0));
        assert_eq!(c.of(200.0), Some(1));
        assert_eq!(c.of(699.9), Some(1));
        assert_eq!(c.of(700.0), Some(2));
        for bad in [&[][..], &[700.0, 200.0], &[1.0, 1.0], &[f64::NAN]] {
            assert!(Classes::from_edges(bad).is_err(), "{bad:?}");
        }
        assert_eq!(Classes::none().of(5.0), None);
    }
}
