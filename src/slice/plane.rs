//! Which plane a slice lies in: the patient's axial, coronal and sagittal planes, or planes
//! along and across an implant's long axis; with the directions its image's pixels step in.

use glam::{DMat3, DVec3};

use super::SliceError;
use crate::scene::Scene;
pub use crate::scene::slice_spec::{BadSliceSpec, PlaneKind, SliceSpec};

/// A plane with the directions of its image: `right` and `down` are unit vectors in the plane,
/// the image seen looking along `right x down`; `normal` is the direction its `@MM` coordinate
/// runs (the patient's S, A or R, or the implant's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// The slice asked for.
    pub spec: SliceSpec,
    /// A point of the plane: the point the slice was asked through, moved onto the plane.
    pub point: DVec3,
    /// The unit normal, along which the plane's coordinate runs.
    pub normal: DVec3,
    /// Unit world direction of the image's +x.
    pub right: DVec3,
    /// Unit world direction of the image's +y (down the image).
    pub down: DVec3,
}

impl Plane {
    /// The plane `spec` asks for, through `through` (the camera's target) for the patient
    /// planes, through the pivot of the mesh named `mesh` (the first mesh where `None`) for
    /// the implant planes.
    ///
    /// # Errors
    ///
    /// An implant plane in a scene without that mesh, or of a mesh without a long axis (no
    /// area, or as long every way: a sphere has none).
    pub fn of(
        scene: &Scene,
        spec: SliceSpec,
        through: DVec3,
        mesh: Option<&str>,
    ) -> Result<Self, SliceError> {
        let patient = scene.patient_frame();
        let [r, a, s] = [DVec3::X, DVec3::Y, DVec3::Z].map(|d| patient.world(d));
        // (normal, right, down) for the patient planes; the along-normal coordinate is a world
        // coordinate there, a distance from the pivot for the implant planes.
        let (point, normal, right, down) = match spec.kind {
            PlaneKind::Axial => (through, s, -r, -a),
            PlaneKind::Coronal => (through, a, -r, -s),
            PlaneKind::Sagittal => (through, r, -a, -s),
            PlaneKind::ImplantLong | PlaneKind::ImplantCross => {
                let (top, name) = scene.mesh_object(mesh)?;
                let axis =
                    long_axis(&scene.object_triangles(top)).ok_or(SliceError::NoLongAxis(name))?;
                // The axis's superior end up.
                let axis = if axis.dot(s) < 0.0 { -axis } else { axis };
                let (pivot, _) = scene.pivot(top);
                let square = |d: DVec3, fallback: DVec3| {
                    (d - axis * d.dot(axis))
                        .try_normalize()
                        .or_else(|| (fallback - axis * fallback.dot(axis)).try_normalize())
                        .unwrap_or_else(|| axis.any_orthonormal_vector())
                };
                let (normal, right, down) = if spec.kind == PlaneKind::ImplantLong {
                    let normal = square(a, -r);
                    (normal, axis.cross(normal), -axis)
                } else {
                    let right = square(-r, -a);
                    (axis, right, axis.cross(right))
                };
                let point = pivot + normal * spec.at_mm.unwrap_or(0.0);
                return Ok(Self {
                    spec,
                    point,
                    normal,
                    right,
                    down,
                });
            }
        };
        let point = match spec.at_mm {
            Some(at) => point + normal * (at - point.dot(normal)),
            None => point,
        };
        Ok(Self {
            spec,
            point,
            normal,
            right,
            down,
        })
    }

    /// The signed distance of `p` from the plane, along the normal.
    pub fn distance(&self, p: DVec3) -> f64 {
        (p - self.point).dot(self.normal)
    }

    /// The coordinate of the plane along its normal (for the patient planes, the `@MM` that
    /// names it).
    pub fn offset(&self) -> f64 {
        self.point.dot(self.normal)
    }
}

/// The long axis of a surface: the principal axis of its area (each triangle's second moment
/// integrated exactly, so that the axis does not depend on how the surface is tessellated).
/// `None` for a surface without area, or one with no single longest direction (the two
/// largest principal moments within 1% of each other).
pub fn long_axis(triangles: &[[DVec3; 3]]) -> Option<DVec3> {
    let mut area = 0.0;
    let mut first = DVec3::ZERO;
    let mut second = DMat3::ZERO;
    for [a, b, c] in triangles {
        let w = 0.5 * (*b - *a).cross(*c - *a).length();
        if !(w.is_finite() && w > 0.0) {
            continue;
        }
        let sum = *a + *b + *c;
        area += w;
        first += w * sum / 3.0;
        // Over a triangle, the mean of x x^T is (a a^T + b b^T + c c^T + s s^T) / 12, s the
        // sum of its corners.
        second += (outer(*a) + outer(*b) + outer(*c) + outer(sum)) * (w / 12.0);
    }
    if area <= 0.0 {
        return None;
    }
    let mean = first / area;
    let covariance = second * (1.0 / area) - outer(mean);
    let (values, vectors) = symmetric_eigen(covariance);
    // The eigenvalues sorted greatest first.
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| values[j].total_cmp(&values[i]));
    let (l0, l1) = (values[order[0]], values[order[1]]);
    if l0.is_nan() || l0 <= 0.0 || l1 > 0.99 * l0 {
        return None;
    }
    vectors[order[0]].try_normalize()
}

fn outer(v: DVec3) -> DMat3 {
    DMat3::from_cols(v * v.x, v * v.y, v * v.z)
}

/// Eigenvalues and unit eigenvectors of a symmetric 3x3 matrix, by cyclic Jacobi rotations
/// (glam has no eigensolver, and a linear-algebra crate for one 3x3 matrix is more than the
/// twenty lines it takes; Jacobi is exact to rounding for symmetric matrices).
pub(crate) fn symmetric_eigen(m: DMat3) -> ([f64; 3], [DVec3; 3]) {
    let mut a = m.to_cols_array_2d();
    let mut v = DMat3::IDENTITY.to_cols_array_2d();
    for _ in 0..50 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        let scale = a[0][0].powi(2) + a[1][1].powi(2) + a[2][2].powi(2);
        if off <= 1e-30 * scale.max(f64::MIN_POSITIVE) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // a <- J^T a J, v <- v J, J the rotation in the (p, q) plane.
            for row in &mut a {
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            let (rp, rq) = (a[p], a[q]);
            for k in 0..3 {
                a[p][k] = c * rp[k] - s * rq[k];
                a[q][k] = s * rp[k] + c * rq[k];
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    // `v` holds the eigenvectors as its columns in the array's second index.
    let vectors = std::array::from_fn(|i| DVec3::new(v[0][i], v[1][i], v[2][i]));
    ([a[0][0], a[1][1], a[2][2]], vectors)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eigenvectors_of_a_turned_diagonal_matrix() {
        let turn = glam::DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1);
        let r = DMat3::from_quat(turn);
        let m = r * DMat3::from_diagonal(DVec3::new(9.0, 4.0, 1.0)) * r.transpose();
        let (values, vectors) = symmetric_eigen(m);
        for (value, vector) in values.iter().zip(vectors) {
            assert!((m * vector - vector * *value).length() < 1e-9, "{value}");
        }
        let mut sorted = values;
        sorted.sort_by(f64::total_cmp);
        assert!((sorted[0] - 1.0).abs() < 1e-9 && (sorted[2] - 9.0).abs() < 1e-9);
    }
}
