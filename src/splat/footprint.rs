//! A splat's footprint on the screen: the EWA projection of its Gaussian (Zwicker et al.
//! 2002, the local affine approximation of the perspective map) with a pixel's variance added
//! (Mip-Splatting's 2-D filter, Yu et al. 2024). One function, generic over the float type, for
//! the reference compositor (f64), the tile compositor (f32) and the splat shader, which
//! mirrors it line by line in `shaders/footprint.wgsl` (held to it by `tests/footprint.rs`).
//!
//! The tile compositor's AVX2 projection (`tiled::simd`) computes the same formulas expanded
//! for eight splats a vector; its unit tests hold it to this function.

use num_traits::Float;

/// What a splat's footprint is on the screen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Footprint<T> {
    /// Centre in pixels (x right, y down from the top-left corner of the image).
    pub centre: [T; 2],
    /// The screen covariance `[[a, b], [b, c]]` in pixels squared, the pixel variance added,
    /// as `[a, b, c]`.
    pub cov: [T; 3],
    /// The share of the splat's opacity the widened footprint keeps, so that its integral
    /// over the image is the unwidened footprint's: `sqrt(det S / det(S + v I))`, at most 1
    /// (Yu et al. 2024, eq. 8). A splat smaller than a pixel covers it with the opacity it
    /// would have spread over its own area.
    pub kept: T,
}

impl<T: Float> Footprint<T> {
    /// The inverse of the screen covariance (the conic), `[a', b', c']` with
    /// `q = a' dx^2 + 2 b' dx dy + c' dy^2` the Gaussian's exponent (times -2) at pixel offset
    /// `(dx, dy)` from the centre.
    #[inline(always)]
    pub fn conic(&self) -> [T; 3] {
        let [a, b, c] = self.cov;
        let inv_det = T::one() / (a * c - b * b);
        [c * inv_det, -b * inv_det, a * inv_det]
    }
}

/// Where a camera looks through: focal length, image centre, the pixel variance, and the
/// projection's kind.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lens<T> {
    /// Focal length in pixels (perspective), or pixels per world unit (orthographic).
    pub focal: T,
    /// The image centre in pixels.
    pub centre: [T; 2],
    /// Screen-space variance added to every footprint, in pixels squared.
    pub pixel_variance: T,
    /// Orthographic projection (else perspective).
    pub orthographic: bool,
}

/// The footprint of a splat centred at `p` in camera space (x right, y up, z forward), whose
/// camera-space covariance has the rows `cov` (symmetric), seen through `lens`; `None` where
/// it is not an ellipse (a covariance that is not positive definite on the screen, or NaN).
///
/// Perspective, the Jacobian of `(x, y, z) -> (f x / z, -f y / z)` at `p`; orthographic, the
/// constant map `(f x, -f y)`. The caller decides which depths are in front of the eye: this
/// is the projection of a splat already kept.
#[inline(always)]
pub fn footprint<T: Float>(p: [T; 3], cov: &[[T; 3]; 3], lens: &Lens<T>) -> Option<Footprint<T>> {
    let f = lens.focal;
    let zero = T::zero();
    let (j0, j1, centre) = if lens.orthographic {
        (
            [f, zero, zero],
            [zero, -f, zero],
            [lens.centre[0] + f * p[0], lens.centre[1] - f * p[1]],
        )
    } else {
        let iz = T::one() / p[2];
        (
            [f * iz, zero, -f * p[0] * iz * iz],
            [zero, -f * iz, f * p[1] * iz * iz],
            [
                lens.centre[0] + f * p[0] * iz,
                lens.centre[1] - f * p[1] * iz,
            ],
        )
    };
    let dot = |u: [T; 3], v: [T; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    let times = |v: [T; 3]| [dot(cov[0], v), dot(cov[1], v), dot(cov[2], v)];
    let v = lens.pixel_variance;
    let a = dot(j0, times(j0)) + v;
    let b = dot(j0, times(j1));
    let c = dot(j1, times(j1)) + v;
    let det = a * c - b * b;
    // Also refuses a NaN determinant.
    if det.partial_cmp(&zero) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let own = (a - v) * (c - v) - b * b;
    let kept = if own > zero {
        (own / det).sqrt().min(T::one())
    } else {
        zero
    };
    Some(Footprint {
        centre,
        cov: [a, b, c],
        kept,
    })
}

/// The four planes, in camera space (x right, y up, z forward, the eye at the origin), past
/// which a perspective view leaves a splat out: a splat centred at `p` is kept where
/// `dot(n, p) <= w` for each plane `[n.x, n.y, n.z, w]`.
///
/// Each is a side of the view's frustum for an image of `size` pixels and focal length `focal`,
/// widened by a pixel and the reach of the screen's low-pass (`sqrt(cutoff pixel_variance)`
/// pixels), and moved out by the splat's own reach along its normal, `sqrt(cutoff n^T S n)`
/// for the camera-space covariance `cov` (`cutoff`: the Gaussian exponent's cut-off,
/// radius^2 / sigma^2). A splat past one has its whole cut-off ellipsoid outside the view:
/// nothing of it lies on a line of sight through the image. The affine approximation of the
/// perspective map does not know that where a splat lies near the plane of the eye: one a few
/// millimetres beside the eye gets a footprint of thousands of pixels, and a view from inside
/// a CT drew its walls as one flat tone (BENCHMARKS.md, "The eye inside the volume"). Far
/// from the eye the two agree, and the planes leave out only splats whose footprints miss
/// the image anyway.
pub fn beside_the_view(
    focal: f64,
    size: (f64, f64),
    cov: &[[f64; 3]; 3],
    cutoff: f64,
    pixel_variance: f64,
) -> [[f64; 4]; 4] {
    let margin = 1.0 + (cutoff * pixel_variance).max(0.0).sqrt();
    let tan_x = (0.5 * size.0 + margin) / focal;
    let tan_y = (0.5 * size.1 + margin) / focal;
    [
        [1.0, 0.0, -tan_x],
        [-1.0, 0.0, -tan_x],
        [0.0, 1.0, -tan_y],
        [0.0, -1.0, -tan_y],
    ]
    .map(|n| {
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let n = n.map(|v| v / len);
        let spread: f64 = (0..3)
            .map(|r| n[r] * (0..3).map(|c| cov[r][c] * n[c]).sum::<f64>())
            .sum();
        let reach = (cutoff * spread.max(0.0)).sqrt();
        [n[0], n[1], n[2], reach]
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sub-pixel splat keeps the integral of its unwidened footprint: the widened Gaussian's
    /// peak times its area `2 pi sqrt(det)` equals the unwidened one's.
    #[test]
    fn the_kept_share_keeps_the_integral() {
        let lens = Lens {
            focal: 500.0f64,
            centre: [32.0, 24.0],
            pixel_variance: 0.3,
            orthographic: false,
        };
        let s = 0.02;
        let cov = [[s, 0.0, 0.0], [0.0, 2.0 * s, 0.0], [0.0, 0.0, s]];
        let p = [0.5, -0.2, 40.0];
        let wide = footprint(p, &cov, &lens).unwrap();
        let own = Footprint {
            cov: [wide.cov[0] - 0.3, wide.cov[1], wide.cov[2] - 0.3],
            ..wide
        };
        let area = |f: &Footprint<f64>| {
            2.0 * std::f64::consts::PI * (f.cov[0] * f.cov[2] - f.cov[1] * f.cov[1]).sqrt()
        };
        assert!(wide.kept < 1.0);
        assert!((wide.kept * area(&wide) - area(&own)).abs() < 1e-12 * area(&own));
        // Closed form of the perspective Jacobian's centre: f x / z, -f y / z about the centre.
        assert_eq!(
            wide.centre,
            [32.0 + 500.0 * 0.5 / 40.0, 24.0 + 500.0 * 0.2 / 40.0]
        );
    }

    /// The conic inverts the covariance.
    #[test]
    fn the_conic_inverts_the_covariance() {
        let f = Footprint {
            centre: [0.0f64; 2],
            cov: [2.0, 0.5, 1.0],
            kept: 1.0,
        };
        let [ia, ib, ic] = f.conic();
        let [a, b, c] = f.cov;
        for (got, want) in [
            (a * ia + b * ib, 1.0),
            (a * ib + b * ic, 0.0),
            (b * ia + c * ib, 0.0),
            (b * ib + c * ic, 1.0),
        ] {
            assert!((got - want).abs() < 1e-15, "{got} != {want}");
        }
    }

    /// A degenerate or NaN covariance has no footprint; an orthographic one does not depend on
    /// depth.
    #[test]
    fn degenerate_footprints_are_refused_and_orthographic_ones_ignore_depth() {
        let lens = Lens {
            focal: 10.0f32,
            centre: [0.0; 2],
            pixel_variance: 0.0,
            orthographic: false,
        };
        let zero = [[0.0f32; 3]; 3];
        assert_eq!(footprint([0.0, 0.0, 5.0], &zero, &lens), None);
        let nan = [[f32::NAN; 3]; 3];
        assert_eq!(footprint([0.0, 0.0, 5.0], &nan, &lens), None);
        let ortho = Lens {
            orthographic: true,
            pixel_variance: 0.3,
            ..lens
        };
        let unit = [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let near = footprint([1.0, 2.0, 3.0], &unit, &ortho).unwrap();
        let far = footprint([1.0, 2.0, 300.0], &unit, &ortho).unwrap();
        assert_eq!(near, far);
        assert_eq!(near.cov, [100.3, 0.0, 100.3]);
    }

    /// The planes beside the view leave out a splat only where its footprint's cut-off box
    /// misses the image, for splats far from the eye, all around the image's edges; and they
    /// leave out a splat beside the eye, whose footprint would cover the image many times.
    #[test]
    fn the_planes_beside_the_view_leave_out_only_what_misses_the_image() {
        let (w, h) = (120.0f64, 80.0f64);
        let lens = Lens {
            focal: 150.0,
            centre: [0.5 * w, 0.5 * h],
            pixel_variance: 0.3,
            orthographic: false,
        };
        // An oblique covariance, 1.5 mm voxels and sigma 0.55.
        let cov = [[0.68, 0.1, -0.2], [0.1, 0.5, 0.05], [-0.2, 0.05, 0.9]];
        let cutoff = 8.2;
        let planes = beside_the_view(lens.focal, (w, h), &cov, cutoff, lens.pixel_variance);
        let kept = |p: [f64; 3]| {
            planes
                .iter()
                .all(|c| c[0] * p[0] + c[1] * p[1] + c[2] * p[2] <= c[3])
        };
        let mut left_out = 0;
        for z in [30.0, 200.0, 2000.0] {
            // Centres across and past every edge of the image, in half-pixel steps.
            let (tx, ty) = (0.5 * w / lens.focal, 0.5 * h / lens.focal);
            for i in -80..=80 {
                for j in -80..=80 {
                    let s = [f64::from(i) / 60.0 * tx, f64::from(j) / 60.0 * ty];
                    let p = [s[0] * z, s[1] * z, z];
                    let f = footprint(p, &cov, &lens).unwrap();
                    let (ex, ey) = ((cutoff * f.cov[0]).sqrt(), (cutoff * f.cov[2]).sqrt());
                    let meets = f.centre[0] + ex >= 0.0
                        && f.centre[0] - ex <= w
                        && f.centre[1] + ey >= 0.0
                        && f.centre[1] - ey <= h;
                    if !kept(p) {
                        left_out += 1;
                        assert!(
                            !meets,
                            "{p:?}: left out, but its footprint {f:?} meets the image"
                        );
                    }
                }
            }
        }
        assert!(left_out > 10_000, "{left_out}");
        // Beside the eye: 0.5 mm in front of it, 10 mm to the right. Its footprint covers
        // the image, though its cut-off ellipsoid (about 2.7 mm across) lies wholly outside
        // the view.
        let beside = [10.0, 0.0, 0.5];
        let f = footprint(beside, &cov, &lens).unwrap();
        let ex = (cutoff * f.cov[0]).sqrt();
        assert!(f.centre[0] - ex < 0.0 && ex > 10.0 * w, "{f:?}");
        assert!(!kept(beside));
        // The view's own axis, however near, is kept.
        assert!(kept([0.0, 0.0, 0.05]) && kept([0.3, -0.2, 1.0]));
    }
}
