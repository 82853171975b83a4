//! The ordering shows in the error measure: on a small CT-like shell phantom seen from close
//! eyes, IP-PBTF is well below PBTF, the bucketed order below IP-PBTF, the pyramid order below
//! half of IP-PBTF from inside the volume, and the exact order has no nearer-before-farther
//! fragments.

use glam::DVec3;
use splatscene::camera::Camera;
use splatscene::classify::{TransferFunction, classify, view_step_mm};
use splatscene::order::{OrderOptions, Orderer, Ordering, ViewCase};
use splatscene::splat::reference::{SplatStyle, SplatVolume, compare, composite};
use splatscene::volume::CpuVolume;

/// Nested spherical shells of "bone" (denser outside) in a 28^3 grid.
fn shells(spacing: [f64; 3]) -> CpuVolume {
    let n = 28u32;
    let c = (f64::from(n) - 1.0) / 2.0;
    let values = (0..n * n * n)
        .map(|id| {
            let (x, y, z) = (id % n, id / n % n, id / n / n);
            let r = ((f64::from(x) - c).powi(2)
                + (f64::from(y) - c).powi(2)
                + (f64::from(z) - c).powi(2))
            .sqrt();
            match r {
                r if r > 13.0 => -1000.0,
                r if r > 11.0 => 1300.0,
                r if r > 6.0 => 400.0 + 30.0 * (id % 7) as f32,
                _ => 40.0,
            }
        })
        .collect();
    CpuVolume {
        dims: [n; 3],
        spacing,
        origin: [0.0; 3],
        direction: glam::DMat3::IDENTITY,
        values,
    }
}

/// Mean image RMSE against the exact order for each ordering over a few eyes of one case.
fn errors(volume: &CpuVolume, eyes: &[[f64; 3]]) -> Vec<(Ordering, f64)> {
    let geometry = volume.geometry().unwrap();
    let classified = classify(volume, &TransferFunction::ct_bone(), 1.0 / 255.0).unwrap();
    let mut orderer = Orderer::new();
    let mut list = Vec::new();
    let options = OrderOptions {
        cull_behind_eye: true,
        ..Default::default()
    };
    let style = SplatStyle::default();
    let mut sums = vec![0.0; Ordering::ALL.len()];
    for eye in eyes {
        let eye = geometry.index_to_world_point(DVec3::from(*eye));
        let target = geometry.centre_world();
        let view = ViewCase::new(&geometry, eye, target).unwrap();
        let step = view_step_mm(geometry.index_to_world().matrix3, target - eye).unwrap();
        let colors = classified.premultiplied(step as f32);
        let splats = SplatVolume {
            geometry: &geometry,
            grid: &classified.grid,
            colors: &colors,
        };
        let mut camera = Camera::looking_at(eye, target, 96, 96);
        camera.up = Camera::safe_up(eye, target);
        orderer
            .order(
                &classified.grid,
                &view,
                Ordering::Exact,
                &options,
                &mut list,
            )
            .unwrap();
        let (reference, stats) = composite(&camera, &splats, &list, &style).unwrap();
        assert_eq!(stats.inversions, 0, "the exact order is back to front");
        for (i, &ordering) in Ordering::ALL.iter().enumerate() {
            orderer
                .order(&classified.grid, &view, ordering, &options, &mut list)
                .unwrap();
            let (frame, _) = composite(&camera, &splats, &list, &style).unwrap();
            sums[i] += compare(&frame, &reference).unwrap().rmse / eyes.len() as f64;
        }
    }
    Ordering::ALL.iter().copied().zip(sums).collect()
}

fn get(errors: &[(Ordering, f64)], ordering: Ordering) -> f64 {
    errors.iter().find(|(o, _)| *o == ordering).unwrap().1
}

#[test]
fn face_on_close_ip_pbtf_beats_pbtf_and_bucketed_beats_ip_pbtf() {
    let volume = shells([1.0; 3]);
    let e = errors(
        &volume,
        &[[12.3, 15.6, -9.0], [14.2, 11.1, 38.0], [-10.0, 13.4, 12.2]],
    );
    let (pbtf, ip, bucketed) = (
        get(&e, Ordering::Pbtf),
        get(&e, Ordering::IpPbtfImplicit),
        get(&e, Ordering::Bucketed),
    );
    assert_eq!(get(&e, Ordering::Exact), 0.0);
    assert_eq!(ip, get(&e, Ordering::IpPbtfExplicit));
    assert!(ip * 2.0 < pbtf, "IP-PBTF {ip} against PBTF {pbtf}");
    assert!(bucketed < ip, "bucketed {bucketed} against IP-PBTF {ip}");
}

#[test]
fn ct_like_spacing_bucketed_halves_ip_pbtf() {
    let volume = shells([0.7, 0.7, 2.5]);
    let e = errors(
        &volume,
        &[[12.3, 15.6, -4.0], [14.2, -12.0, 9.5], [13.1, 12.7, 14.2]],
    );
    let (ip, bucketed) = (
        get(&e, Ordering::IpPbtfImplicit),
        get(&e, Ordering::Bucketed),
    );
    assert!(
        bucketed * 2.0 < ip,
        "bucketed {bucketed} against IP-PBTF {ip}"
    );
}

#[test]
fn a_rotated_anisotropic_volume_orders_correctly() {
    // Patient orientation: direction x spacing + origin, turned about two axes, far from the
    // world origin. The exact order stays free of inversions (checked in `errors`) and the
    // orderings keep their ranking.
    let mut volume = shells([0.7, 0.7, 2.5]);
    volume.direction = glam::DMat3::from_rotation_z(0.5) * glam::DMat3::from_rotation_x(0.35);
    volume.origin = [1.0e4, -2.0e4, 3.0e3];
    let e = errors(
        &volume,
        &[[12.3, 15.6, -4.0], [14.2, -12.0, 9.5], [13.1, 12.7, 14.2]],
    );
    let (pbtf, ip, bucketed) = (
        get(&e, Ordering::Pbtf),
        get(&e, Ordering::IpPbtfImplicit),
        get(&e, Ordering::Bucketed),
    );
    assert_eq!(get(&e, Ordering::Exact), 0.0);
    assert!(ip < pbtf, "IP-PBTF {ip} against PBTF {pbtf}");
    assert!(bucketed < ip, "bucketed {bucketed} against IP-PBTF {ip}");
}

#[test]
fn volume_on_pyramid_beats_ip_pbtf() {
    // Eyes inside the volume, looking at its centre along no axis: IP-PBTF draws whole slabs
    // of one axis where many rays run closer to another; the pyramid order does not.
    let volume = shells([1.0; 3]);
    let e = errors(
        &volume,
        &[[7.5, 8.2, 10.4], [19.1, 8.7, 17.3], [8.4, 18.6, 9.2]],
    );
    let (ip, pyramid) = (
        get(&e, Ordering::IpPbtfImplicit),
        get(&e, Ordering::Pyramid),
    );
    assert!(pyramid * 2.0 < ip, "pyramid {pyramid} against IP-PBTF {ip}");
}
