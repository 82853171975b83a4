//! A deterministic CT-like phantom of a right shoulder, for prosthesis-planning scenes without
//! patient data.
//!
//! Values are Hounsfield units: air -1000 outside a rounded body envelope, a thin subcutaneous
//! fat layer (-90) over soft tissue (45); the proximal humerus (a spherical head with a thin
//! cortical shell over textured cancellous bone, an anatomical neck, a greater tuberosity, and a
//! shaft whose thick cortical wall surrounds a marrow-filled canal); and the glenoid of the
//! scapula across the joint space: a shallow pear-shaped cup with a cortical rim, a scapular
//! neck and a plate-like body going medially.
//!
//! Every tissue is a smooth signed distance (millimetres, negative inside) evaluated at voxel
//! centres, with a 0.6 mm smooth step at each boundary standing in for partial volume, so that
//! gradients are smooth. The only irregularity is a value noise from a fixed integer hash.
//!
//! **World frame** (millimetres, RAS): origin at voxel (0, 0, 0), grid axes along the world
//! axes; +x is lateral (patient right, from the glenoid toward the humeral head), +y anterior,
//! +z superior. The anatomy keeps its size in millimetres: the humeral head sits a fixed
//! distance from the lateral and top faces of the volume, centred front to back, so a smaller
//! grid crops the scapula and the shaft rather than shrinking anything.

use glam::{DMat3, DVec3};

use super::CpuVolume;
use crate::grid::voxel_count;

/// Grid size of [`shoulder_phantom_default`]: about one million voxels.
pub const DEFAULT_DIMS: [u32; 3] = [112, 80, 112];
/// Voxel spacing of [`shoulder_phantom_default`], in millimetres.
pub const DEFAULT_SPACING: [f64; 3] = [0.85, 0.85, 1.0];

const AIR: f64 = -1000.0;
const FAT: f64 = -90.0;
const SOFT_TISSUE: f64 = 45.0;
const MARROW: f64 = 40.0;
const CANCELLOUS: f64 = 325.0;
const CORTICAL: f64 = 1400.0;

const FAT_DEPTH: f64 = 4.0;
const HEAD_RADIUS: f64 = 22.0;
/// The anatomical-neck plane lies this far from the head centre, toward the shaft, so the
/// articular cap is a little more than a hemisphere.
const NECK_OFFSET: f64 = 6.0;
/// The shaft axis lies lateral of the head centre (the head's medial offset).
const SHAFT_OFFSET: f64 = 7.0;
const SHAFT_RADIUS: f64 = 11.0;
/// The shaft widens by this much toward the head (the metaphysis).
const METAPHYSIS_FLARE: f64 = 5.0;
const CANAL_RADIUS: f64 = 7.5;
/// The canal's rounded top lies this far below the head centre; above it is cancellous bone.
const CANAL_TOP_DEPTH: f64 = 27.5;
const TUBEROSITY_RADIUS: f64 = 10.0;
const JOINT_SPACE: f64 = 4.0;
/// Larger than the head's radius + joint space, so the joint space widens toward the glenoid
/// rim as in real shoulders.
const CUP_RADIUS: f64 = 28.0;
const SCAPULA_CORTEX: f64 = 1.5;
/// Half-width of the smooth step at every tissue boundary.
const EDGE: f64 = 0.3;

/// Anatomical landmarks of the phantom, in world millimetres, for seating a prosthesis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShoulderLandmarks {
    /// Centre of the spherical humeral head.
    pub head_centre: [f64; 3],
    /// Radius of the humeral head (outer surface).
    pub head_radius: f64,
    /// Upper end of the humeral shaft axis: where the marrow canal opens into the cancellous
    /// metaphysis. The axis is vertical.
    pub shaft_axis_top: [f64; 3],
    /// Lower end of the shaft axis, on the lowest voxel plane (z = 0).
    pub shaft_axis_bottom: [f64; 3],
    /// Radius of the marrow canal (inner radius of the shaft's cortical wall).
    pub canal_radius: f64,
    /// Deepest point of the glenoid's articular surface.
    pub glenoid_centre: [f64; 3],
    /// Unit normal of the glenoid face, pointing out of the bone toward the humeral head.
    pub glenoid_normal: [f64; 3],
    /// A point on the anatomical-neck plane (the head-resection plane), on the head's axis.
    pub neck_centre: [f64; 3],
    /// Unit normal of the anatomical-neck plane, pointing into the articular head
    /// (medial-superior, 45 degrees from the shaft: a neck-shaft angle of 135 degrees).
    pub neck_normal: [f64; 3],
}

/// The phantom's shapes, placed for one grid.
struct Anatomy {
    head: DVec3,
    neck_normal: DVec3,
    /// A point on the shaft axis at the height of the head centre.
    shaft: DVec3,
    tuberosity: DVec3,
    glenoid: DVec3,
    glenoid_normal: DVec3,
    glenoid_up: DVec3,
    glenoid_side: DVec3,
    plate_origin: DVec3,
    plate_along: DVec3,
    plate_across: DVec3,
    skin_lo: DVec3,
    skin_hi: DVec3,
}

impl Anatomy {
    fn new(dims: [u32; 3], spacing: [f64; 3]) -> Self {
        let extent = DVec3::from_array(std::array::from_fn(|a| {
            f64::from(dims[a].max(1) - 1) * spacing[a]
        }));
        let head = DVec3::new(extent.x - 36.0, 0.5 * extent.y, extent.z - 38.0);
        let shaft = head + SHAFT_OFFSET * DVec3::X;
        let glenoid_normal = DVec3::new(1.0, 0.12, 0.08).normalize();
        let glenoid = head - (HEAD_RADIUS + JOINT_SPACE) * glenoid_normal;
        let glenoid_side = DVec3::Z.cross(glenoid_normal).normalize();
        // The scapular body runs medially and backwards over the chest wall.
        let plate_along = DVec3::new(-1.0, -0.45, 0.0).normalize();
        let skin_top = (head.z + HEAD_RADIUS + 10.0).min(extent.z - 3.0);
        Self {
            head,
            neck_normal: DVec3::new(-1.0, 0.0, 1.0).normalize(),
            shaft,
            tuberosity: shaft + DVec3::new(8.0, 3.0, 2.0),
            glenoid,
            glenoid_normal,
            glenoid_up: glenoid_normal.cross(glenoid_side),
            glenoid_side,
            plate_origin: glenoid - 14.0 * glenoid_normal,
            plate_along,
            plate_across: plate_along.cross(DVec3::Z),
            // The body continues medially and downwards beyond the volume.
            skin_lo: DVec3::new(-500.0, 3.0, -500.0),
            skin_hi: DVec3::new(extent.x - 3.0, extent.y - 3.0, skin_top),
        }
    }

    /// Hounsfield value at world point `p`.
    fn hu(&self, p: DVec3) -> f64 {
        let skin = rounded_box(p, self.skin_lo, self.skin_hi, 16.0);
        if skin > EDGE {
            return AIR;
        }
        let tissue = mix(FAT, SOFT_TISSUE, inside(skin + FAT_DEPTH));
        let mut value = mix(AIR, tissue, inside(skin));
        let humerus = self.humerus(p);
        if humerus < EDGE {
            let (cortex, interior) = self.humerus_interior(p);
            value = bone(value, humerus, cortex, interior);
        }
        let scapula = self.scapula(p);
        if scapula < EDGE {
            value = bone(value, scapula, SCAPULA_CORTEX, cancellous(p));
        }
        value
    }

    fn humerus(&self, p: DVec3) -> f64 {
        let rel = p - self.head;
        let cap = smooth_max(
            rel.length() - HEAD_RADIUS,
            -NECK_OFFSET - rel.dot(self.neck_normal),
            4.0,
        );
        let radial = (p - self.shaft).truncate().length();
        let flare = METAPHYSIS_FLARE * smoothstep(self.head.z - 45.0, self.head.z - 5.0, p.z);
        let column = (radial - SHAFT_RADIUS - flare).max(rel.z);
        let tuberosity = (p - self.tuberosity).length() - TUBEROSITY_RADIUS;
        smooth_min(smooth_min(cap, column, 8.0), tuberosity, 5.0)
    }

    /// Cortical thickness and the value inside the cortex at `p`.
    fn humerus_interior(&self, p: DVec3) -> (f64, f64) {
        // The head's thin shell thickens into the shaft's wall below the surgical neck.
        let cortex = mix(
            2.0,
            3.5,
            smoothstep(self.head.z - 25.0, self.head.z - 40.0, p.z),
        );
        let radial = (p - self.shaft).truncate().length();
        let above_canal = p.z - (self.head.z - CANAL_TOP_DEPTH - CANAL_RADIUS);
        let canal = if above_canal > 0.0 {
            radial.hypot(above_canal)
        } else {
            radial
        } - CANAL_RADIUS;
        (cortex, mix(cancellous(p), MARROW, inside(canal)))
    }

    fn scapula(&self, p: DVec3) -> f64 {
        let q = p - self.glenoid;
        let depth = -q.dot(self.glenoid_normal);
        let (u, v) = (q.dot(self.glenoid_up), q.dot(self.glenoid_side));
        let cup_centre = self.glenoid + CUP_RADIUS * self.glenoid_normal;
        let cup = CUP_RADIUS - (p - cup_centre).length();
        // The pear outline narrows from the glenoid face into the scapular neck.
        let scale = mix(1.0, 0.65, smoothstep(5.0, 16.0, depth));
        let outline = scale * pear(u / scale, v / scale);
        let vault = outline.max(cup).max(-depth - 7.0).max(depth - 24.0);
        let r = p - self.plate_origin;
        let across = r.dot(self.plate_across).abs() - 2.6;
        let plate = across
            .max(-r.dot(self.plate_along))
            .max(r.z - 18.0)
            .max(-r.z - 45.0);
        smooth_min(vault, plate, 5.0)
    }

    fn landmarks(&self) -> ShoulderLandmarks {
        let axis_at = |z| DVec3::new(self.shaft.x, self.shaft.y, z).to_array();
        ShoulderLandmarks {
            head_centre: self.head.to_array(),
            head_radius: HEAD_RADIUS,
            shaft_axis_top: axis_at(self.head.z - CANAL_TOP_DEPTH),
            shaft_axis_bottom: axis_at(0.0),
            canal_radius: CANAL_RADIUS,
            glenoid_centre: self.glenoid.to_array(),
            glenoid_normal: self.glenoid_normal.to_array(),
            neck_centre: (self.head - NECK_OFFSET * self.neck_normal).to_array(),
            neck_normal: self.neck_normal.to_array(),
        }
    }
}

/// The glenoid outline in its own plane (`u` superior, `v` across): wider below than above.
fn pear(u: f64, v: f64) -> f64 {
    let lower = (u + 5.0).hypot(v) - 12.5;
    let upper = (u - 9.0).hypot(v) - 8.0;
    smooth_min(lower, upper, 6.0)
}

/// Cortical shell of thickness `cortex` over `interior`, blended into `around` at the surface.
fn bone(around: f64, distance: f64, cortex: f64, interior: f64) -> f64 {
    let solid = mix(CORTICAL, interior, inside(distance + cortex));
    mix(around, solid, inside(distance))
}

/// Trabecular texture: value noise at two scales, so cancellous bone is not flat.
fn cancellous(p: DVec3) -> f64 {
    CANCELLOUS + 45.0 * value_noise(p / 1.7) + 20.0 * value_noise(p / 0.6 + 17.0)
}

/// Smoothly interpolated lattice noise in [-1, 1].
fn value_noise(p: DVec3) -> f64 {
    let cell = p.floor();
    let f = p - cell;
    let w = f * f * (3.0 - 2.0 * f);
    let c = cell.as_ivec3();
    let corner = |dx, dy, dz| lattice_hash(c.x + dx, c.y + dy, c.z + dz);
    let along_x = |dy, dz| mix(corner(0, dy, dz), corner(1, dy, dz), w.x);
    let along_y = |dz| mix(along_x(0, dz), along_x(1, dz), w.y);
    mix(along_y(0), along_y(1), w.z)
}

/// A fixed integer hash of a lattice point, mapped to [-1, 1].
fn lattice_hash(x: i32, y: i32, z: i32) -> f64 {
    let mut h = (x as u32).wrapping_mul(0x8da6_b343)
        ^ (y as u32).wrapping_mul(0xd816_3841)
        ^ (z as u32).wrapping_mul(0xcb1a_b31f);
    h ^= h >> 16;
    h = h.wrapping_mul(0x7feb_352d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x846c_a68b);
    h ^= h >> 16;
    f64::from(h) / f64::from(u32::MAX) * 2.0 - 1.0
}

/// Signed distance to an axis-aligned box with edges rounded by `radius`.
fn rounded_box(p: DVec3, lo: DVec3, hi: DVec3, radius: f64) -> f64 {
    let q = (p - 0.5 * (lo + hi)).abs() - 0.5 * (hi - lo) + radius;
    q.max(DVec3::ZERO).length() + q.max_element().min(0.0) - radius
}

/// A union of two distances with the crease rounded over `k` millimetres.
fn smooth_min(a: f64, b: f64, k: f64) -> f64 {
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - 0.25 * k * h * h
}

/// An intersection of two distances with the edge rounded over `k` millimetres.
fn smooth_max(a: f64, b: f64, k: f64) -> f64 {
    -smooth_min(-a, -b, k)
}

/// 1 well inside a shape (distance below -EDGE), 0 well outside.
fn inside(distance: f64) -> f64 {
    smoothstep(EDGE, -EDGE, distance)
}

fn smoothstep(from: f64, to: f64, x: f64) -> f64 {
    let t = ((x - from) / (to - from)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn mix(a: f64, b: f64, t: f64) -> f64 {
    a + (b - a) * t
}

/// The shoulder phantom on a `dims` grid with `spacing` (mm), origin at zero and axes along the
/// world axes (see the module documentation for the frame and the tissues).
///
/// # Panics
///
/// If the grid has an empty axis or more than 2^32 voxels (see [`voxel_count`]).
pub fn shoulder_phantom(dims: [u32; 3], spacing: [f64; 3]) -> CpuVolume {
    let count =
        voxel_count(dims).expect("the phantom grid must be non-empty with at most 2^32 voxels");
    let anatomy = Anatomy::new(dims, spacing);
    let mut values = Vec::with_capacity(count as usize);
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let k = DVec3::new(f64::from(x), f64::from(y), f64::from(z));
                values.push(anatomy.hu(k * DVec3::from_array(spacing)) as f32);
            }
        }
    }
    CpuVolume {
        dims,
        spacing,
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values: values.into(),
    }
}

/// The phantom at [`DEFAULT_DIMS`] and [`DEFAULT_SPACING`] (94 x 67 x 111 mm).
pub fn shoulder_phantom_default() -> CpuVolume {
    shoulder_phantom(DEFAULT_DIMS, DEFAULT_SPACING)
}

/// The landmarks of [`shoulder_phantom`] for the same `dims` and `spacing`.
pub fn shoulder_landmarks(dims: [u32; 3], spacing: [f64; 3]) -> ShoulderLandmarks {
    Anatomy::new(dims, spacing).landmarks()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The value of the voxel whose centre is nearest to world point `p`.
    fn nearest(volume: &CpuVolume, p: DVec3) -> f32 {
        let k: [usize; 3] = std::array::from_fn(|a| {
            let i = (p[a] / volume.spacing[a])
                .round()
                .clamp(0.0, f64::from(volume.dims[a] - 1));
            i as usize
        });
        let [nx, ny, _] = volume.dims.map(|n| n as usize);
        volume.values.at(k[0] + nx * (k[1] + ny * k[2]))
    }

    type Probe = (&'static str, DVec3, [f32; 2]);

    /// Points around the landmarks with the Hounsfield range each must fall in.
    fn probes(marks: &ShoulderLandmarks) -> Vec<Probe> {
        let at = DVec3::from_array;
        let (head, radius) = (at(marks.head_centre), marks.head_radius);
        let (glenoid, normal) = (at(marks.glenoid_centre), at(marks.glenoid_normal));
        let (top, bottom) = (at(marks.shaft_axis_top), at(marks.shaft_axis_bottom));
        let low = bottom + 10.0 * DVec3::Z;
        let far = DEFAULT_DIMS.map(|n| f64::from(n - 1));
        let (cancellous, cortical, soft) = ([250.0, 400.0], [1200.0, 1500.0], [0.0, 100.0]);
        vec![
            ("head centre", head, cancellous),
            (
                "head surface facing the glenoid",
                head - (radius - 1.0) * normal,
                cortical,
            ),
            (
                "articular apex",
                head + (radius - 1.0) * at(marks.neck_normal),
                cortical,
            ),
            ("joint space", head - (radius + 2.0) * normal, soft),
            ("joint space at the glenoid", glenoid + 2.0 * normal, soft),
            ("glenoid face", glenoid - 0.8 * normal, cortical),
            ("glenoid vault", glenoid - 6.0 * normal, cancellous),
            ("anatomical neck centre", at(marks.neck_centre), cancellous),
            ("low in the canal", bottom.lerp(top, 0.1), [20.0, 60.0]),
            (
                "shaft wall",
                low + (marks.canal_radius + 1.8) * DVec3::X,
                cortical,
            ),
            ("beside the shaft", low + 14.0 * DVec3::X, soft),
            ("corner at the origin", DVec3::ZERO, [-1000.0; 2]),
            ("far corner", at(far) * at(DEFAULT_SPACING), [-1000.0; 2]),
        ]
    }

    #[test]
    fn landmarks_sit_in_the_right_tissues() {
        let volume = shoulder_phantom_default();
        let anatomy = Anatomy::new(DEFAULT_DIMS, DEFAULT_SPACING);
        for (what, p, [lo, hi]) in probes(&shoulder_landmarks(DEFAULT_DIMS, DEFAULT_SPACING)) {
            // Both the shape functions at the exact point and the sampled volume.
            let exact = anatomy.hu(p) as f32;
            let voxel = nearest(&volume, p);
            assert!(
                (lo..=hi).contains(&exact),
                "{what} at {p}: value {exact} not in {lo}..={hi}"
            );
            assert!(
                (lo..=hi).contains(&voxel),
                "{what} at {p}: voxel {voxel} not in {lo}..={hi}"
            );
        }
    }

    #[test]
    fn bone_is_a_plausible_share_of_the_volume() {
        let volume = shoulder_phantom_default();
        assert_eq!(volume.values.len(), 112 * 80 * 112);
        let bone = volume.values.iter().filter(|&v| v > 300.0).count();
        let share = bone as f64 / volume.values.len() as f64;
        println!(
            "phantom: {bone} of {} voxels above 300 HU ({:.1}%)",
            volume.values.len(),
            100.0 * share
        );
        assert!((0.02..=0.25).contains(&share), "bone share {share}");
        let (lo, hi) = volume
            .values
            .iter()
            .fold((f32::MAX, f32::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
        assert_eq!(lo, -1000.0);
        assert!((1300.0..=1500.0).contains(&hi), "brightest voxel {hi}");
    }

    #[test]
    fn same_inputs_give_the_same_volume_and_tiny_grids_work() {
        let a = shoulder_phantom([24, 20, 28], [3.2, 3.5, 4.0]);
        assert_eq!(a, shoulder_phantom([24, 20, 28], [3.2, 3.5, 4.0]));
        assert!(
            a.values.iter().any(|v| v > 1000.0),
            "coarse grid still shows cortex"
        );
        assert_eq!(shoulder_phantom([1, 1, 1], [1.0; 3]).values.len(), 1);
        let noise: Vec<f64> = (0..50)
            .map(|i| value_noise(DVec3::splat(f64::from(i) * 0.37)))
            .collect();
        assert!(noise.iter().all(|n| (-1.0..=1.0).contains(n)));
        assert!(noise.iter().any(|&n| n > 0.2) && noise.iter().any(|&n| n < -0.2));
    }
}
