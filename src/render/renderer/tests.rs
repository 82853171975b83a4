use super::*;

/// The bounds views are set up with: a 2 m cube about the origin, holding every grid of these
/// tests, so that the near plane lies nearer the eye than any of them (without bounds the
/// near plane lies a millimetre short of the target, past the nearer half of each grid, and
/// its splats would be left out).
const WORLD: Option<(DVec3, DVec3)> = Some((DVec3::splat(-1000.0), DVec3::splat(1000.0)));

#[test]
fn refined_voxels_tile_the_coarse_box() {
    // Fine voxel j of coarse voxel k sits at k - 1/2 + (j + 1/2) / f: the first fine
    // centre half a fine voxel inside the coarse box, the last as far from its other end.
    let m = refinement([2, 3, 1]);
    let first = m.transform_point3(DVec3::ZERO);
    assert!((first - DVec3::new(-0.25, -1.0 / 3.0, 0.0)).length() < 1e-12);
    let last = m.transform_point3(DVec3::new(9.0, 5.0, 3.0));
    assert!((last - DVec3::new(4.25, 1.0 + 1.0 / 3.0, 3.0)).length() < 1e-12);
}

#[test]
fn refinement_brings_voxels_to_about_a_pixel_within_its_caps() {
    let all = Within::WHOLE;
    // To at most 1.5 pixels: 1.4 pixels apart stays, 1.6 doubles, 3.5 triples, 3.0
    // doubles.
    assert_eq!(refine_factors([100; 3], [1.4, 1.5, 0.3], all), None);
    assert_eq!(
        refine_factors([100; 3], [1.6, 3.5, 3.0], all),
        Some([2, 3, 2])
    );
    // At most MAX_REFINE an axis, and 2048 voxels along it.
    assert_eq!(
        refine_factors([10; 3], [50.0, 1.0, 1.0], all),
        Some([8, 1, 1])
    );
    assert_eq!(
        refine_factors([1000, 4, 4], [5.0, 1.0, 1.0], all),
        Some([2, 1, 1])
    );
    // At most MAX_REFINED_VOXELS in all: the largest factor goes down first.
    let fine = |f: [u32; 3], voxels: u64| voxels * f.iter().map(|&f| u64::from(f)).product::<u64>();
    let f = refine_factors([512, 512, 512], [4.0, 4.0, 2.0], all).unwrap();
    assert!(fine(f, 512 * 512 * 512) <= MAX_REFINED_VOXELS, "{f:?}");
    assert!(f.iter().all(|&f| f >= 1) && f != [1; 3], "{f:?}");
    // A thin-slice CT's grid (0.7 mm, 512 x 512 x 532) whose voxels fall 2.5 pixels apart:
    // classified whole, it is past the cap at any refinement...
    let (ct, apart) = ([512, 512, 532], [2.5, 2.5, 2.5]);
    let voxels = 512 * 512 * 532;
    assert_eq!(refine_factors(ct, apart, all), None);
    // ...but a close-up classified within a sixth of it is refined as a thick-slice grid is.
    let f = refine_factors(ct, apart, Within::voxels(voxels / 6)).unwrap();
    assert_eq!(f, [2, 2, 2]);
    assert!(fine(f, voxels / 6) <= MAX_REFINED_VOXELS);
    // Within few voxels, the whole refined grid is still bounded (its bitmap spans it all).
    let f = refine_factors(ct, [5.0; 3], Within::voxels(4096)).unwrap();
    assert!(fine(f, voxels) <= MAX_REFINED_GRID, "{f:?}");
    assert!(fine(f.map(|f| f + 1), voxels) > MAX_REFINED_GRID, "{f:?}");
    // The refinement's splats bounded: the own grid's splats times the factors' product.
    let bounded = |splats, most| Within {
        voxels: voxels / 6,
        splats: Some((splats, most)),
    };
    assert_eq!(
        refine_factors(ct, apart, bounded(1_000_000, 4_000_000)),
        Some([2, 2, 1])
    );
    assert_eq!(refine_factors(ct, apart, bounded(1_000_000, 999_999)), None);
    // Never coarser than the whole grid's cap makes it, however tight the view's bounds.
    let tight = Within {
        voxels: 1000,
        splats: Some((1000, 1)),
    };
    assert_eq!(refine_factors([100; 3], [4.0; 3], tight), Some([3, 3, 3]));
    // Not a number: no refinement.
    assert_eq!(refine_factors([10; 3], [f64::NAN; 3], all), None);
}

#[test]
fn the_detail_follows_the_pixels_a_voxel_spans() {
    // A 100 mm cube of 50 voxels (2 mm) seen from 400 mm at 35 degrees, along its z axis.
    let geometry = |spacing: f64| {
        VolumeGeometry::new([50; 3], glam::DAffine3::from_scale(DVec3::splat(spacing))).unwrap()
    };
    let camera = SceneCamera::look_at(DVec3::new(50.0, 50.0, -400.0), DVec3::splat(50.0));
    let view = |pixels: u32| ViewSetup::new(&camera, (pixels, pixels), WORLD).unwrap();
    let apart = |g: &VolumeGeometry, v: &ViewSetup| pixels_apart(g, v).unwrap();
    // About 2 pixels apart across the view at 256: refined 2 x 2 x 2 (the voxels' edges
    // along z, the view, would span as many pixels across it). Along z the voxels lie nearly
    // on top of each other: the edge of a voxel across the sight lines to the cube's near
    // corners (10 degrees off the axis, the most) is about a sixth of a voxel.
    let g = geometry(2.0);
    let a = apart(&g, &view(256));
    assert!(
        (1.9..2.1).contains(&a[0]) && (1.9..2.1).contains(&a[1]),
        "{a:?}"
    );
    let share = (50.0f64.hypot(50.0) / 50.0f64.hypot(50.0).hypot(400.0)).min(1.0);
    assert!(
        (a[2] - a[0] * share).abs() < 0.05 * a[0],
        "{a:?} against {share}"
    );
    assert_eq!(detail_for(&g, &view(256)), Detail::Refined([2; 3]));
    // Under half a pixel apart at 48: a level coarser across the view, whose voxels are
    // under a pixel apart; along the view one more, with its smaller indices facing the eye
    // (the view runs towards +z).
    let a = apart(&g, &view(48));
    assert!((0.25..0.5).contains(&a[0]), "{a:?}");
    assert_eq!(
        detail_for(&g, &view(48)),
        Detail::Level([1, 1, 2], [0, 0, -1])
    );
    // About a pixel apart: the own grid across the view, halved once along it.
    for pixels in [64, 160] {
        assert_eq!(
            detail_for(&g, &view(pixels)),
            Detail::Level([0, 0, 1], [0, 0, -1]),
            "{pixels}"
        );
    }
    // From the other side its larger indices face the eye.
    let behind = SceneCamera::look_at(DVec3::new(50.0, 50.0, 500.0), DVec3::splat(50.0));
    let v = ViewSetup::new(&behind, (160, 160), WORLD).unwrap();
    assert_eq!(detail_for(&g, &v), Detail::Level([0, 0, 1], [0, 0, 1]));
    // Along the diagonal no axis lies along the view: every axis alike.
    let diagonal = SceneCamera::look_at(DVec3::splat(-300.0), DVec3::splat(50.0));
    let v = ViewSetup::new(&diagonal, (48, 48), WORLD).unwrap();
    let a = apart(&g, &v);
    assert!(
        (a[0] - a[1]).abs() < 1e-9 && (a[1] - a[2]).abs() < 1e-9,
        "{a:?}"
    );
    assert!(
        matches!(detail_for(&g, &v), Detail::Level(l, [0, 0, 0]) if l[0] == l[1] && l[1] == l[2])
    );
    // Orthographic along x: the voxels along x fall on each other exactly, and x is halved
    // once more than the others (no further: MAX_DEPTH_LEVELS).
    let ortho = SceneCamera {
        projection: crate::scene::Projection::Orthographic { height: 200.0 },
        ..SceneCamera::look_at(DVec3::new(-400.0, 50.0, 50.0), DVec3::splat(50.0))
    };
    let v = ViewSetup::new(&ortho, (100, 100), WORLD).unwrap();
    let a = apart(&g, &v);
    assert!(a[0].abs() < 1e-9 && (a[1] - 1.0).abs() < 1e-9, "{a:?}");
    assert_eq!(
        detail_for(&g, &v),
        Detail::Level([MAX_DEPTH_LEVELS, 0, 0], [-1, 0, 0])
    );
    // The eye inside the box: its voxels may lie as near as the splats' near cut, a tenth of
    // a voxel (the view's own near plane is nearer), so the grid is refined as far as it may
    // be: MAX_REFINE along every axis (50^3 voxels refined 8^3 times is under
    // MAX_REFINED_VOXELS).
    let inside = SceneCamera::look_at(DVec3::splat(50.0), DVec3::new(50.0, 50.0, 400.0));
    let v = ViewSetup::new(
        &inside,
        (256, 256),
        Some((DVec3::ZERO, DVec3::splat(100.0))),
    )
    .unwrap();
    let near = v.splat_near(2.0);
    assert!((near - 0.2).abs() < 1e-12, "{near}");
    let a = apart(&g, &v);
    let expected = 2.0 * v.focal / near;
    assert!(
        a.iter().all(|&p| (p - expected).abs() < 1e-6 * expected),
        "{a:?} against {expected}"
    );
    assert_eq!(detail_for(&g, &v), Detail::Refined([MAX_REFINE; 3]));
    // A larger grid inside: the factors shrink to MAX_REFINED_VOXELS, largest first.
    let large =
        VolumeGeometry::new([400; 3], glam::DAffine3::from_scale(DVec3::splat(0.25))).unwrap();
    match detail_for(&large, &v) {
        Detail::Refined(f) => {
            let voxels: u64 = f.iter().map(|&f| 400 * u64::from(f)).product();
            assert!(voxels <= MAX_REFINED_VOXELS, "{f:?}");
            assert!(
                f.iter().all(|&f| f >= 1) && f.iter().max().unwrap() - f.iter().min().unwrap() <= 1,
                "{f:?}"
            );
        }
        other => panic!("{other:?}"),
    }
}

/// An `n`^3 grid of 1 mm voxels at the origin holding `values`.
fn unit_volume(n: u32, values: crate::volume::Voxels) -> CpuVolume {
    CpuVolume {
        dims: [n; 3],
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values,
    }
}

/// An `n`^3 grid of 1 mm voxels, air but where `inside` (1000), classified by a ramp: its
/// classification, occupied bricks and geometry.
fn content_grid(
    n: u32,
    inside: impl Fn([u32; 3]) -> bool,
) -> (Classified, Occupied, VolumeGeometry) {
    let values = (0..n * n * n)
        .map(|id| {
            let k = [id % n, id / n % n, id / n / n];
            if inside(k) { 1000.0 } else { 0.0 }
        })
        .collect();
    let volume = unit_volume(n, values);
    let tf = crate::classify::TransferFunction::ramp(100.0, 900.0, [1.0, 1.0, 1.0, 0.8]);
    let classified = crate::classify::classify(&volume, &tf, 0.0).unwrap();
    let occupied = Occupied::of(&classified);
    let geometry = VolumeGeometry::new([n; 3], glam::DAffine3::from_scale(DVec3::ONE)).unwrap();
    (classified, occupied, geometry)
}

#[test]
fn the_detail_goes_by_where_the_content_comes_nearest() {
    // A 64^3 grid of 1 mm voxels, air but for a 6-voxel cube near its far corner.
    let n = 64u32;
    let (classified, occupied, geometry) =
        content_grid(n, |k| k.iter().all(|&c| (50..56).contains(&c)));
    assert!(!classified.grid.is_empty());
    let eye = DVec3::new(-100.0, -80.0, -120.0);
    // Brute force over the splats' voxel boxes (half a voxel beyond each centre): the
    // bricks' distance is never farther, and at most a brick's diagonal nearer.
    let exact = classified
        .grid
        .ids()
        .map(|id| {
            let k = DVec3::from(classified.grid.coords(id).map(f64::from));
            (eye.clamp(k - 0.5, k + 0.5) - eye).length()
        })
        .fold(f64::INFINITY, f64::min);
    let near = occupied.nearest(&geometry, eye).unwrap();
    let diagonal = f64::from(BRICK) * 3f64.sqrt();
    assert!(
        near <= exact + 1e-9 && near >= exact - diagonal,
        "{near} against {exact}"
    );
    // The box's corner is far nearer than the content: by the content the voxels are fewer
    // pixels apart, and a view that the box keeps at the own grid draws a coarser level.
    let camera = SceneCamera::look_at(eye, DVec3::splat(53.0));
    let mut coarser = 0;
    for pixels in (16..=256).step_by(4) {
        let view = ViewSetup::new(&camera, (pixels, pixels), WORLD).unwrap();
        let by_box = pixels_apart(&geometry, &view).unwrap()[0];
        let by_content = pixels_apart_near(&geometry, &view, Some(&occupied)).unwrap()[0];
        assert!(by_content < 0.7 * by_box, "{by_content} against {by_box}");
        let level = |d| match detail_at(
            [n; 3],
            Some(Apart {
                pixels: [d; 3],
                full: [d; 3],
                facing: [0; 3],
            }),
            Within::WHOLE,
        ) {
            Detail::Level(l, _) => l[0],
            Detail::Refined(_) => 0,
        };
        assert!(level(by_content) >= level(by_box));
        coarser += usize::from(level(by_content) > level(by_box));
    }
    assert!(coarser > 5, "{coarser} sizes drawn coarser");
}

#[test]
fn content_off_the_image_does_not_set_the_detail() {
    // Looking along +z from the origin at 35 degrees (half-angle 17.5): a box 100 mm ahead
    // is on the image; one as far ahead but 100 mm to a side, or behind the eye, is not.
    let camera = SceneCamera::look_at(DVec3::ZERO, DVec3::new(0.0, 0.0, 100.0));
    let view = ViewSetup::new(&camera, (200, 100), WORLD).unwrap();
    let half = DVec3::splat(5.0);
    let at = |x: f64, y: f64, z: f64| (DVec3::new(x, y, z), half);
    assert!(!off_image(&view, at(0.0, 0.0, 100.0)));
    // The image is twice as wide as high: 35 degrees high, about 64 wide.
    assert!(!off_image(&view, at(50.0, 0.0, 100.0)));
    assert!(off_image(&view, at(0.0, 50.0, 100.0)));
    for side in [
        at(100.0, 0.0, 100.0),
        at(-100.0, 0.0, 100.0),
        at(0.0, 100.0, 100.0),
        at(0.0, -100.0, 100.0),
        at(0.0, 0.0, -100.0),
    ] {
        assert!(off_image(&view, side), "{side:?}");
    }
    // A box reaching into the image from off it is on it.
    assert!(!off_image(
        &view,
        (DVec3::new(0.0, 60.0, 100.0), DVec3::splat(40.0))
    ));
    // Orthographic, 100 mm high and 200 wide: the planes are parallel.
    let ortho = SceneCamera {
        projection: crate::scene::Projection::Orthographic { height: 100.0 },
        ..camera
    };
    let view = ViewSetup::new(&ortho, (200, 100), WORLD).unwrap();
    assert!(!off_image(&view, at(90.0, 0.0, 500.0)));
    assert!(off_image(&view, at(0.0, 60.0, 500.0)));
    assert!(off_image(&view, at(0.0, 0.0, -100.0)));
    // A grid whose content nearest the eye lies off the image: the detail goes by the
    // content on it, farther and so coarser.
    let n = 64u32;
    let near_off = |k: [u32; 3]| k[0] >= 56 && k[2] < 8;
    let far_on = |k: [u32; 3]| (28..36).contains(&k[0]) && (28..36).contains(&k[1]) && k[2] >= 56;
    let (_, occupied, geometry) = content_grid(n, |k| near_off(k) || far_on(k));
    // From 40 mm in front of the grid's face, narrowly at the far cube.
    let camera = SceneCamera {
        projection: crate::scene::Projection::Perspective {
            fov_y_degrees: 10.0,
        },
        ..SceneCamera::look_at(DVec3::new(32.0, 32.0, -40.0), DVec3::new(32.0, 32.0, 60.0))
    };
    let view = ViewSetup::new(&camera, (64, 64), WORLD).unwrap();
    let on_image = pixels_apart_near(&geometry, &view, Some(&occupied)).unwrap();
    // By the far cube's brick alone (z from 47.5), 87.5 mm from the eye; the near cube's
    // brick, off the image, lies 42 mm from it.
    let pixel = 87.5 / view.focal;
    assert!(
        (on_image[0] * pixel - 1.0).abs() < 0.01,
        "{on_image:?} against {}",
        1.0 / pixel
    );
}

#[test]
fn bricks_are_ordered_so_that_none_lies_behind_a_later_one() {
    // A 70 x 50 x 40 grid (bricks of 16: 5 x 4 x 3, partly filled at the far ends), sheared,
    // turned and anisotropic, seen from outside along every octant, from inside and from
    // planes between bricks.
    let dims = [70u32, 50, 40];
    let turn = glam::DMat3::from_euler(glam::EulerRot::XYZ, 0.3, -0.5, 0.8);
    let linear = turn
        * glam::DMat3::from_cols(
            DVec3::new(0.7, 0.0, 0.0),
            DVec3::new(0.1, 0.7, 0.0),
            DVec3::new(0.0, 0.0, 1.3),
        );
    let geometry = VolumeGeometry::new(
        dims,
        glam::DAffine3::from_mat3_translation(linear, DVec3::new(5.0, -3.0, 2.0)),
    )
    .unwrap();
    let counts = dims.map(|n| n.div_ceil(BRICK));
    let all: Vec<([u32; 3], Detail)> = (0..counts[0] * counts[1] * counts[2])
        .map(|i| {
            (
                [
                    i % counts[0],
                    i / counts[0] % counts[1],
                    i / counts[0] / counts[1],
                ],
                Detail::default(),
            )
        })
        .collect();
    let mut eyes: Vec<DVec3> = Vec::new();
    for corner in 0..27u32 {
        // Each axis below, within and beyond the grid (in index coordinates).
        let at = |a: u32, n: u32| match corner / 3u32.pow(a) % 3 {
            0 => -60.0,
            1 => 0.37 * f64::from(n),
            _ => f64::from(n) + 45.0,
        };
        eyes.push(DVec3::new(at(0, dims[0]), at(1, dims[1]), at(2, dims[2])));
    }
    // On the plane between two bricks along x, and on a brick's centre plane.
    eyes.push(DVec3::new(15.5, -30.0, 20.0));
    eyes.push(DVec3::new(23.5, 80.0, 7.5));
    for eye_index in eyes {
        let eye = geometry.index_to_world_point(eye_index);
        let target = geometry.index_to_world_point(DVec3::new(35.0, 25.0, 20.0));
        let target = if (target - eye).length() < 1.0 {
            target + DVec3::X * 10.0
        } else {
            target
        };
        let mut bricks = all.clone();
        brick_order(&geometry, eye, target, BRICK, &mut bricks).unwrap();
        let place: HashMap<[u32; 3], usize> = bricks
            .iter()
            .enumerate()
            .map(|(i, (b, _))| (*b, i))
            .collect();
        assert_eq!(place.len(), all.len());
        // Of two bricks that share a face, the one on the eye's side of the face's plane (in
        // the grid's own index coordinates: between voxels 16 b - 1 and 16 b) comes later.
        for (b, _) in &all {
            for a in 0..3 {
                let mut next = *b;
                next[a] += 1;
                let Some(&later_if_near) = place.get(&next) else {
                    continue;
                };
                let plane = f64::from(next[a] * BRICK) - 0.5;
                let e = eye_index[a];
                if e > plane {
                    assert!(later_if_near > place[b], "{b:?} {next:?} eye {eye_index:?}");
                } else if e < plane {
                    assert!(later_if_near < place[b], "{b:?} {next:?} eye {eye_index:?}");
                }
            }
        }
    }
}

#[test]
fn bricks_far_from_the_eye_draw_coarser_levels_and_those_off_the_image_none() {
    // A 128^3 grid of 1 mm voxels filled but for a margin, seen from 30 mm before its face
    // along z at 40 degrees, 96 x 96 pixels: the near face's voxels fall about 2.4 pixels apart
    // (the own grid there), the far face's, 158 mm away, under half a pixel.
    let n = 128u32;
    let (_, occupied, geometry) = content_grid(n, |k| k.iter().all(|&c| (2..126).contains(&c)));
    let camera = SceneCamera {
        projection: crate::scene::Projection::Perspective {
            fov_y_degrees: 40.0,
        },
        ..SceneCamera::look_at(DVec3::new(64.0, 64.0, -30.0), DVec3::new(64.0, 64.0, 64.0))
    };
    let view = ViewSetup::new(&camera, (96, 96), WORLD).unwrap();
    let bricks = brick_details(&geometry, &view, &occupied, 0, REFINE_TO);
    let level = |d: &Detail| match d {
        Detail::Level(l, _) => l.iter().copied().max().unwrap_or(0),
        Detail::Refined(_) => 0,
    };
    let at_z = |z: u32| {
        bricks
            .iter()
            .filter(|w| w.brick[2] == z)
            .map(|w| level(&w.detail))
            .collect::<Vec<_>>()
    };
    let (near, far) = (at_z(0), at_z(n / BRICK - 1));
    assert!(near.iter().all(|&l| l == 0), "{near:?}");
    assert!(!far.is_empty() && far.iter().all(|&l| l >= 1), "{far:?}");
    // The near slab's bricks that lie off the image (its corners, outside the 40 degree cone
    // 30 mm ahead) are left out; every brick of the far slab is on it.
    assert!(
        near.len() < (n / BRICK * n / BRICK) as usize,
        "{}",
        near.len()
    );
    assert_eq!(far.len(), (n / BRICK * n / BRICK) as usize);
    // Each brick left out lies off the image, as a plain test of its voxel centres says: no
    // centre of it projects within the image.
    let kept: std::collections::HashSet<[u32; 3]> = bricks.iter().map(|w| w.brick).collect();
    let [right, up, forward] = [view.axes.x_axis, view.axes.y_axis, view.axes.z_axis];
    let project = |p: DVec3| {
        let d = p - view.camera.eye;
        let z = d.dot(forward);
        (z > 0.0).then(|| {
            glam::DVec2::new(
                48.0 + view.focal * d.dot(right) / z,
                48.0 - view.focal * d.dot(up) / z,
            )
        })
    };
    for z in 0..2 {
        for y in 0..n / BRICK {
            for x in 0..n / BRICK {
                let b = [x, y, z];
                if kept.contains(&b) {
                    continue;
                }
                for k in 0..BRICK * BRICK * BRICK {
                    let v = [k % BRICK, k / BRICK % BRICK, k / BRICK / BRICK];
                    let p = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
                        f64::from(b[a] * BRICK + v[a])
                    }));
                    let Some(s) = project(p) else {
                        continue;
                    };
                    assert!(
                        !(-2.0..98.0).contains(&s.x) || !(-2.0..98.0).contains(&s.y),
                        "brick {b:?} left out, voxel {v:?} at {s:?}"
                    );
                }
            }
        }
    }
}

#[test]
fn runs_walked_alone_give_their_levels_orders_sorted_into_runs() {
    // A translucent 96^3 field seen from 30 mm before its face along z, and from an oblique
    // eye whose coordinates along y and z fall on brick boundaries, at 32 x 32 pixels: the near
    // bricks draw the own grid, the far ones coarser levels. The mix's order walked run by
    // run (each over its box of bricks) is the one each level's whole order gives, sorted into
    // runs, splat for splat, in both interleavings.
    let n = 96u32;
    let (scene, id) = wavy_field(n);
    let cameras = [
        (DVec3::new(48.0, 47.0, -30.0), DVec3::new(48.0, 50.0, 48.0)),
        (DVec3::new(-20.0, 32.0, 16.0), DVec3::new(60.0, 50.0, 70.0)),
    ];
    for (eye, target) in cameras {
        let camera = SceneCamera {
            projection: crate::scene::Projection::Perspective {
                fov_y_degrees: 50.0,
            },
            ..SceneCamera::look_at(eye, target)
        };
        for ordering in [Ordering::IpPbtfImplicit, Ordering::IpPbtfExplicit] {
            let mut renderer = Renderer::with_compositor(super::super::Compositor::Cpu);
            let options = FrameOptions {
                ordering: Some(ordering),
                ..FrameOptions::default()
            };
            let shot = renderer
                .screenshot_without_gpu(&scene, &camera, (32, 32), &options)
                .unwrap();
            assert_eq!(shot.report.bricks_by_level, 1, "{eye}: {:?}", shot.report);
            let mix = renderer.mixes.get(&id).unwrap();
            assert!(mix.runs.len() > 1, "{eye}: {:?}", mix.runs);
            let mut whole = Mix {
                bricks: mix.bricks.clone(),
                ..Mix::default()
            };
            let pinhole = shot.view.pinhole().unwrap();
            order_mix_from_whole_levels(
                &mut renderer.volumes,
                (id, DMat4::IDENTITY),
                (pinhole.eye, pinhole.target),
                (
                    ordering,
                    &OrderOptions {
                        cull_behind_eye: true,
                        ..Default::default()
                    },
                ),
                [n.div_ceil(BRICK); 3],
                &mut whole,
            )
            .unwrap();
            let mix = renderer.mixes.get(&id).unwrap();
            assert_eq!(whole.runs, mix.runs, "{eye} {ordering:?}");
            assert!(whole.ids == mix.ids, "{eye} {ordering:?}");
        }
    }
}

#[test]
fn smooth_bricks_draw_a_level_coarser_and_detailed_ones_their_own() {
    // A 64^3 grid of 1 mm voxels, uniform where x < 32 and blocks of 2 x 2 x 2 voxels of two
    // values in turn where x >= 32, each straddling two of the level above's blocks (a
    // pattern a level coarser would average away; one that alternates voxel by voxel the
    // splats' cells average already, and blocks that are the level's own lose nothing
    // halved), both translucent, seen
    // along z from 100 mm before its face at 64 x 64 pixels: its voxels fall 0.55-0.9 pixels
    // apart, so every brick wants its own grid across the view and most may be drawn a
    // level coarser where they are smooth.
    let n = 64u32;
    let values: Vec<f32> = (0..n * n * n)
        .map(|id| {
            let k = [id % n, id / n % n, id / n / n];
            match (
                k[0] < n / 2,
                k.iter().map(|c| c.div_ceil(2)).sum::<u32>() % 2,
            ) {
                (true, _) => 350.0,
                (false, 0) => 200.0,
                (false, _) => 500.0,
            }
        })
        .collect();
    let transfer = crate::classify::TransferFunction::new(vec![
        (100.0, [0.9, 0.5, 0.3, 0.0]),
        (600.0, [1.0, 0.9, 0.7, 0.15]),
    ]);
    let mut scene = Scene::new();
    let id = scene
        .add(
            "volume",
            DMat4::IDENTITY,
            None,
            crate::scene::NodeContent::Volume(VolumeNode {
                volume: Arc::new(unit_volume(n, values.into())),
                transfer: Arc::new(transfer),
                splats: crate::scene::SplatSettings::default(),
            }),
        )
        .unwrap();
    let camera = SceneCamera {
        projection: crate::scene::Projection::Perspective {
            fov_y_degrees: 40.0,
        },
        ..SceneCamera::look_at(DVec3::new(31.5, 31.5, -100.0), DVec3::new(31.5, 31.5, 31.5))
    };
    let mut renderer = Renderer::with_compositor(super::super::Compositor::Cpu);
    let shot = renderer
        .screenshot_without_gpu(&scene, &camera, (64, 64), &FrameOptions::default())
        .unwrap();
    assert_eq!(shot.report.bricks_by_level, 1, "{:?}", shot.report);
    let mix = renderer.mixes.get(&id).unwrap();
    // What each brick's spacing alone calls for, and the level its smoothness may take.
    let occupied = renderer.volumes[&(id, Detail::default())]
        .occupied
        .as_ref()
        .unwrap();
    let geometry = VolumeGeometry::new([n; 3], glam::DAffine3::from_scale(DVec3::ONE)).unwrap();
    let wants = brick_details(&geometry, &shot.view, occupied, 0, REFINE_TO);
    let half = n / 2 / BRICK;
    let last = n / BRICK - 1;
    let mut inner = 0;
    for (brick, drawn) in &mix.bricks {
        let want = wants.iter().find(|w| w.brick == *brick).unwrap();
        if brick[0] >= half {
            // The blocks' half: its own level, though its spacing allows a coarser one.
            assert!(want.smooth.is_some(), "{brick:?}: {want:?}");
            assert_eq!(*drawn, want.detail, "{brick:?}");
        } else if brick[0] > 0 && (0..3).all(|a| a == 0 || (1..last).contains(&brick[a])) {
            // The uniform half away from the grid's faces (where the cells that reach past
            // the last voxels fade): a level coarser.
            assert_eq!(Some(*drawn), want.smooth, "{brick:?}");
            inner += 1;
        }
    }
    assert!(inner >= 4, "{inner}");
    // Without smooth bricks, every brick draws what its spacing calls for: here one level
    // for the whole volume.
    let mut plain = Renderer::with_compositor(super::super::Compositor::Cpu);
    plain.set_smooth_bricks(false);
    let shot_plain = plain
        .screenshot_without_gpu(&scene, &camera, (64, 64), &FrameOptions::default())
        .unwrap();
    assert_eq!(
        shot_plain.report.bricks_by_level, 0,
        "{:?}",
        shot_plain.report
    );
    assert!(wants.iter().all(|w| w.detail == wants[0].detail));
    // The uniform half's picture, away from the seam where the coarser splats meet the
    // finer ones, stays that of the volume drawn at its one level.
    let mut one = Renderer::with_compositor(super::super::Compositor::Cpu);
    one.set_levels_by_brick(false);
    let whole = one
        .screenshot_without_gpu(&scene, &camera, (64, 64), &FrameOptions::default())
        .unwrap();
    let (mut squared, mut count) = (0.0f64, 0);
    for (i, (a, b)) in shot
        .frame
        .pixels
        .iter()
        .zip(&whole.frame.pixels)
        .enumerate()
    {
        if i % 64 < 28 {
            squared += (0..3).map(|c| f64::from(a[c] - b[c]).powi(2)).sum::<f64>();
            count += 3;
        }
    }
    let rmse = (squared / f64::from(count)).sqrt();
    assert!(rmse < 0.005, "{rmse}");
}

#[test]
fn a_draw_order_is_reused_only_for_views_that_give_the_same_order() {
    // A sparse 20 x 17 x 13 grid (about a third of its voxels significant), sheared and turned
    // in the world, ordered along camera paths that orbit it from outside in small steps, look
    // down on it from over its top face (the eye's planes cut two axes), pass through it, step
    // the eye by a quarter voxel along each axis over it, and turn within it (the eye plane
    // culls voxels).
    // After every view the state's order must be the one a fresh orderer makes.
    let dims = [20u32, 17, 13];
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let values: Vec<f32> = (0..dims.iter().product::<u32>())
        .map(|_| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            if seed.is_multiple_of(3) { 1000.0 } else { 0.0 }
        })
        .collect();
    let volume = Arc::new(CpuVolume {
        dims,
        spacing: [0.7, 0.9, 1.6],
        origin: [-5.0, 2.0, 1.0],
        direction: DMat3::from_rotation_z(0.3) * DMat3::from_rotation_x(-0.2),
        values: values.into(),
    });
    let tf = crate::classify::TransferFunction::ramp(100.0, 900.0, [1.0, 1.0, 1.0, 0.8]);
    let classified = crate::classify::classify(&volume, &tf, 0.0).unwrap();
    let world = DMat4::from_cols_array(&[
        1.0, 0.0, 0.0, 0.0, 0.2, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 3.0, -1.0, 2.0, 1.0,
    ]);
    // One state an ordering, each keeping its own order from view to view.
    let orderings = [Ordering::IpPbtfImplicit, Ordering::IpPbtfExplicit];
    let mut states = orderings.map(|_| {
        VolumeState::new(
            (0, 0, 0, 0, 0, 0, None),
            Arc::clone(&volume),
            [1; 3],
            classified.clone(),
            Orderer::new(),
            Vec::new(),
        )
    });
    let geometry = states[0].geometry(world).unwrap();
    let centre = geometry.centre_world();
    let (mut eyes, mut turns) = (Vec::new(), Vec::new());
    for step in 0..120 {
        let a = f64::from(step).to_radians() * 3.0;
        eyes.push(centre + DVec3::new(a.cos(), a.sin(), 0.35) * 60.0);
    }
    for step in 0..40 {
        let t = f64::from(step) / 39.0;
        eyes.push(centre + DVec3::new(-12.0 + 24.0 * t, -3.0 + 6.0 * t, 25.0));
    }
    for step in 0..40 {
        let t = f64::from(step) / 39.0;
        eyes.push(centre + DVec3::new(-30.0 + 60.0 * t, 4.0, 1.0));
    }
    for step in 0..40 {
        let quarter = f64::from(step) * 0.25;
        eyes.push(geometry.index_to_world().transform_point3(DVec3::new(
            quarter,
            0.5 * quarter,
            20.0,
        )));
    }
    // Standing inside it and turning by a degree a view: the class stays, the culled set does
    // not.
    let inside = centre + DVec3::new(1.3, -0.4, 0.2);
    for step in 0..30 {
        let a = f64::from(step - 15).to_radians();
        eyes.push(inside);
        turns.push(inside + DVec3::new(a.cos(), a.sin(), 0.1) * 10.0);
    }
    let options = OrderOptions {
        cull_behind_eye: true,
        ..Default::default()
    };
    let (mut reused, mut split_reused, mut culled, mut previous) = (0, 0, 0, [None; 2]);
    for (i, &eye) in eyes.iter().enumerate() {
        // Looking at the centre, or straight down from over the top face.
        let target = if i >= 240 {
            turns[i - 240]
        } else if (120..160).contains(&i) || i >= 200 {
            eye - geometry.index_to_world().transform_vector3(DVec3::Z)
        } else {
            centre
        };
        let case = ViewCase::new(&geometry, eye, target).unwrap();
        for (o, (ordering, state)) in orderings.into_iter().zip(&mut states).enumerate() {
            state
                .order(world, (eye, target), (ordering, &options))
                .unwrap();
            let mut fresh = Vec::new();
            Orderer::new()
                .order(&classified.grid, &case, ordering, &options, &mut fresh)
                .unwrap();
            assert_eq!(state.ids, fresh, "view {i}, {ordering:?}");
            let key = OrderKey::of(&case, ordering, &options);
            if key.is_some() && key == previous[o] {
                reused += 1;
                if case.axes.iter().any(|a| a.is_split()) {
                    split_reused += 1;
                }
            }
            previous[o] = key;
            if key.is_none() && i >= 240 {
                culled += 1;
            }
        }
    }
    // The paths do reuse orders, with the eye's planes cutting the grid too.
    assert!(reused > 100, "{reused}");
    assert!(split_reused > 10, "{split_reused}");
    // Turning within the grid culls other voxels at the same class: never reused.
    assert!(culled > 20, "{culled}");
}

#[test]
fn bricks_that_want_a_rare_level_draw_a_finer_one_that_stands() {
    let level = |l: [u8; 3], f: [i8; 3]| Detail::Level(l, f);
    let own = Detail::default();
    let even = level([1, 1, 1], [0; 3]);
    let along_y = level([0, 1, 0], [0, 1, 0]);
    let want = |detail: Detail, splats: u32| BrickWant {
        brick: [0; 3],
        detail,
        splats,
        smooth: None,
    };
    // 10,000 own splats: half the bricks' splats want the own grid, 30% the even level, 12%
    // 0/1/0 (kept: over a tenth), 5% 1/0/0, 2% 2/1/1 and 1% 1/1/0 (rare).
    let mut wants = vec![
        want(own, 5_000),
        want(even, 3_000),
        want(along_y, 1_200),
        want(level([1, 0, 0], [-1, 0, 0]), 500),
        want(level([2, 1, 1], [-1, 0, 0]), 200),
        want(level([1, 1, 0], [-1, 1, 0]), 100),
    ];
    fall_back_from_rare_levels(&mut wants, 10_000);
    let got: Vec<Detail> = wants.iter().map(|w| w.detail).collect();
    // 1/0/0 draws the own grid (the only one no coarser along x, y and z; 250 splats more),
    // 2/1/1 the even level (12.5 more), 1/1/0 the kept 0/1/0 (25 more): 287.5 added to the
    // mix's 6,362.5, within 5%.
    assert_eq!(got, [own, even, along_y, own, even, along_y]);
    // Where the own grid is drawn by no brick it stands in for none; where falling back adds
    // too much, the cheapest fall back first and the level that would add most is made.
    let mut wants = vec![
        want(even, 9_000),
        want(level([1, 0, 0], [-1, 0, 0]), 900),
        want(level([2, 1, 1], [-1, 0, 0]), 100),
    ];
    fall_back_from_rare_levels(&mut wants, 10_000);
    let got: Vec<Detail> = wants.iter().map(|w| w.detail).collect();
    assert_eq!(got, [even, level([1, 0, 0], [-1, 0, 0]), even]);
    let mut wants = vec![
        want(own, 8_000),
        want(level([1, 0, 0], [-1, 0, 0]), 900),
        want(level([0, 0, 1], [0, 0, 1]), 700),
    ];
    fall_back_from_rare_levels(&mut wants, 10_000);
    let got: Vec<Detail> = wants.iter().map(|w| w.detail).collect();
    // The mix draws 8,800 splats; the z level falls back (350 more, 4%), then 1/0/0 would
    // add 450 more: it is made.
    assert_eq!(got, [own, level([1, 0, 0], [-1, 0, 0]), own]);
}

#[test]
fn levels_made_in_one_frame_where_they_save_more_drawing_than_they_cost() {
    // An own grid of 1,000 splats: a level halved from it costs 550 (LEVEL_COST), one halved
    // from a level 1/1/1 of 125 splats 68.75; n splats at 2^-l of them save n (1 - 2^-l).
    assert_eq!(LEVEL_COST, 0.55);
    let l = |l: [u8; 3]| Detail::Level(l, [0; 3]);
    let own = Detail::default();
    let pay = |asked: &[(Detail, f64)], made: &[Detail]| levels_that_pay(asked, made, 1_000);
    // 700 splats save 612.5 (paid); 600 save 525 (not: the own grid).
    assert_eq!(
        pay(&[(l([1, 1, 1]), 700.0)], &[]),
        [(l([1, 1, 1]), l([1, 1, 1]))]
    );
    assert_eq!(pay(&[(l([1, 1, 1]), 600.0)], &[]), [(l([1, 1, 1]), own)]);
    // Made already, 1/1/1 costs nothing: 2/2/2 for 80 splats saves 78.75 against 68.75; for
    // 60, 59.06 (not paid: they draw 1/1/1, made and no coarser along any axis).
    assert_eq!(
        pay(&[(l([2, 2, 2]), 80.0)], &[l([1, 1, 1])]),
        [(l([2, 2, 2]), l([2, 2, 2]))]
    );
    assert_eq!(
        pay(&[(l([2, 2, 2]), 60.0)], &[l([1, 1, 1])]),
        [(l([2, 2, 2]), l([1, 1, 1]))]
    );
    // Three levels of 300 splats each: none pays alone (3/3/3 saves 299.4 for its 627.3), but
    // made, 3/3/3 puts 1/1/1 and 2/2/2 on the way: 2/2/2 saves 295.3 and 2/2/3 draws 2/2/2
    // (295.3): 890 for 627.3. Making 2/2/3 as well (8.6) would save 2.3 more.
    let asked = [
        (l([2, 2, 2]), 300.0),
        (l([2, 2, 3]), 300.0),
        (l([3, 3, 3]), 300.0),
    ];
    assert_eq!(
        pay(&asked, &[]),
        [
            (l([3, 3, 3]), l([3, 3, 3])),
            (l([2, 2, 3]), l([2, 2, 2])),
            (l([2, 2, 2]), l([2, 2, 2])),
        ]
    );
    assert_eq!(pay(&asked[2..], &[]), [(l([3, 3, 3]), own)]);
    // Facing: a level halved along the view stands for the one asked only with its sides.
    let along = Detail::Level([0, 1, 0], [0, 1, 0]);
    assert_eq!(pay(&[(along, 2_000.0)], &[]), [(along, along)]);
    assert_eq!(
        pay(&[(along, 2_000.0)], &[Detail::Level([0, 1, 0], [0, -1, 0])]),
        [(along, along)]
    );
}

#[test]
fn a_grid_seen_small_pays_for_its_levels_in_its_first_frame() {
    // The wavy field seen from 0.6 m at 32 x 32: its voxels fall a sixth of a pixel apart, so
    // every brick wants a coarse level, and levels made only where they pay are made in the
    // first frame. The picture stays near the full grid's.
    let (shoot, full) = wavy_field_seen(
        DVec3::new(-300.0, 300.0, -400.0),
        DVec3::new(48.0, 48.0, 48.0),
        20.0,
    );
    let mut renderer = Renderer::with_compositor(super::super::Compositor::Cpu);
    renderer.set_levels_for_one_frame(true);
    let once = shoot(&mut renderer);
    assert!(once.report.levels_made > 0, "{:?}", once.report);
    assert!(
        once.report.splats * 8 < full.report.splats,
        "{} of {}",
        once.report.splats,
        full.report.splats
    );
    // Over the pixels away from the background's colour (the corner's).
    let background = full.frame.pixels[0];
    let lit = |i: usize| (0..3).any(|c| (full.frame.pixels[i][c] - background[c]).abs() > 0.05);
    let rmse = rmse_where(&once.frame, &full.frame, lit);
    assert!(rmse < 0.03, "{rmse}");
}

/// [`wavy_field`] of 96^3 voxels seen from `eye` towards `target` with a vertical field of
/// view of `fov` degrees at 32 x 32: a function that draws it with a renderer, and its
/// picture from the full grid.
fn wavy_field_seen(
    eye: DVec3,
    target: DVec3,
    fov: f64,
) -> (impl Fn(&mut Renderer) -> Screenshot, Screenshot) {
    let (scene, _) = wavy_field(96);
    let camera = SceneCamera {
        projection: crate::scene::Projection::Perspective { fov_y_degrees: fov },
        ..SceneCamera::look_at(eye, target)
    };
    let shoot = move |renderer: &mut Renderer| {
        renderer
            .screenshot_without_gpu(&scene, &camera, (32, 32), &FrameOptions::default())
            .unwrap()
    };
    let mut full = Renderer::with_compositor(super::super::Compositor::Cpu);
    full.set_level_of_detail(false);
    let full = shoot(&mut full);
    (shoot, full)
}

/// A translucent field of `n`^3 unit voxels, waves along each axis (the node's id with it).
fn wavy_field(n: u32) -> (Scene, NodeId) {
    let values: Vec<f32> = (0..n * n * n)
        .map(|id| {
            let k = [id % n, id / n % n, id / n / n].map(f64::from);
            (200.0 + 250.0 * (k[0] / 7.0).sin() * (k[1] / 9.0).sin() * (k[2] / 11.0).sin()) as f32
        })
        .collect();
    volume_scene(
        unit_volume(n, values.into()),
        crate::classify::TransferFunction::new(vec![
            (250.0, [0.9, 0.5, 0.3, 0.0]),
            (450.0, [1.0, 0.9, 0.7, 0.05]),
        ]),
    )
}

/// A scene of `volume` alone, classified by `transfer` (the node's id with it).
fn volume_scene(volume: CpuVolume, transfer: crate::classify::TransferFunction) -> (Scene, NodeId) {
    let mut scene = Scene::new();
    let node = VolumeNode {
        volume: Arc::new(volume),
        transfer: Arc::new(transfer),
        splats: crate::scene::SplatSettings::default(),
    };
    let id = scene
        .add(
            "volume",
            DMat4::IDENTITY,
            None,
            crate::scene::NodeContent::Volume(node),
        )
        .unwrap();
    (scene, id)
}

#[test]
fn levels_that_do_not_pay_in_one_frame_are_not_made() {
    // The wavy field from 30 mm before its face at 32 x 32: by brick, the near bricks want the
    // own grid and the far ones coarser levels, too few to pay for one. Made only where they pay
    // in the frame, no level is made, every brick draws the own grid, and the picture is the
    // full grid's; levels made by an earlier frame do not change that, so the picture is the
    // same whatever was drawn before.
    let (shoot, full) = wavy_field_seen(
        DVec3::new(48.0, 47.0, -30.0),
        DVec3::new(48.0, 50.0, 48.0),
        50.0,
    );
    let mut renderer = Renderer::with_compositor(super::super::Compositor::Cpu);
    renderer.set_levels_for_one_frame(true);
    let own = shoot(&mut renderer);
    assert!(own.report.levels_not_made, "{:?}", own.report);
    assert_eq!(own.report.levels_made, 0);
    assert_eq!(own.report.splats, full.report.splats);
    assert_eq!(own.report.bricks_by_level, 0);
    assert_eq!(own.frame.pixels, full.frame.pixels);
    assert!(
        renderer
            .volumes
            .keys()
            .all(|(_, d)| *d == Detail::default())
    );
    // Made by a frame with making on, the levels are drawn with it off again, where the
    // bricks' spacing wants them (no brick goes coarser for being smooth, which takes a
    // measurement of the level above).
    renderer.set_levels_for_one_frame(false);
    renderer.set_smooth_bricks(false);
    let made = shoot(&mut renderer);
    assert!(made.report.levels_made > 0, "{:?}", made.report);
    assert!(made.report.splats < full.report.splats);
    renderer.set_levels_for_one_frame(true);
    let again = shoot(&mut renderer);
    assert_eq!(again.report.levels_made, 0);
    assert!(again.report.levels_not_made, "{:?}", again.report);
    assert_eq!(again.report.splats, full.report.splats);
    assert_eq!(again.frame.pixels, own.frame.pixels);
}

#[test]
fn a_camera_that_travels_holds_a_refinement_near_the_size_of_its_view() {
    // A bar of opaque tissue 192 mm long, seen close up (orthographic, its 2 mm voxels 6 pixels
    // apart: refined) by a camera sliding along it. Each view joins the bricks it shows; a
    // refinement grown past twice the view's bricks is made anew within them, so the one held
    // stays near the view's size, and each picture is a fresh renderer's.
    let dims = [96u32, 16, 16];
    let values: Vec<f32> = (0..dims.iter().product::<u32>())
        .map(|id| {
            let k = [id % dims[0], id / dims[0] % dims[1], id / dims[0] / dims[1]];
            350.0 + ((k[0] * 7 + k[1] * 3 + k[2] * 5) % 13) as f32 * 8.0
        })
        .collect();
    let volume = CpuVolume {
        dims,
        spacing: [2.0; 3],
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values: values.into(),
    };
    let (scene, id) = volume_scene(
        volume,
        crate::classify::TransferFunction::new(vec![
            (250.0, [0.9, 0.5, 0.3, 0.0]),
            (400.0, [1.0, 0.9, 0.7, 0.9]),
        ]),
    );
    let camera_at = |x: f64| SceneCamera {
        eye: DVec3::new(x, -60.0, 15.0),
        target: DVec3::new(x, 15.0, 15.0),
        up: DVec3::Z,
        projection: crate::scene::Projection::Orthographic { height: 16.0 },
        near: None,
    };
    let shoot = |renderer: &mut Renderer, x: f64| {
        renderer
            .screenshot_without_gpu(&scene, &camera_at(x), (64, 48), &FrameOptions::default())
            .unwrap()
    };
    let held = |renderer: &Renderer| {
        let (_, state) = renderer
            .volumes
            .iter()
            .find(|((v, d), _)| *v == id && matches!(d, Detail::Refined(_)))
            .expect("a refinement is held");
        let bricks = |r: &Option<Region>| r.as_ref().map_or(0, Region::bricks_covered);
        (bricks(&state.region), bricks(&state.within))
    };
    let mut travelling = Renderer::with_compositor(super::super::Compositor::Cpu);
    let mut most_held = 0;
    let mut remade = false;
    let mut before = 0;
    for step in 0..12 {
        let x = 12.0 + 14.0 * f64::from(step);
        let shot = shoot(&mut travelling, x);
        assert!(shot.report.refined.is_some(), "{:?}", shot.report);
        let (made, within) = held(&travelling);
        assert!(within > 0 && made >= within, "{made} {within}");
        assert!(
            made <= 3 * within,
            "held {made} bricks for a view of {within}"
        );
        most_held = most_held.max(made);
        remade |= step > 0 && made < before;
        before = made;
        if step % 4 == 3 {
            let fresh = shoot(
                &mut Renderer::with_compositor(super::super::Compositor::Cpu),
                x,
            );
            assert_eq!(shot.report.splats, fresh.report.splats, "step {step}");
            assert_eq!(shot.frame.pixels, fresh.frame.pixels, "step {step}");
        }
    }
    assert!(
        remade,
        "the refinement was made anew on the way (at most {most_held} bricks)"
    );
}

#[test]
fn keeping_a_refinement_within_bricks_keeps_the_order() {
    // A 20 x 12 x 9 own grid refined 3 x 1 x 2: fine dims 60 x 12 x 18. Bricks of REGION_BRICK
    // own voxels; every third brick kept.
    let own = [20u32, 12, 9];
    let factors = [3u32, 1, 2];
    let dims = [60u32, 12, 18];
    let within = Region::new(own, REGION_BRICK, |b| (b[0] + 2 * b[1] + b[2]) % 3 == 0).unwrap();
    let inside = |id: u32| {
        let f = [id % dims[0], id / dims[0] % dims[1], id / dims[0] / dims[1]];
        within.covers(std::array::from_fn(|a| f[a] / factors[a]))
    };
    // Every fine voxel, in a scrambled order.
    let count = dims.iter().product::<u32>();
    let ids: Vec<u32> = (0..count).map(|i| (i * 7919) % count).collect();
    let mut kept = ids.clone();
    keep_within(&mut kept, dims, factors, &within);
    let expected: Vec<u32> = ids.iter().copied().filter(|&id| inside(id)).collect();
    assert!(!expected.is_empty() && expected.len() < ids.len());
    assert_eq!(kept, expected);
}

#[test]
fn bricks_that_follow_one_another_at_one_detail_run_as_one_where_their_box_is_full_enough() {
    let own = Detail::default();
    let level = Detail::Level([1, 1, 1], [0; 3]);
    // A slab of 4 x 3 bricks taken as the brick order takes it, its rows from both sides of
    // the eye in turn (rows 0 and 2 before row 1): one run, though its first two rows' box is
    // half empty.
    let slab: Vec<([u32; 3], Detail)> = [0, 2, 1]
        .iter()
        .flat_map(|&y| (0..4).map(move |x| ([x, y, 5], own)))
        .collect();
    let runs = brick_runs(&slab);
    assert_eq!(runs.len(), 1, "{runs:?}");
    assert_eq!(
        (runs[0].lo, runs[0].hi, runs[0].bricks),
        ([0, 0, 5], [3, 2, 5], 12)
    );
    assert!(runs[0].fills_its_box());
    // A change of detail ends a run; a stretch whose box holds over two bricks a brick is
    // halved until each part's does not.
    let mut mixed = slab.clone();
    for b in [[0, 0, 4], [1, 0, 4], [2, 0, 4], [3, 3, 0]] {
        mixed.push((b, level));
    }
    let runs = brick_runs(&mixed);
    let ends: Vec<usize> = runs.iter().map(|r| r.end).collect();
    assert_eq!(ends, [12, 14, 15, 16], "{runs:?}");
    assert_eq!(runs[1].detail, level);
    // Every brick lies in the run of its place: runs follow one another, each of one detail,
    // and `bricks_in_runs` gives each brick of a detail its run's place in the draw order.
    let in_level = bricks_in_runs(&mixed, &runs, [4, 4, 6], level);
    let at = |b: [u32; 3]| in_level[(b[0] + 4 * (b[1] + 4 * b[2])) as usize];
    assert_eq!(
        [[0, 0, 4], [1, 0, 4], [2, 0, 4], [3, 3, 0]].map(at),
        [1, 1, 2, 3]
    );
    assert_eq!(at([0, 0, 5]), u32::MAX);
}

/// [`on_image`] as it tested bricks before blocks: each brick's grown box against the image's
/// edges, one by one.
fn on_image_brick_by_brick(geometry: &VolumeGeometry, view: &ViewSetup) -> Vec<bool> {
    let to_world = geometry.index_to_world();
    let dims = geometry.dims();
    let bricks = dims.map(|n| n.div_ceil(REGION_BRICK));
    let mut marks = Vec::new();
    for z in 0..bricks[2] {
        for y in 0..bricks[1] {
            for x in 0..bricks[0] {
                let b = [x, y, z];
                // The box's eight corners in the world, the world box round them.
                let lo: [f64; 3] = std::array::from_fn(|a| f64::from(b[a] * REGION_BRICK) - 2.5);
                let hi: [f64; 3] = std::array::from_fn(|a| {
                    f64::from(((b[a] + 1) * REGION_BRICK).min(dims[a])) + 1.5
                });
                let corners: Vec<DVec3> = (0..8)
                    .map(|c| {
                        let p = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
                            if c >> a & 1 == 0 { lo[a] } else { hi[a] }
                        }));
                        to_world.transform_point3(p)
                    })
                    .collect();
                let (wlo, whi) = corners.iter().fold(
                    (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)),
                    |(l, h), &p| (l.min(p), h.max(p)),
                );
                let (centre, half) = (0.5 * (wlo + whi), 0.5 * (whi - wlo));
                let pixel = if view.is_orthographic() {
                    1.0 / view.focal
                } else {
                    ((centre - view.camera.eye).length() + half.length()) / view.focal
                };
                let grown = half + DVec3::splat(3.0 * pixel);
                marks.push(!off_image(view, (centre, grown)));
            }
        }
    }
    marks
}

#[test]
fn bricks_on_the_image_settled_by_blocks_are_the_bricks_tested_one_by_one() {
    // A thin-slice grid's shape (odd sizes: bricks cut short at the far ends), turned off the
    // world's axes so that its boxes are not its bricks' own.
    let turn = glam::DMat3::from_euler(glam::EulerRot::ZYX, 0.4, -0.3, 0.2);
    let placed = glam::DAffine3::from_mat3_translation(
        turn * glam::DMat3::from_diagonal(DVec3::new(0.7, 0.7, 0.62)),
        DVec3::new(-180.0, -150.0, -160.0),
    );
    let geometry = VolumeGeometry::new([203, 187, 171], placed).unwrap();
    let centre = placed.transform_point3(DVec3::new(101.0, 93.0, 85.0));
    let views = [
        // Far: all of it on the image.
        (centre + DVec3::new(0.0, 900.0, 100.0), centre, None),
        // Close-ups of part of it, from two sides.
        (
            centre + DVec3::new(0.0, 120.0, 0.0),
            centre + DVec3::X * 30.0,
            None,
        ),
        (centre + DVec3::new(-90.0, -40.0, 60.0), centre, None),
        // The eye inside the grid, looking along it.
        (centre, centre + DVec3::new(10.0, 3.0, 80.0), None),
        // Orthographic, a part of it.
        (
            centre + DVec3::new(300.0, 0.0, 0.0),
            centre + DVec3::Y * 20.0,
            Some(60.0),
        ),
    ];
    let mut partial = 0;
    for (eye, target, ortho) in views {
        let camera = SceneCamera {
            projection: match ortho {
                Some(height) => crate::scene::Projection::Orthographic { height },
                None => crate::scene::Projection::Perspective {
                    fov_y_degrees: 35.0,
                },
            },
            ..SceneCamera::look_at(eye, target)
        };
        let view = ViewSetup::new(&camera, (320, 200), WORLD).unwrap();
        let want = on_image_brick_by_brick(&geometry, &view);
        let bricks = geometry.dims().map(|n| n.div_ceil(REGION_BRICK));
        let got: Vec<bool> = match on_image(&geometry, &view) {
            None => vec![true; want.len()],
            Some(region) => {
                let mut got = Vec::new();
                for z in 0..bricks[2] {
                    for y in 0..bricks[1] {
                        for x in 0..bricks[0] {
                            got.push(region.covers_brick([x, y, z]));
                        }
                    }
                }
                got
            }
        };
        assert_eq!(got, want, "eye {eye:?}, target {target:?}");
        if want.iter().any(|&w| !w) && want.iter().any(|&w| w) {
            partial += 1;
        }
    }
    // The close-ups, the eye inside and the orthographic part leave bricks out.
    assert!(partial >= 4, "{partial}");
}

#[test]
fn a_copy_is_halved_to_the_previews_level_while_its_voxels_stay_fine() {
    let ct = ([0.7017, 0.7017, 0.6215], [512, 512, 532]);
    // The 0.7 mm LIDC2 CT: halved once (1.4 mm), never twice (2.8 mm).
    assert_eq!(copy_halvings(ct.0, ct.1, 0), 1);
    assert_eq!(copy_halvings(ct.0, ct.1, 1), 1);
    assert_eq!(copy_halvings(ct.0, ct.1, 3), 1);
    // Its 1.4 x 1.4 x 2.5 mm grid is not copied.
    assert_eq!(
        copy_halvings([1.40625, 1.40625, 2.5], [256, 256, 133], 1),
        0
    );
    // A 0.1 mm micro-CT as the preview's level says, up to MAX_LEVEL.
    assert_eq!(copy_halvings([0.1; 3], [1024; 3], 2), 2);
    assert_eq!(copy_halvings([0.05; 3], [1024; 3], 9), MAX_LEVEL);
    // An axis of one voxel is not halved, whatever its spacing.
    assert_eq!(copy_halvings([0.5, 0.5, 9.0], [300, 300, 1], 1), 1);
}

#[test]
fn previews_of_a_volume_windowed_anew_draw_a_coarse_copy_until_a_full_frame() {
    // The wavy field of 96^3 voxels 0.5 mm apart, whose previews copy it once its own grid is
    // not classified for its function: halved once, 48^3 voxels 1 mm apart (the level the
    // preview draws; twice would be past PREVIEW_COPY_SPACING_MM).
    let (mut scene, id) = wavy_field_half_mm();
    let camera = SceneCamera {
        projection: crate::scene::Projection::Perspective {
            fov_y_degrees: 40.0,
        },
        ..SceneCamera::look_at(DVec3::new(10.0, 35.0, -75.0), DVec3::splat(24.0))
    };
    let node = |scene: &Scene| node_of(scene, id);
    let own_transfer = Arc::clone(&node(&scene).transfer);
    let window = |scene: &mut Scene, shift: f32| {
        let mut v = node(scene);
        v.transfer = Arc::new(own_transfer.windowed(350.0 + shift, 200.0));
        scene
            .set_content(id, crate::scene::NodeContent::Volume(v))
            .unwrap();
    };
    let (full, preview) = (
        FrameOptions::default(),
        FrameOptions {
            preview: 1,
            ..FrameOptions::default()
        },
    );
    let shoot = |r: &mut Renderer, scene: &Scene, options: &FrameOptions| {
        r.screenshot_without_gpu(scene, &camera, (64, 64), options)
            .unwrap()
    };
    let fresh = |scene: &Scene, options: &FrameOptions| {
        shoot(
            &mut Renderer::with_compositor(super::super::Compositor::Cpu),
            scene,
            options,
        )
    };
    // The preview drawn from the own grid's levels: after a full frame.
    let own_preview = |scene: &Scene| {
        let mut r = Renderer::with_compositor(super::super::Compositor::Cpu);
        shoot(&mut r, scene, &full);
        shoot(&mut r, scene, &preview)
    };
    let mut renderer = Renderer::with_compositor(super::super::Compositor::Cpu);
    let first = shoot(&mut renderer, &scene, &full);
    assert_eq!(
        (first.report.classified, first.report.coarse_copies),
        (1, 0)
    );
    // A window moved: the preview classifies the copy, not the own grid. Under a raised
    // flag it gives up while it makes the copy, and keeps none.
    window(&mut scene, 0.0);
    renderer.set_cancel(Some(Arc::new(std::sync::atomic::AtomicBool::new(true))));
    let given_up = renderer.screenshot_without_gpu(&scene, &camera, (64, 64), &preview);
    assert!(matches!(given_up, Err(RenderError::Cancelled)));
    assert!(
        (renderer.coarse_copies.get(&id)).is_none_or(|c| c.halved.is_empty()),
        "no copy kept"
    );
    renderer.set_cancel(None);
    let copied = shoot(&mut renderer, &scene, &preview);
    assert_eq!(copied.report.coarse_copies, 1, "{:?}", copied.report);
    assert_eq!(copied.report.classified, 1);
    assert_eq!(copied.report.levels, [1, 1, 1]);
    let stale_own = |r: &Renderer| r.volumes.get(&(id, Detail::default())).map(|s| s.key);
    assert_ne!(stale_own(&renderer), Some(class_key(&node(&scene))));
    // The same picture as the own grid's preview, within what two grids of one field differ
    // by, and not that picture (the copy was drawn).
    let from_own = own_preview(&scene);
    assert_eq!(from_own.report.coarse_copies, 0);
    let error = lit_rmse(&copied.frame, &from_own.frame);
    assert!(error < 0.02 && error > 0.0, "{error}");
    // Drawn again, the copy's classification is kept; a new window classifies the copy
    // again, the copy itself kept.
    let again = shoot(&mut renderer, &scene, &preview);
    assert_eq!(
        (again.report.classified, again.report.coarse_copies),
        (0, 1)
    );
    assert_eq!(again.frame.pixels, copied.frame.pixels);
    let copy = |r: &Renderer| Arc::as_ptr(&r.coarse_copies[&id].halved[0].1);
    let made = copy(&renderer);
    window(&mut scene, 20.0);
    let moved = shoot(&mut renderer, &scene, &preview);
    assert_eq!(
        (moved.report.classified, moved.report.coarse_copies),
        (1, 1)
    );
    assert_eq!(copy(&renderer), made);
    assert_eq!(moved.frame.pixels, fresh(&scene, &preview).frame.pixels);
    // A full frame whose flag is raised gives up in the own grid's classification and keeps
    // nothing of it.
    let raised = Arc::new(std::sync::atomic::AtomicBool::new(true));
    renderer.set_cancel(Some(raised));
    let cancelled = renderer.screenshot_without_gpu(&scene, &camera, (64, 64), &full);
    assert!(matches!(cancelled, Err(RenderError::Cancelled)));
    assert_ne!(stale_own(&renderer), Some(class_key(&node(&scene))));
    renderer.set_cancel(None);
    // The next full frame classifies the own grid and is a fresh renderer's picture; the
    // copy's grid goes, and the previews after it draw the own grid's levels.
    let whole = shoot(&mut renderer, &scene, &full);
    assert_eq!(
        (whole.report.classified, whole.report.coarse_copies),
        (1, 0)
    );
    assert_eq!(whole.frame.pixels, fresh(&scene, &full).frame.pixels);
    let own_volume = node(&scene).volume;
    assert!(
        renderer
            .volumes
            .values()
            .all(|s| Arc::ptr_eq(&s.volume, &own_volume))
    );
    let after = shoot(&mut renderer, &scene, &preview);
    assert_eq!(after.report.coarse_copies, 0);
    assert_eq!(after.frame.pixels, own_preview(&scene).frame.pixels);
}

#[test]
fn a_preview_whose_coarse_copy_the_memory_left_cannot_hold_draws_the_own_grid() {
    // The wavy field windowed anew: its preview would copy it halved once (48^3 values). With
    // the memory left one byte short of that copy, the preview classifies the own grid, as a
    // full frame would, instead of failing; with exactly the copy's bytes left it copies.
    let (mut scene, id) = wavy_field_half_mm();
    let camera = SceneCamera::look_at(DVec3::new(10.0, 35.0, -75.0), DVec3::splat(24.0));
    let preview = FrameOptions {
        preview: 1,
        ..FrameOptions::default()
    };
    let mut v = node_of(&scene, id);
    let copy_bytes =
        48u64.pow(3) * crate::volume::Voxels::held_bytes(v.volume.values.scalar_type()) as u64;
    v.transfer = Arc::new(v.transfer.windowed(350.0, 200.0));
    scene
        .set_content(id, crate::scene::NodeContent::Volume(v))
        .unwrap();
    let shoot = |headroom: u64| {
        let mut r = Renderer::with_compositor(super::super::Compositor::Cpu);
        r.set_headroom(Some(headroom));
        r.screenshot_without_gpu(&scene, &camera, (64, 64), &preview)
    };
    let short = shoot(copy_bytes - 1).expect("a preview with no room for a copy is drawn");
    assert_eq!(
        (short.report.coarse_copies, short.report.classified),
        (0, 1),
        "{:?}",
        short.report
    );
    assert!(short.report.splats > 0);
    let room = shoot(copy_bytes).unwrap();
    assert_eq!(
        (room.report.coarse_copies, room.report.classified),
        (1, 1),
        "{:?}",
        room.report
    );
}

#[test]
fn a_previews_coarse_copy_is_classified_within_the_bricks_on_the_image() {
    // The wavy field of 96^3 voxels 0.5 mm apart seen close up, a part of it on the image. A
    // preview after a new window classifies its coarse copy within the copy's bricks on the
    // image: fewer splats, the picture of the copy classified whole. A turned view that shows
    // bricks it left out classifies it anew, whole, since the camera moves under one function:
    // neither the same view drawn again nor a view turned further classifies it.
    let (mut scene, id) = wavy_field_half_mm();
    let close = |eye: DVec3| SceneCamera {
        projection: crate::scene::Projection::Perspective {
            fov_y_degrees: 20.0,
        },
        ..SceneCamera::look_at(eye, DVec3::splat(24.0))
    };
    let (front, turned) = (
        close(DVec3::new(24.0, 24.0, -10.0)),
        close(DVec3::new(-10.0, 24.0, 24.0)),
    );
    let preview = FrameOptions {
        preview: 1,
        ..FrameOptions::default()
    };
    let shoot = |r: &mut Renderer, scene: &Scene, camera: &SceneCamera, options: &FrameOptions| {
        r.screenshot_without_gpu(scene, camera, (64, 64), options)
            .unwrap()
    };
    // The own grid never classified: previews draw the copy from the first.
    let mut whole = Renderer::with_compositor(super::super::Compositor::Cpu);
    whole.set_refinement_on_image_only(false);
    let mut shown = Renderer::with_compositor(super::super::Compositor::Cpu);
    let mut v = node_of(&scene, id);
    v.transfer = Arc::new(v.transfer.windowed(350.0, 200.0));
    scene
        .set_content(id, crate::scene::NodeContent::Volume(v))
        .unwrap();
    let copy_splats = |r: &Renderer| {
        let copy = &r.coarse_copies[&id].halved[0].1;
        (r.volumes.values())
            .find(|s| Arc::ptr_eq(&s.volume, copy))
            .map(|s| s.classified.grid.len())
            .unwrap()
    };
    let (a, b) = (
        shoot(&mut whole, &scene, &front, &preview),
        shoot(&mut shown, &scene, &front, &preview),
    );
    for s in [&a, &b] {
        assert_eq!((s.report.coarse_copies, s.report.classified), (1, 1));
    }
    assert_eq!(a.frame.pixels, b.frame.pixels);
    let (all, part) = (copy_splats(&whole), copy_splats(&shown));
    assert!(part * 2 < all, "{part} of {all} splats");
    // Turned: the bricks now on the image were partly left out.
    let (a, b) = (
        shoot(&mut whole, &scene, &turned, &preview),
        shoot(&mut shown, &scene, &turned, &preview),
    );
    assert_eq!(a.report.classified, 0);
    assert_eq!(b.report.classified, 1);
    assert_eq!(a.frame.pixels, b.frame.pixels);
    assert_eq!(copy_splats(&shown), all);
    let again = shoot(&mut shown, &scene, &turned, &preview);
    assert_eq!(again.report.classified, 0);
    assert_eq!(again.frame.pixels, b.frame.pixels);
    let further = close(DVec3::new(24.0, 58.0, 24.0));
    let (a, b) = (
        shoot(&mut whole, &scene, &further, &preview),
        shoot(&mut shown, &scene, &further, &preview),
    );
    assert_eq!((a.report.classified, b.report.classified), (0, 0));
    assert_eq!(a.frame.pixels, b.frame.pixels);
    // A new window classifies within the bricks on the image again.
    let mut v = node_of(&scene, id);
    v.transfer = Arc::new(v.transfer.windowed(360.0, 200.0));
    scene
        .set_content(id, crate::scene::NodeContent::Volume(v))
        .unwrap();
    assert_eq!(
        shoot(&mut shown, &scene, &further, &preview)
            .report
            .classified,
        1
    );
    assert!(copy_splats(&shown) * 2 < all);
}

/// The RMSE of two frames' premultiplied colours over the pixels either covers (alpha over
/// 0.02), of which there must be a hundred.
fn lit_rmse(a: &Frame, b: &Frame) -> f64 {
    rmse_where(a, b, |i| a.pixels[i][3].max(b.pixels[i][3]) > 0.02)
}

/// The RMSE of two frames' colour channels over the pixels `lit` chooses by index, of which
/// there must be a hundred.
fn rmse_where(a: &Frame, b: &Frame, lit: impl Fn(usize) -> bool) -> f64 {
    let lit: Vec<usize> = (0..a.pixels.len()).filter(|&i| lit(i)).collect();
    assert!(lit.len() > 100, "{} pixels lit", lit.len());
    let squared: f64 = (lit.iter())
        .flat_map(|&i| (0..3).map(move |c| (i, c)))
        .map(|(i, c)| f64::from(a.pixels[i][c] - b.pixels[i][c]).powi(2))
        .sum();
    (squared / (3 * lit.len()) as f64).sqrt()
}

/// [`wavy_field`] of 96^3 voxels 0.5 mm apart.
fn wavy_field_half_mm() -> (Scene, NodeId) {
    let (mut scene, id) = wavy_field(96);
    let mut half_mm = node_of(&scene, id);
    let mut volume = (*half_mm.volume).clone();
    volume.spacing = [0.5; 3];
    half_mm.volume = Arc::new(volume);
    scene
        .set_content(id, crate::scene::NodeContent::Volume(half_mm))
        .unwrap();
    (scene, id)
}

/// Volume node `id` of `scene`.
fn node_of(scene: &Scene, id: NodeId) -> VolumeNode {
    match &scene.node(id).unwrap().content {
        crate::scene::NodeContent::Volume(v) => v.clone(),
        _ => panic!("node {id:?} is no volume"),
    }
}

#[test]
fn a_frame_cancelled_while_it_makes_a_level_keeps_no_part_of_it() {
    // The wavy field seen small wants levels of detail its own grid's frame did not make; a frame whose
    // flag is raised gives up in the halving (the own grid's classification kept from the
    // frame before) and keeps no new level; the next frame, the flag lowered, makes them and
    // is a fresh renderer's picture.
    let (scene, id) = wavy_field(96);
    let far = SceneCamera::look_at(DVec3::new(48.0, 48.0, -900.0), DVec3::splat(48.0));
    let size = (48, 48);
    let options = FrameOptions::default();
    let mut renderer = Renderer::with_compositor(super::super::Compositor::Cpu);
    // The own grid alone first.
    renderer.set_level_of_detail(false);
    let first = renderer
        .screenshot_without_gpu(&scene, &far, size, &options)
        .unwrap();
    assert_eq!(first.report.classified, 1);
    renderer.set_level_of_detail(true);
    let levels = |r: &Renderer| {
        let mut made: Vec<Detail> = (r.volumes.keys())
            .filter(|(v, d)| *v == id && *d != Detail::default())
            .map(|(_, d)| *d)
            .collect();
        made.sort_by_key(|d| format!("{d:?}"));
        made
    };
    let before = levels(&renderer);
    renderer.set_cancel(Some(Arc::new(std::sync::atomic::AtomicBool::new(true))));
    let cancelled = renderer.screenshot_without_gpu(&scene, &far, size, &options);
    assert!(matches!(cancelled, Err(RenderError::Cancelled)));
    assert_eq!(levels(&renderer), before);
    renderer.set_cancel(None);
    let next = renderer
        .screenshot_without_gpu(&scene, &far, size, &options)
        .unwrap();
    assert!(next.report.levels_made > 0, "{:?}", next.report);
    let fresh = Renderer::with_compositor(super::super::Compositor::Cpu)
        .screenshot_without_gpu(&scene, &far, size, &options)
        .unwrap();
    assert_eq!(next.frame.pixels, fresh.frame.pixels);
}

#[test]
fn a_levels_key_holds_the_end_of_the_one_axis_whose_pairs_it_merges() {
    // The steps from the own grid to a level, walked here as `Renderer::make_levels` takes
    // them: each step halves every axis still short of its level, and a step that halves one
    // axis alone merges that axis's pairs nearer over farther, by the end facing the eye. The
    // key keeps that axis's end and no other: two keys for one level's content would make it
    // twice.
    for code in 0..64u32 {
        let levels = [code % 4, code / 4 % 4, code / 16].map(|l| l as u8);
        for f in 0..27i32 {
            let facing = [f % 3 - 1, f / 3 % 3 - 1, f / 9 - 1].map(|v| v as i8);
            let mut merged_by_ends = [false; 3];
            let mut level = [0u8; 3];
            while level != levels {
                let short: Vec<usize> = (0..3).filter(|&a| level[a] < levels[a]).collect();
                if let [a] = short[..] {
                    merged_by_ends[a] = facing[a] != 0;
                }
                for a in short {
                    level[a] += 1;
                }
            }
            let expected = std::array::from_fn(|a| if merged_by_ends[a] { facing[a] } else { 0 });
            assert_eq!(
                level_facing(levels, facing),
                Detail::Level(levels, expected),
                "{levels:?} {facing:?}"
            );
        }
    }
}

#[test]
fn only_the_cpu_tiles_and_auto_draw_volumes_with_no_adapter_looked_for() {
    use super::super::Compositor;
    assert!(Compositor::Cpu.volumes_without_adapter());
    assert!(!Compositor::Gpu.volumes_without_adapter());
    assert!(!Compositor::GpuTiles.volumes_without_adapter());
    // Auto looks wherever a GPU may be there to find.
    assert_eq!(
        Compositor::Auto.volumes_without_adapter(),
        !super::super::GpuContext::hardware_may_exist()
    );
}

#[test]
fn uneven_levels_are_dropped_least_recently_used_first_past_the_splats_kept() {
    let level = |x: u8| Detail::Level([x, 1, 0], [0; 3]);
    let (a, b, c, d, e) = (
        level(1),
        level(2),
        level(3),
        level(4),
        Detail::Level([0, 1, 0], [0, 1, 0]),
    );
    // Own grid of 100 splats: 200 kept. By last use, 5, 5, 4 come to 170; 3 and 1 go.
    let uneven = vec![(c, 3, 60), (a, 5, 60), (e, 1, 10), (b, 4, 60), (d, 5, 50)];
    let mut dropped = uneven_levels_dropped(uneven, 100, 5);
    dropped.sort_by_key(|d| format!("{d:?}"));
    let mut expected = vec![c, e];
    expected.sort_by_key(|d| format!("{d:?}"));
    assert_eq!(dropped, expected);
    // Levels the frame used stay, however many splats they hold, and push the others out.
    let uneven = vec![(a, 7, 150), (b, 7, 150), (c, 6, 1)];
    assert_eq!(uneven_levels_dropped(uneven, 100, 7), vec![c]);
    // Within the splats kept, nothing goes.
    let uneven = vec![(a, 1, 100), (b, 2, 99)];
    assert!(uneven_levels_dropped(uneven, 100, 9).is_empty());
}

#[test]
fn a_level_halved_most_along_two_axes_is_made_once_for_a_camera_crossing_one() {
    // The wavy field with slices 4 mm apart, seen from far across the diagonal of x and y
    // and then across the other diagonal: its x and y voxels fall nearer together on the
    // screen than its z voxels, so both views draw the grid halved as much along x as along y
    // and less along z. The view's end of y turns round between them, but that level merges
    // no pair along an axis by its ends: the second frame makes nothing and draws what a
    // fresh renderer draws.
    let (mut scene, id) = wavy_field(96);
    let mut thick = node_of(&scene, id);
    let mut volume = (*thick.volume).clone();
    volume.spacing = [1.0, 1.0, 4.0];
    thick.volume = Arc::new(volume);
    scene
        .set_content(id, crate::scene::NodeContent::Volume(thick))
        .unwrap();
    let centre = DVec3::new(48.0, 48.0, 192.0);
    let seen = |dir: DVec3| SceneCamera {
        projection: crate::scene::Projection::Perspective {
            fov_y_degrees: 20.0,
        },
        ..SceneCamera::look_at(centre + 1400.0 * dir.normalize(), centre)
    };
    let (first, second) = (
        seen(DVec3::new(1.0, 1.0, 0.0)),
        seen(DVec3::new(1.0, -1.0, 0.0)),
    );
    let size = (48, 48);
    let options = FrameOptions::default();
    let mut renderer = Renderer::with_compositor(super::super::Compositor::Cpu);
    renderer.set_levels_by_brick(false);
    let a = renderer
        .screenshot_without_gpu(&scene, &first, size, &options)
        .unwrap();
    let [x, y, z] = a.report.levels;
    assert!(x == y && x > z, "{:?}", a.report);
    assert!(a.report.levels_made > 0, "{:?}", a.report);
    let b = renderer
        .screenshot_without_gpu(&scene, &second, size, &options)
        .unwrap();
    assert_eq!(b.report.levels, a.report.levels, "{:?}", b.report);
    assert_eq!(b.report.levels_made, 0, "{:?}", b.report);
    let mut fresh = Renderer::with_compositor(super::super::Compositor::Cpu);
    fresh.set_levels_by_brick(false);
    let c = fresh
        .screenshot_without_gpu(&scene, &second, size, &options)
        .unwrap();
    assert_eq!(c.report.levels, b.report.levels);
    assert_eq!(c.frame.pixels, b.frame.pixels);
}

#[test]
fn the_levels_given_up_for_a_new_one_are_the_least_recently_used_that_make_room() {
    let each = crate::budget::LEVEL_SPLAT_BYTES;
    let spare = || vec![('a', 7, 10), ('b', 3, 20), ('c', 5, 40)];
    // Room enough already: nothing given up.
    assert_eq!(levels_given_up(spare(), 100, 100), Some(vec![]));
    // b (the least recently used) frees 20 splats' bytes, enough.
    assert_eq!(levels_given_up(spare(), 20 * each, 0), Some(vec!['b']));
    // b and c, then a too.
    assert_eq!(
        levels_given_up(spare(), 20 * each + 1, 0),
        Some(vec!['b', 'c'])
    );
    assert_eq!(
        levels_given_up(spare(), 70 * each, 0),
        Some(vec!['b', 'c', 'a'])
    );
    // Not even all of them: none given up.
    assert_eq!(levels_given_up(spare(), 70 * each + 1, 0), None);
    assert_eq!(levels_given_up(Vec::<(char, u64, u64)>::new(), 1, 0), None);
}

#[test]
fn a_level_the_memory_left_cannot_hold_gives_up_levels_kept_or_draws_finer() {
    // The wavy field seen along x, then along y, near enough that each view wants its own
    // grid halved once along the view: two uneven levels, each made from the own grid. With
    // the memory left set just short of what the second needs, even once the first is given
    // up, nothing is given up and the own grid draws; set at what it needs, the first level
    // goes and the second is made, the picture a fresh renderer's.
    let (scene, id) = wavy_field(96);
    let centre = DVec3::splat(48.0);
    let seen = |dir: DVec3| SceneCamera {
        projection: crate::scene::Projection::Perspective {
            fov_y_degrees: 20.0,
        },
        ..SceneCamera::look_at(centre + 300.0 * dir, centre)
    };
    let (along_x, along_y) = (seen(DVec3::X), seen(DVec3::Y));
    let (size, options) = ((48, 48), FrameOptions::default());
    let levels = |r: &Renderer| {
        let mut held: Vec<(Detail, usize)> = (r.volumes.iter())
            .filter(|((v, _), _)| *v == id)
            .map(|((_, d), s)| (*d, s.classified.grid.len()))
            .collect();
        held.sort_by_key(|(d, _)| format!("{d:?}"));
        held
    };
    let shoot = |r: &mut Renderer, camera: &SceneCamera| {
        r.screenshot_without_gpu(&scene, camera, size, &options)
            .unwrap()
    };
    let mut renderer = Renderer::with_compositor(super::super::Compositor::Cpu);
    renderer.set_levels_by_brick(false);
    let a = shoot(&mut renderer, &along_x);
    assert!(!a.report.levels_short_of_memory);
    let after_a = levels(&renderer);
    let own = after_a
        .iter()
        .find(|(d, _)| *d == Detail::default())
        .map(|&(_, n)| n as u64)
        .unwrap();
    let uneven: Vec<_> = after_a.iter().filter(|(d, _)| is_uneven(*d)).collect();
    assert_eq!((after_a.len(), uneven.len()), (2, 1), "{after_a:?}");
    let first = uneven[0].1 as u64;
    assert!(first < own, "{after_a:?}");
    let each = crate::budget::LEVEL_SPLAT_BYTES;
    renderer.set_headroom(Some((own - first) * each - 1));
    let short = shoot(&mut renderer, &along_y);
    assert!(short.report.levels_short_of_memory, "{:?}", short.report);
    assert_eq!((short.report.levels, short.report.levels_made), ([0; 3], 0));
    assert_eq!(levels(&renderer), after_a);
    let mut whole = Renderer::with_compositor(super::super::Compositor::Cpu);
    whole.set_level_of_detail(false);
    assert_eq!(short.frame.pixels, shoot(&mut whole, &along_y).frame.pixels);
    renderer.set_headroom(Some((own - first) * each));
    let b = shoot(&mut renderer, &along_y);
    assert!(!b.report.levels_short_of_memory, "{:?}", b.report);
    assert_eq!(b.report.levels_made, 1, "{:?}", b.report);
    let after_b = levels(&renderer);
    assert!(!after_b.contains(uneven[0]), "{after_b:?}");
    assert_eq!(after_b.iter().filter(|(d, _)| is_uneven(*d)).count(), 1);
    let mut fresh = Renderer::with_compositor(super::super::Compositor::Cpu);
    fresh.set_levels_by_brick(false);
    assert_eq!(b.frame.pixels, shoot(&mut fresh, &along_y).frame.pixels);
}

#[test]
fn a_coarser_preview_draws_a_level_coarser_where_the_view_wants_one_and_floors_all_axes() {
    // A full frame: what the view wants.
    assert_eq!(preview_level(2, 0), 2);
    // The viewer's previews: at least a level above the own grid.
    assert_eq!(preview_level(0, 1), 1);
    assert_eq!(preview_level(2, 1), 2);
    // Coarser previews: a level coarser than the view wants for each step past the first,
    // at least their coarseness above the own grid, within the pyramid.
    assert_eq!(preview_level(0, 2), 2);
    assert_eq!(preview_level(1, 2), 2);
    assert_eq!(preview_level(2, 2), 3);
    assert_eq!(preview_level(MAX_LEVEL, 3), MAX_LEVEL);
    assert_eq!(preview_level(u8::MAX, 2), MAX_LEVEL);
    // The gap between two axes' levels never widens (a level halved along the view stays
    // within MAX_DEPTH_LEVELS of the others).
    for n in 0..=MAX_LEVEL + 1 {
        for a in 0..=MAX_LEVEL {
            for b in a..=(a + MAX_DEPTH_LEVELS).min(MAX_LEVEL) {
                let (pa, pb) = (preview_level(a, n), preview_level(b, n));
                assert!(pa <= pb && pb - pa <= b - a, "{a} {b} at {n}: {pa} {pb}");
            }
        }
    }
}
