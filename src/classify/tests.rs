use super::*;

#[test]
fn uniform_in_plane_keeps_labels_whose_clamped_square_holds_them_alone() {
    // Planes of every small shape, labels from a fixed hash, against the 3x3 test done
    // voxel by voxel.
    for (nx, ny) in [(1, 1), (1, 4), (4, 1), (2, 2), (5, 3), (7, 6)] {
        for seed in 0..20u32 {
            let labels: Vec<u8> = (0..nx * ny)
                .map(|i| {
                    let h = (i as u32 ^ seed.wrapping_mul(2654435761)).wrapping_mul(40503);
                    [0u8, 1, 1, 1, 2][(h >> 7) as usize % 5]
                })
                .collect();
            let got = uniform_in_plane(&labels, nx, ny);
            for y in 0..ny {
                for x in 0..nx {
                    let label = labels[y * nx + x];
                    let mut alone = true;
                    for dy in [-1i64, 0, 1] {
                        for dx in [-1i64, 0, 1] {
                            let qx = (x as i64 + dx).clamp(0, nx as i64 - 1) as usize;
                            let qy = (y as i64 + dy).clamp(0, ny as i64 - 1) as usize;
                            alone &= labels[qy * nx + qx] == label;
                        }
                    }
                    let want = if alone { label } else { 0 };
                    assert_eq!(got[y * nx + x], want, "{nx}x{ny} seed {seed} at {x},{y}");
                }
            }
        }
    }
}

#[test]
fn the_automatic_transfer_function_follows_the_values() {
    let ct: Vec<f32> = (0..1000).map(|i| -1024.0 + 3.0 * i as f32).collect();
    let auto = auto_transfer(&ct.clone().into());
    assert!(
        auto.hounsfield && auto.reason.starts_with("ct-bone"),
        "{}",
        auto.reason
    );
    assert_eq!(auto.transfer, TransferFunction::ct_bone());
    // 8-bit data: most voxels background (0), the object spread over 1 to 200: the ramp
    // spans the 90th to 99.5th percentile of the object's values.
    let mut bytes = vec![0.0f32; 10_000];
    bytes.extend((1..=200).flat_map(|v| std::iter::repeat_n(v as f32, 10)));
    let auto = auto_transfer(&bytes.clone().into());
    assert!(!auto.hounsfield);
    let points = auto.transfer.points();
    let (from, to) = (points[0].0, points[points.len() - 1].0);
    assert!(
        (from - 180.0).abs() < 1.0 && (to - 199.0).abs() < 1.0,
        "{from} to {to}"
    );
    assert!(auto.reason.contains("percentile"), "{}", auto.reason);
    // Constant or empty data still give a usable function.
    for values in [vec![7.0; 10], Vec::new(), vec![f32::NAN; 3]] {
        let auto = auto_transfer(&values.clone().into());
        assert!(
            auto.transfer.points().iter().all(|(v, _)| v.is_finite()),
            "{values:?}"
        );
    }
    assert!(is_hounsfield(&vec![-600.0, 40.0].into()) && !is_hounsfield(&vec![0.0, 4000.0].into()));
}
use glam::DMat3;

/// A `dims` grid of 1 mm voxels at the origin, axis-aligned, holding `values`.
fn unit_volume(dims: [u32; 3], values: impl Into<crate::volume::Voxels>) -> CpuVolume {
    CpuVolume {
        dims,
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values: values.into(),
    }
}

#[test]
fn sample_interpolates_and_clamps() {
    let tf = TransferFunction::ramp(100.0, 200.0, [1.0, 0.5, 0.0, 0.8]);
    assert_eq!(tf.sample(50.0)[3], 0.0);
    assert!((tf.sample(150.0)[3] - 0.4).abs() < 1e-6);
    assert_eq!(tf.sample(500.0), [1.0, 0.5, 0.0, 0.8]);
    assert_eq!(tf.sample(f32::NAN)[3], 0.0);
}

#[test]
fn presets_windows_and_shifts() {
    for name in TransferFunction::PRESETS {
        let tf = TransferFunction::preset(name).unwrap();
        assert!(tf.points().len() >= 2, "{name}");
        assert_eq!(tf.sample(-5000.0)[3], 0.0, "{name}: air is clear");
    }
    assert!(TransferFunction::preset("ct-lung").is_none());
    let bone = TransferFunction::ct_bone();
    assert_eq!(bone.shifted(100.0).sample(400.0), bone.sample(300.0));
    let w = bone.windowed(500.0, 1000.0);
    assert_eq!(
        (w.points()[0].0, w.points().last().unwrap().0),
        (0.0, 1000.0)
    );
    assert_eq!(w.sample(1000.0), bone.sample(1200.0));
    // The metal preset keeps bone faint and metal nearly opaque.
    let metal = TransferFunction::ct_metal();
    assert!(metal.sample(700.0)[3] < 0.15 && metal.sample(3000.0)[3] > 0.8);
}

#[test]
fn densities_add_up_to_the_transfer_function_along_a_ray() {
    // A ray along an index axis crosses one layer of splats per index step; each splat
    // puts density * step_mm * exp(-r^2 / 2 sigma^2) on it (r its distance from the ray, in
    // voxels), so per millimetre the ray meets density times the layer's sum of
    // footprints, whatever the step. That must be the transfer function's extinction,
    // -ln(1 - a) per millimetre: checked with the layer summed over the lattice by brute
    // force, for rays through a lattice point and between points, two splat sizes.
    for (sigma, cutoff) in [(0.7, 2.0), (1.0, 3.0)] {
        let opacity = Opacity {
            sigma,
            cutoff,
            ..Default::default()
        };
        for offset in [[0.0, 0.0], [0.5, 0.5], [0.3, 0.1]] {
            let mut layer = 0.0;
            for i in -10i32..=10 {
                for j in -10i32..=10 {
                    let (dx, dy) = (f64::from(i) - offset[0], f64::from(j) - offset[1]);
                    let r2 = dx * dx + dy * dy;
                    if r2 <= cutoff * cutoff {
                        layer += (-0.5 * r2 / (sigma * sigma)).exp();
                    }
                }
            }
            for a in [0.3f32, 0.02, 0.9] {
                let per_mm = f64::from(opacity.density(a)) * layer;
                let want = -(1.0 - f64::from(a)).ln();
                assert!(
                    (per_mm - want).abs() < 0.01 * want,
                    "sigma {sigma}, ray at {offset:?}, opacity {a}: {per_mm} against {want}"
                );
            }
        }
    }
    let opacity = Opacity::default();
    assert_eq!(opacity.density(0.0), 0.0);
    assert_eq!(opacity.density(f32::NAN), 0.0);
    let opaque = opacity.density(1.0);
    assert!(
        opaque.is_finite() && splat_alpha(opaque, 1.0) > 0.9999,
        "{opaque}"
    );
    assert_eq!(splat_alpha(f32::INFINITY, 0.5), 1.0);
    assert_eq!(splat_alpha(0.3, 0.0), 0.0);
    // Twice the reference length: half the density.
    let two = Opacity {
        reference_mm: 2.0,
        ..opacity
    };
    assert!((two.density(0.5) * 2.0 - opacity.density(0.5)).abs() < 1e-6);
}

#[test]
fn the_view_step_follows_the_spacing_along_the_view() {
    let l = glam::DMat3::from_diagonal(glam::DVec3::new(1.4, 1.4, 2.5));
    let step = |d: [f64; 3]| view_step_mm(l, glam::DVec3::from(d)).unwrap();
    assert!((step([1.0, 0.0, 0.0]) - 1.4).abs() < 1e-12);
    assert!((step([0.0, -3.0, 0.0]) - 1.4).abs() < 1e-12);
    assert!((step([0.0, 0.0, 1.0]) - 2.5).abs() < 1e-12);
    // Diagonally in x and z: 1 / sqrt((0.5 / 1.4^2) + (0.5 / 2.5^2)).
    let want = 1.0 / (0.5 / 1.96 + 0.5 / 6.25f64).sqrt();
    assert!((step([1.0, 0.0, 1.0]) - want).abs() < 1e-12);
    assert!(view_step_mm(l, glam::DVec3::ZERO).is_none());
    assert!(view_step_mm(l, glam::DVec3::NAN).is_none());
    assert!(view_step_mm(glam::DMat3::ZERO, glam::DVec3::X).is_none());
}

/// The definition of a voxel's splat, computed the plain way: the trilinear field (its
/// own interpolation, the grid clamped at its faces) classified at the eight points a
/// quarter voxel from the centre, `-ln(1 - a)` averaged, colours weighted by it; a point past
/// the outer voxel centres along an axis of more than one voxel adds nothing.
#[test]
fn open_voxels_are_found_word_by_word_as_one_by_one() {
    // Rows of every length around the 8-byte words, open voxels from a fixed hash (runs of
    // both kinds and lone ones), against a plain filter; and the slice test against its
    // definition.
    for n in [0usize, 1, 7, 8, 9, 16, 23, 40] {
        for seed in 0..16u32 {
            let mix = |i: usize, k: u32| {
                (i as u32 ^ seed.wrapping_mul(2654435761) ^ k).wrapping_mul(40503) >> 9
            };
            let [below, here, above]: [Vec<u8>; 3] = std::array::from_fn(|k| {
                (0..n)
                    .map(|i| if mix(i / 3, k as u32) % 4 == 0 { 0 } else { 1 })
                    .collect()
            });
            let mut open = vec![9u8; n];
            open_in_slice(&below, &here, &above, &mut open);
            for i in 0..n {
                let want = here[i] == 0 || here[i] != below[i] || here[i] != above[i];
                assert_eq!(open[i], u8::from(want), "{n} seed {seed} at {i}");
            }
            let mut got = Vec::new();
            for_each_open(&open, |x| got.push(x));
            let want: Vec<usize> = (0..n).filter(|&i| open[i] == 1).collect();
            assert_eq!(got, want, "{n} seed {seed}");
        }
    }
}

#[test]
fn cells_in_clear_air_are_left_out_and_all_others_kept_on_a_wide_grid() {
    // Rows longer than the 8-voxel words, with tissue in patches and single voxels amid
    // clear air: every voxel whose cell reaches tissue is a splat with its cell's values (the
    // oracle classifies every voxel), whether it lies in a word of air or not.
    let dims = [37u32, 6, 5];
    let values: Vec<f32> = (0..37 * 6 * 5u32)
        .map(|id| {
            let k = [id % 37, id / 37 % 6, id / (37 * 6)];
            let h = (k[0] / 5 + 7 * k[1] + 13 * k[2]).wrapping_mul(2654435761) >> 27;
            let lone = (id.wrapping_mul(40503) >> 5) % 29 == 0;
            if h % 3 == 0 || lone {
                (90 + (id * 7) % 80) as f32
            } else {
                (id % 40) as f32
            }
        })
        .collect();
    let volume = unit_volume(dims, values);
    let tf = TransferFunction::new(vec![
        (60.0, [1.0, 0.8, 0.6, 0.0]),
        (160.0, [1.0, 1.0, 1.0, 0.8]),
    ]);
    let classified = classify(&volume, &tf, 0.0).unwrap();
    let (kept, left) = check_cells(&volume, &tf, [1; 3], &classified);
    assert!(kept > 100 && left > 100, "{kept} kept, {left} left out");
}

/// A ramp (one segment, the tables' path without a search) and a function of three points
/// (two segments, searched).
fn ramp_and_three() -> [TransferFunction; 2] {
    [
        TransferFunction::ramp(60.0, 190.0, [1.0, 0.93, 0.85, 0.6]),
        TransferFunction::new(vec![
            (10.0, [1.0, 0.0, 0.0, 0.0]),
            (90.0, [0.0, 1.0, 0.0, 0.5]),
            (200.0, [0.0, 0.0, 1.0, 1.0]),
        ]),
    ]
}

#[test]
fn rows_sampled_whole_classify_as_voxels_one_at_a_time() {
    // Grids of tissue patches, ramps and lone voxels in clear air, narrow and wide, of three
    // voxel types, through a ramp and a function of several segments: the cells of each row
    // sampled whole give the same splats, bit for bit, as each voxel's block (which the
    // faces still take), on the own grid and refined.
    let [ramp, three] = ramp_and_three();
    for dims in [[3u32, 3, 3], [4, 5, 3], [37, 6, 5], [70, 9, 20]] {
        let n = dims.iter().product::<u32>();
        let value = |id: u32| {
            let k = [
                id % dims[0],
                id / dims[0] % dims[1],
                id / (dims[0] * dims[1]),
            ];
            let patch = (k[0] / 6 + 5 * k[1] + 11 * k[2]).wrapping_mul(2654435761) >> 28;
            let lone = (id.wrapping_mul(40503) >> 4).is_multiple_of(31);
            if patch.is_multiple_of(3) || lone {
                (50 + (id * 37) % 180) as f32
            } else {
                (k[0] * 3 % 50) as f32
            }
        };
        let f32s: Vec<f32> = (0..n).map(value).collect();
        let u8s: Vec<u8> = f32s.iter().map(|&v| v as u8).collect();
        let i16s: Vec<i16> = f32s.iter().map(|&v| v as i16 - 40).collect();
        let values: [crate::volume::Voxels; 3] = [f32s.into(), u8s.into(), i16s.into()];
        for values in values {
            let volume = CpuVolume {
                dims,
                spacing: [0.7, 0.7, 1.2],
                origin: [0.0; 3],
                direction: DMat3::IDENTITY,
                values,
            };
            for (tf, factors) in [
                (&ramp, [1; 3]),
                (&three, [1; 3]),
                (&ramp, [3, 2, 1]),
                (&three, [2, 1, 3]),
            ] {
                let options = ClassifyOptions::default();
                let whole =
                    classify_cells(&volume, tf, &options, factors, true, None, None).unwrap();
                let blocks =
                    classify_cells(&volume, tf, &options, factors, false, None, None).unwrap();
                assert!(!whole.grid.is_empty(), "{dims:?}: no splat");
                assert_eq!(
                    whole.grid.ids().collect::<Vec<_>>(),
                    blocks.grid.ids().collect::<Vec<_>>(),
                    "{dims:?}, {factors:?}"
                );
                assert_eq!(whole.colors.len(), blocks.colors.len());
                for (a, b) in whole.colors.iter().zip(&blocks.colors) {
                    assert_eq!(
                        (a.rgb, a.density.to_bits()),
                        (b.rgb, b.density.to_bits()),
                        "{dims:?}, {factors:?}"
                    );
                }
            }
        }
    }
}

/// Every voxel of `classified`, the classification of `volume` on the grid `factors` times
/// finer, against [`fine_cell_oracle`]: a splat where the cell has opacity, with its
/// density and colour; returns how many voxels were kept and left out.
fn check_cells(
    volume: &CpuVolume,
    tf: &TransferFunction,
    factors: [u32; 3],
    classified: &Classified,
) -> (usize, usize) {
    let fine = refined_dims(volume.dims, factors).unwrap();
    assert_eq!(classified.grid.dims(), fine);
    let scale = Opacity::default().scale() as f32;
    let (mut kept, mut left) = (0, 0);
    for id in 0..fine.iter().product::<u32>() {
        let k = [
            id % fine[0],
            id / fine[0] % fine[1],
            id / (fine[0] * fine[1]),
        ]
        .map(|v| v as usize);
        let (depth, rgb) = fine_cell_oracle(volume, tf, factors, k);
        let Some(rank) = classified.grid.rank(id) else {
            assert!(
                depth <= 0.0,
                "{factors:?}: {k:?} left out with depth {depth}"
            );
            left += 1;
            continue;
        };
        kept += 1;
        let c = classified.colors[rank as usize];
        let want = depth as f32 * scale;
        assert!(
            (c.density.to_f32() / want - 1.0).abs() < 2e-3,
            "{factors:?}: {k:?}: density {} against {want}",
            { c.density }
        );
        for i in 0..3 {
            assert!(
                (f64::from(c.rgb[i]) - rgb[i] * 255.0).abs() <= 0.6,
                "{factors:?}: {k:?}: {:?} against {rgb:?}",
                c.rgb
            );
        }
    }
    (kept, left)
}

/// The mean extinction and colour over the cell of voxel `k` of the grid `factors` times
/// finer than `volume`'s, by plain trilinear interpolation at the eight quarter points.
fn fine_cell_oracle(
    volume: &CpuVolume,
    tf: &TransferFunction,
    factors: [u32; 3],
    k: [usize; 3],
) -> (f64, [f64; 3]) {
    let n = volume.dims.map(|n| n as f64);
    let at = |p: [f64; 3]| {
        let p: [f64; 3] = std::array::from_fn(|a| p[a].clamp(0.0, n[a] - 1.0));
        let i: [usize; 3] = std::array::from_fn(|a| p[a].floor() as usize);
        let mut sum = 0.0;
        for corner in 0..8usize {
            let mut w = 1.0;
            let mut q = [0usize; 3];
            for a in 0..3 {
                let t = p[a] - i[a] as f64;
                let up = corner >> a & 1 == 1;
                q[a] = (i[a] + usize::from(up)).min(volume.dims[a] as usize - 1);
                w *= if up { t } else { 1.0 - t };
            }
            let [nx, ny, _] = volume.dims.map(|n| n as usize);
            sum += w * f64::from(volume.values.at(q[0] + nx * (q[1] + ny * q[2])));
        }
        sum
    };
    let (mut depth, mut rgb) = (0.0, [0.0; 3]);
    for corner in 0..8 {
        let p: [f64; 3] = std::array::from_fn(|a| {
            let f = f64::from(factors[a]);
            (k[a] as f64 + 0.5 + if corner >> a & 1 == 1 { 0.25 } else { -0.25 }) / f - 0.5
        });
        // Past the outer voxel centres there is no tissue (an axis of one voxel aside).
        let outside = (0..3).any(|a| n[a] > 1.0 && (p[a] < 0.0 || p[a] > n[a] - 1.0));
        if outside {
            continue;
        }
        let c = tf.sample(at(p) as f32).map(f64::from);
        let d = -(1.0 - c[3].min(1.0)).ln();
        depth += d / 8.0;
        for i in 0..3 {
            rgb[i] += d / 8.0 * c[i];
        }
    }
    (
        depth,
        rgb.map(|v| if depth > 0.0 { v / depth } else { 0.0 }),
    )
}

#[test]
fn a_splat_carries_its_cells_classified_field() {
    // Values rising along every axis with a thin bright plane, through a ramp: voxels whose
    // centre is transparent but whose cell reaches into the ramp become splats, and each
    // splat's density and colour are the cell's, checked against the plain computation.
    let dims = [5u32, 4, 6];
    let values: Vec<f32> = (0..5 * 4 * 6)
        .map(|id| {
            let k = [id % 5, id / 5 % 4, id / 20];
            let plane = if k[2] == 3 { 180.0 } else { 0.0 };
            (k[0] * 9 + k[1] * 4 + k[2] * 6) as f32 + plane
        })
        .collect();
    let volume = CpuVolume {
        dims,
        spacing: [0.5, 1.0, 2.0],
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values: values.into(),
    };
    let tf = TransferFunction::new(vec![
        (60.0, [1.0, 0.2, 0.1, 0.0]),
        (150.0, [0.2, 0.9, 1.0, 0.7]),
    ]);
    let classified = classify(&volume, &tf, 0.0).unwrap();
    let (kept, _) = check_cells(&volume, &tf, [1; 3], &classified);
    // Centres at or above 60: k.x * 9 + k.y * 4 + k.z * 6 >= 60, or on the plane.
    let centres = (0..5 * 4 * 6u32)
        .filter(|id| {
            let k = [id % 5, id / 5 % 4, id / 20];
            k[0] * 9 + k[1] * 4 + k[2] * 6 > 60 || k[2] == 3
        })
        .count();
    assert!(
        kept > centres,
        "cells reach past their centres: {kept} against {centres}"
    );
}

#[test]
fn a_refined_splat_carries_its_fine_cells_field() {
    // The same kind of field on a small grid, refined unevenly along the axes: every fine
    // voxel's splat against the plain computation at its own quarter points, the fine
    // voxels tiling the coarse grid's box.
    let dims = [4u32, 3, 5];
    let values: Vec<f32> = (0..4 * 3 * 5)
        .map(|id| {
            let k = [id % 4, id / 4 % 3, id / 12];
            let plane = if k[1] == 1 { 140.0 } else { 0.0 };
            (k[0] * 17 + k[1] * 5 + k[2] * 11) as f32 + plane
        })
        .collect();
    let volume = CpuVolume {
        dims,
        spacing: [1.0, 1.0, 2.5],
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values: values.into(),
    };
    let tf = TransferFunction::new(vec![
        (50.0, [1.0, 0.2, 0.1, 0.0]),
        (160.0, [0.2, 0.9, 1.0, 0.8]),
    ]);
    let options = ClassifyOptions {
        min_opacity: 0.0,
        ..Default::default()
    };
    for factors in [[2u32, 3, 1], [1, 2, 4], [3, 3, 3]] {
        let classified = classify_refined(&volume, &tf, &options, factors).unwrap();
        let (kept, left) = check_cells(&volume, &tf, factors, &classified);
        assert!(
            kept > 10 && left > 10,
            "{factors:?}: {kept} kept, {left} left"
        );
    }
    // Factors of one: the own grid's classification.
    let own = classify_with(&volume, &tf, &options).unwrap();
    let same = classify_refined(&volume, &tf, &options, [1, 1, 1]).unwrap();
    assert_eq!(own.grid.dims(), same.grid.dims());
    assert_eq!(own.colors, same.colors);
}

#[test]
fn a_refined_gradient_is_the_fields_along_the_fine_axes() {
    // A field linear in x and z: its gradient is the same everywhere inside, and in the
    // fine grid's index space each component shrinks by its axis's factor.
    let dims = [6u32, 5, 7];
    let values: Vec<f32> = (0..6 * 5 * 7)
        .map(|id| {
            let k = [id % 6, id / 6 % 5, id / 30];
            (3 * k[0] + 4 * k[2]) as f32
        })
        .collect();
    let volume = unit_volume(dims, values);
    let factors = [2u32, 1, 4];
    let n = refined_gradient_snorm8(&volume, factors, [5, 2, 13]).unwrap();
    let n = n.map(|v| f32::from(v as i8) / 127.0);
    let want = glam::Vec3::new(-3.0 / 2.0, 0.0, -4.0 / 4.0).normalize();
    for a in 0..3 {
        assert!((n[a] - want[a]).abs() < 0.02, "{n:?} against {want}");
    }
    assert_eq!(
        refined_gradient_snorm8(&volume, [1; 3], [2, 2, 2]),
        gradient_snorm8(&volume, [2, 2, 2])
    );
}

/// The own voxel that fine voxel `id` of a refinement by `factors` (a `fine` grid) splits.
fn coarse_voxel(fine: [u32; 3], factors: [u32; 3], id: u32) -> [u32; 3] {
    let f = [
        id % fine[0],
        id / fine[0] % fine[1],
        id / (fine[0] * fine[1]),
    ];
    [0, 1, 2].map(|a| f[a] / factors[a])
}

/// A `dims` volume whose value at voxel `k` is `k . slopes` folded back into `0..fold`: ramps
/// of tissue in every direction, each fold a sharp edge.
fn folded_ramp(dims: [u32; 3], slopes: [u32; 3], fold: f32) -> CpuVolume {
    let values: Vec<f32> = (0..dims.iter().product::<u32>())
        .map(|id| {
            let k = [
                id % dims[0],
                id / dims[0] % dims[1],
                id / (dims[0] * dims[1]),
            ];
            (k[0] * slopes[0] + k[1] * slopes[1] + k[2] * slopes[2]) as f32 % fold
        })
        .collect();
    unit_volume(dims, values)
}

#[test]
fn a_region_leaves_out_the_fine_voxels_of_the_bricks_it_does_not_cover() {
    // A ramp of tissue through a 19 x 13 x 11 grid, refined 2 x 3 x 1, in bricks of 4: the
    // classification within a checkerboard of bricks is the whole one's splats whose coarse
    // voxel lies in a covered brick, the same ids and colours, with and without rows sampled
    // whole.
    let dims = [19u32, 13, 11];
    let volume = folded_ramp(dims, [7, 3, 5], 200.0);
    let tf = TransferFunction::ramp(40.0, 160.0, [1.0, 0.5, 0.25, 0.8]);
    let factors = [2u32, 3, 1];
    let region = Region::new(dims, 4, |b| (b[0] + b[1] + b[2]) % 2 == 0).unwrap();
    assert!(!region.is_whole());
    let whole = classify_refined(&volume, &tf, &ClassifyOptions::default(), factors).unwrap();
    let fine = whole.grid.dims();
    let coarse = |id: u32| coarse_voxel(fine, factors, id);
    let want: Vec<(u32, [u8; 3])> = whole
        .grid
        .ids()
        .zip(&whole.colors)
        .filter(|(id, _)| region.covers(coarse(*id)))
        .map(|(id, c)| (id, c.rgb))
        .collect();
    assert!(!want.is_empty() && want.len() < whole.colors.len());
    for by_rows in [true, false] {
        let options = ClassifyOptions::default();
        let within = classify_cells(
            &volume,
            &tf,
            &options,
            factors,
            by_rows,
            Some(&region),
            None,
        )
        .unwrap();
        let got: Vec<(u32, [u8; 3])> = within
            .grid
            .ids()
            .zip(&within.colors)
            .map(|(id, c)| (id, c.rgb))
            .collect();
        assert_eq!(got, want, "rows sampled whole: {by_rows}");
    }
    // Containment: a region contains itself and what it covers a part of.
    let elsewhere = Region::new([19, 13, 12], 4, |_| true).unwrap();
    assert!(matches!(
        classify_refined_in(
            &volume,
            &tf,
            &ClassifyOptions::default(),
            factors,
            Some(&elsewhere),
            None
        ),
        Err(GridError::RegionMismatch { .. })
    ));
    let fewer = Region::new(dims, 4, |b| b == [0, 0, 0]).unwrap();
    assert!(region.contains(&fewer) && region.contains(&region));
    assert!(!fewer.contains(&region));
    let both = fewer
        .union(&Region::new(dims, 4, |b| b == [1, 0, 0]).unwrap())
        .unwrap();
    assert!(both.covers([0, 0, 0]) && both.covers([4, 3, 3]) && !both.covers([8, 0, 0]));
    assert!(
        fewer
            .union(&Region::new(dims, 2, |_| true).unwrap())
            .is_none()
    );
}

#[test]
fn a_refinement_whose_cancel_flag_is_raised_gives_up_and_one_left_lowered_is_unchanged() {
    use std::sync::atomic::AtomicBool;
    let dims = [19u32, 13, 11];
    let volume = folded_ramp(dims, [5, 11, 3], 190.0);
    let tf = TransferFunction::ramp(40.0, 160.0, [1.0, 0.5, 0.25, 0.8]);
    let options = ClassifyOptions::default();
    let factors = [2u32, 1, 3];
    let region = Region::new(dims, 4, |b| b[0] <= b[2]).unwrap();
    for region in [None, Some(&region)] {
        let plain = classify_refined_in(&volume, &tf, &options, factors, region, None).unwrap();
        assert!(!plain.colors.is_empty());
        let lowered = AtomicBool::new(false);
        let kept =
            classify_refined_in(&volume, &tf, &options, factors, region, Some(&lowered)).unwrap();
        assert_eq!(
            kept.grid.ids().collect::<Vec<_>>(),
            plain.grid.ids().collect::<Vec<_>>()
        );
        assert_eq!(kept.colors, plain.colors);
        let raised = AtomicBool::new(true);
        assert!(matches!(
            classify_refined_in(&volume, &tf, &options, factors, region, Some(&raised)),
            Err(GridError::Cancelled)
        ));
    }
}

#[test]
fn a_refinement_joined_with_the_bricks_it_lacked_is_the_union_classified_at_once() {
    // The oracle is the whole refinement filtered to the union's bricks (as in the test
    // above): a region's classification, joined with the classification of the bricks a
    // second region adds, holds the same ids and colours.
    let dims = [19u32, 13, 11];
    let volume = folded_ramp(dims, [5, 11, 3], 190.0);
    let tf = TransferFunction::ramp(40.0, 160.0, [1.0, 0.5, 0.25, 0.8]);
    let options = ClassifyOptions::default();
    let factors = [2u32, 1, 3];
    let first = Region::new(dims, 4, |b| b[0] <= b[2]).unwrap();
    let second = Region::new(dims, 4, |b| b[1] == 1 || b[0] == 4).unwrap();
    let union = first.union(&second).unwrap();
    let added = second.without(&first).unwrap();
    assert!(!added.is_whole() && !union.is_whole());
    let whole = classify_refined(&volume, &tf, &options, factors).unwrap();
    let fine = whole.grid.dims();
    let coarse = |id: u32| coarse_voxel(fine, factors, id);
    let listed = |c: &Classified, keep: &dyn Fn(u32) -> bool| -> Vec<(u32, SplatColor)> {
        c.grid
            .ids()
            .zip(&c.colors)
            .filter(|(id, _)| keep(*id))
            .map(|(id, c)| (id, *c))
            .collect()
    };
    let want = listed(&whole, &|id| union.covers(coarse(id)));
    let a = classify_refined_in(&volume, &tf, &options, factors, Some(&first), None).unwrap();
    let b = classify_refined_in(&volume, &tf, &options, factors, Some(&added), None).unwrap();
    assert!(!a.colors.is_empty() && !b.colors.is_empty());
    let joined = a.clone().joined_with(b.clone()).unwrap();
    assert_eq!(listed(&joined, &|_| true), want);
    assert_eq!(joined.grid.len(), joined.colors.len());
    // Either way round.
    let other_way = b.clone().joined_with(a.clone()).unwrap();
    assert_eq!(listed(&other_way, &|_| true), want);
    // Refused: a voxel in both, grids of two sizes, colours that do not match the grid.
    assert!(matches!(
        a.clone().joined_with(a.clone()),
        Err(GridError::NotDisjoint { .. })
    ));
    let small = classify_refined_in(&volume, &tf, &options, [1, 1, 1], None, None).unwrap();
    assert!(matches!(
        a.clone().joined_with(small),
        Err(GridError::NotDisjoint { .. })
    ));
    let mut short = b;
    short.colors.pop();
    assert!(matches!(
        a.joined_with(short),
        Err(GridError::ColorsMismatch { .. })
    ));
    // The complement of a region covers what it does not.
    let rest = first.complement();
    assert!(first.union(&rest).unwrap().is_whole());
    assert!(first.without(&rest).unwrap().contains(&first));
}

#[test]
fn refined_differences_are_two_trilinear_samples_apart() {
    // The oracle: the trilinear field sampled at the fine voxel's two faces, along each axis.
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed
    };
    for case in 0..40 {
        let dims: [u32; 3] = std::array::from_fn(|_| 1 + (next() % 6) as u32);
        let factors: [u32; 3] = std::array::from_fn(|_| 1 + (next() % 5) as u32);
        let count = dims.iter().product::<u32>() as usize;
        let values: Vec<f32> = (0..count)
            .map(|_| (next() % 4001) as f32 - 2000.0)
            .collect();
        let volume = CpuVolume {
            dims,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            direction: DMat3::IDENTITY,
            values: values.clone().into(),
        };
        let f = factors.map(f64::from);
        for z in 0..dims[2] * factors[2] {
            for y in 0..dims[1] * factors[1] {
                for x in 0..dims[0] * factors[0] {
                    let k = [x, y, z];
                    let centre: [f64; 3] =
                        std::array::from_fn(|a| (f64::from(k[a]) + 0.5) / f[a] - 0.5);
                    let want: [f32; 3] = std::array::from_fn(|a| {
                        let (mut lo, mut hi) = (centre, centre);
                        lo[a] -= 0.5 / f[a];
                        hi[a] += 0.5 / f[a];
                        volume.trilinear(hi) - volume.trilinear(lo)
                    });
                    let n = dims.map(|d| d as usize);
                    let places =
                        std::array::from_fn(|a| super::FinePlace::new(n[a], factors[a], k[a]));
                    let got = super::refined_differences_in(&values, n, &places);
                    let table = super::RefinedGradients::new(&volume, factors);
                    if factors != [1; 3] {
                        assert_eq!(
                            table.snorm8(k),
                            super::refined_gradient_snorm8(&volume, factors, k)
                        );
                    }
                    for a in 0..3 {
                        assert!(
                            (got[a] - want[a]).abs() <= 1e-3 * (1.0 + want[a].abs()),
                            "case {case}: dims {dims:?}, factors {factors:?}, voxel {k:?}: \
                             {got} against {want:?}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn a_refined_normal_is_the_slope_of_its_own_cell() {
    // Along x the field is flat up to voxel 2 and climbs 4 a voxel after it; along y it climbs
    // 1 a voxel everywhere. Refined 2 x 1 x 1, fine voxel 4's centre is coarse x = 1.75, inside
    // the flat cell: its gradient has no x part. Fine voxel 5's centre, 2.25, is in the
    // climbing cell: x slope 4 per coarse voxel, 2 per fine one, against y's 1.
    let dims = [6u32, 3, 3];
    let kink = [0.0f32, 0.0, 0.0, 4.0, 8.0, 12.0];
    let values: Vec<f32> = (0..6 * 3 * 3)
        .map(|id| kink[(id % 6) as usize] + (id / 6 % 3) as f32)
        .collect();
    let volume = unit_volume(dims, values);
    let unit = |k: [u32; 3]| {
        refined_gradient_snorm8(&volume, [2, 1, 1], k)
            .unwrap()
            .map(|v| f32::from(v as i8) / 127.0)
    };
    let flat = unit([4, 1, 1]);
    assert!(flat[0].abs() < 0.01 && flat[1] < -0.99, "{flat:?}");
    let climbing = unit([5, 1, 1]);
    let want = -glam::Vec3::new(2.0, 1.0, 0.0).normalize();
    for a in 0..3 {
        assert!(
            (climbing[a] - want[a]).abs() < 0.02,
            "{climbing:?} against {want}"
        );
    }
    // An odd factor's middle fine voxel is the coarse voxel 2, where the slope changes: its
    // own central difference, (4 - 0) / 2 along x, a third of that per fine voxel.
    let middle = refined_gradient_snorm8(&volume, [3, 1, 1], [7, 1, 1])
        .unwrap()
        .map(|v| f32::from(v as i8) / 127.0);
    let want = -glam::Vec3::new(2.0 / 3.0, 1.0, 0.0).normalize();
    for a in 0..3 {
        assert!(
            (middle[a] - want[a]).abs() < 0.02,
            "{middle:?} against {want}"
        );
    }
}

/// A `dims` grid whose voxels `id` are significant where `kept(id)`, of colours that vary from
/// voxel to voxel and density `density(id)`.
fn varied_splats(
    dims: [u32; 3],
    kept: impl Fn(u32) -> bool,
    density: impl Fn(u32) -> f32,
) -> Classified {
    let (mut ids, mut colors) = (Vec::new(), Vec::new());
    for id in (0..dims.iter().product::<u32>()).filter(|&id| kept(id)) {
        ids.push(id);
        colors.push(SplatColor {
            rgb: [
                (id * 37 % 256) as u8,
                (id * 91 % 256) as u8,
                (id * 13 % 256) as u8,
            ],
            density: half::f16::from_f32(density(id)),
        });
    }
    Classified {
        grid: SparseGrid::from_sorted_ids(dims, &ids).unwrap(),
        colors,
    }
}

#[test]
fn a_coarser_level_keeps_each_blocks_optical_depth_and_emission() {
    // A 5 x 4 x 3 grid (odd along x and z) of varied splats, some left out: each block's
    // splat, computed plainly from its children.
    let dims = [5u32, 4, 3];
    let fine = varied_splats(dims, |id| id % 3 != 1, |id| 0.05 + 0.07 * (id % 5) as f32);
    let coarse = fine.halved().unwrap();
    assert_eq!(coarse.grid.dims(), [3, 2, 2]);
    for block in 0..12u32 {
        let b = [block % 3, block / 3 % 2, block / 6];
        let (mut d, mut rgb, mut count) = (0.0f64, [0.0f64; 3], 0);
        for id in 0..60u32 {
            let k = [id % 5, id / 5 % 4, id / 20];
            if (0..3).any(|a| k[a] / 2 != b[a]) {
                continue;
            }
            count += 1;
            if let Some(rank) = fine.grid.rank(id) {
                let c = fine.colors[rank as usize];
                let dc = f64::from(c.density.to_f32());
                d += dc;
                for (sum, v) in rgb.iter_mut().zip(c.rgb) {
                    *sum += dc * f64::from(v);
                }
            }
        }
        let Some(rank) = coarse.grid.rank(block) else {
            assert_eq!(d, 0.0, "block {b:?}");
            continue;
        };
        let c = coarse.colors[rank as usize];
        let want = d / f64::from(count);
        assert!(
            (f64::from(c.density.to_f32()) / want - 1.0).abs() < 1e-3,
            "block {b:?}: {} against {want}",
            { c.density }
        );
        for (got, sum) in c.rgb.iter().zip(rgb) {
            assert!((f64::from(*got) - sum / d).abs() <= 0.5, "block {b:?}");
        }
    }
}

#[test]
fn a_level_halved_along_the_view_composites_each_pair_as_a_ray_does() {
    // A 5 x 5 x 3 grid (odd along y, the axis halved) of varied splats, some left out, some
    // opaque; halved along y seen from either end. Each pair's splat against the two voxels
    // composited plainly, nearer over farther: the same opacity over twice the step, and the
    // same emission.
    let dims = [5u32, 5, 3];
    let mut ids = Vec::new();
    let mut colors = Vec::new();
    for id in 0..75u32 {
        if id % 4 == 1 {
            continue;
        }
        ids.push(id);
        let density = if id % 7 == 0 {
            f32::INFINITY
        } else {
            0.1 + 0.6 * (id % 5) as f32
        };
        colors.push(SplatColor {
            rgb: [
                (id * 37 % 256) as u8,
                (id * 91 % 256) as u8,
                (id * 13 % 256) as u8,
            ],
            density: half::f16::from_f32(density),
        });
    }
    let fine = Classified {
        grid: SparseGrid::from_sorted_ids(dims, &ids).unwrap(),
        colors,
    };
    let step_mm = 0.8f32;
    let mut differs = false;
    let mut drawn = Vec::new();
    for larger_nearer in [true, false] {
        let front = Front {
            axis: 1,
            larger_nearer,
            step_mm,
        };
        let coarse = fine
            .halved_along([false, true, false], Some(front))
            .unwrap();
        assert_eq!(coarse.grid.dims(), [5, 3, 3]);
        let voxel = |k: [u32; 3]| -> Option<(f64, [f64; 3])> {
            if k[1] >= dims[1] {
                return None;
            }
            let rank = fine.grid.rank(k[0] + 5 * (k[1] + 5 * k[2]))?;
            let c = fine.colors[rank as usize];
            let d = f64::from(c.density.to_f32()).min(65504.0);
            Some((
                1.0 - (-d * f64::from(step_mm)).exp(),
                c.rgb.map(|v| f64::from(v) / 255.0),
            ))
        };
        for id in 0..45u32 {
            let b = [id % 5, id / 5 % 3, id / 15];
            let (lo, hi) = (
                voxel([b[0], 2 * b[1], b[2]]),
                voxel([b[0], 2 * b[1] + 1, b[2]]),
            );
            let (near, far) = if larger_nearer { (hi, lo) } else { (lo, hi) };
            let (an, cn) = near.unwrap_or((0.0, [0.0; 3]));
            let (af, cf) = far.unwrap_or((0.0, [0.0; 3]));
            let alpha = 1.0 - (1.0 - an) * (1.0 - af);
            let Some(rank) = coarse.grid.rank(id) else {
                assert!(near.is_none() && far.is_none(), "block {b:?}");
                continue;
            };
            let c = coarse.colors[rank as usize];
            // The pair's optical depth over the coarse voxel's step, twice the fine one (at
            // the odd end a block of one voxel takes its density as the mean, as
            // `halved` does).
            if 2 * b[1] + 1 < dims[1] {
                let got = 1.0 - (-f64::from(c.density.to_f32()) * 2.0 * f64::from(step_mm)).exp();
                assert!(
                    (got - alpha).abs() < 2e-3,
                    "block {b:?}: {got} against {alpha}"
                );
            }
            for ch in 0..3 {
                let want = (an * cn[ch] + (1.0 - an) * af * cf[ch]) / alpha * 255.0;
                let got = f64::from(c.rgb[ch]);
                assert!(
                    (got - want).abs() <= 0.51,
                    "block {b:?}: {got} against {want}"
                );
            }
            drawn.push((larger_nearer, id, c.rgb));
        }
    }
    // The two ends give other colours where a pair's voxels differ.
    for (end, id, rgb) in &drawn {
        if *end {
            differs |= drawn.iter().any(|(e, i, c)| !*e && i == id && c != rgb);
        }
    }
    assert!(differs);
    // A front along an axis not halved alone is ignored: the mean by density.
    let front = Front {
        axis: 1,
        larger_nearer: true,
        step_mm,
    };
    let both = fine.halved_along([true, true, false], Some(front)).unwrap();
    let plain = fine.halved_along([true, true, false], None).unwrap();
    assert_eq!(both.colors, plain.colors);
}

#[test]
fn the_shell_keeps_the_surface_of_an_opaque_block() {
    // A 6^3 grid with an opaque 4^3 block inside: its 2^3 core has only opaque neighbours.
    let values: Voxels = (0..216u32)
        .map(|id| {
            let k = [id % 6, id / 6 % 6, id / 36];
            if k.iter().all(|&c| (1..=4).contains(&c)) {
                1000.0
            } else {
                0.0
            }
        })
        .collect();
    let volume = CpuVolume {
        dims: [6; 3],
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values,
    };
    let tf = TransferFunction::ramp(100.0, 200.0, [1.0; 4]);
    let full = classify(&volume, &tf, 0.0).unwrap();
    let shell_at = |high| {
        let options = ClassifyOptions {
            min_opacity: 0.0,
            shell: Some(high),
            ..Default::default()
        };
        classify_with(&volume, &tf, &options).unwrap()
    };
    let shell = shell_at(0.5);
    // The block, and around it the voxels whose cells reach into it.
    assert!(full.grid.len() > 64, "{}", full.grid.len());
    assert_eq!(
        shell.grid.len(),
        full.grid.len() - 8,
        "the 2x2x2 core is left out"
    );
    let core = 2 + 6 * (2 + 6 * 2);
    assert!(full.grid.contains(core) && !shell.grid.contains(core));
    assert_eq!(shell.colors.len(), shell.grid.len());
    // With `high` at full opacity every visible voxel is on the shell.
    assert_eq!(shell_at(1.0).grid.len(), full.grid.len());
}

/// A uniform volume holds its tissue from its first voxel centre to its last, as a ray caster
/// bounds it: along a column of `n` voxels the splats' extinctions add up to `n - 1` voxels of
/// it (the end voxels' cells are half inside), on an axis of one voxel to the whole voxel.
#[test]
fn a_volume_holds_tissue_from_its_first_voxel_centre_to_its_last() {
    for dims in [[4u32, 4, 5], [4, 4, 2], [4, 4, 1]] {
        let volume = CpuVolume {
            dims,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            direction: DMat3::IDENTITY,
            values: vec![150.0f32; dims.iter().product::<u32>() as usize].into(),
        };
        let tf = TransferFunction::ramp(100.0, 200.0, [1.0; 4]);
        let classified = classify(&volume, &tf, 0.0).unwrap();
        let per_voxel = Opacity::default().density(0.5);
        // An interior column along z, and one along x through interior y and z where z has
        // room for one.
        let column: f32 = (0..dims[2])
            .map(|z| {
                let id = 1 + dims[0] * (1 + dims[1] * z);
                classified.colors[classified.grid.rank(id).unwrap() as usize]
                    .density
                    .to_f32()
            })
            .sum();
        let want = (dims[2].max(2) - 1) as f32;
        assert!(
            (column / per_voxel - want).abs() < 2e-3 * want,
            "{dims:?}: {} voxels of tissue along z, not {want}",
            column / per_voxel
        );
        let z = dims[2] / 2;
        let row: f32 = (0..dims[0])
            .map(|x| {
                let id = x + dims[0] * (1 + dims[1] * z);
                classified.colors[classified.grid.rank(id).unwrap() as usize]
                    .density
                    .to_f32()
            })
            .sum();
        // Along x: three voxels; the column's z end halves its voxels where z has several.
        let edge = if dims[2] > 1 && (z == 0 || z + 1 == dims[2]) {
            0.5
        } else {
            1.0
        };
        assert!(
            (row / per_voxel - 3.0 * edge).abs() < 6e-3,
            "{dims:?}: {} voxels of tissue along x",
            row / per_voxel
        );
    }
}

#[test]
fn a_uniform_field_gives_its_own_opacity_and_clear_space_no_splat() {
    let mut values = vec![110.0f32; 24];
    values[..8].fill(-5.0);
    let volume = CpuVolume {
        dims: [2, 3, 4],
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values: values.into(),
    };
    let classified = classify(
        &volume,
        &TransferFunction::ramp(100.0, 200.0, [1.0; 4]),
        0.0,
    )
    .unwrap();
    // The last voxel's cell lies wholly in the value 110; it is a corner of the grid, and
    // of its eight samples only the one inside the box of voxel centres holds tissue.
    let c = classified.colors[classified.grid.rank(23).unwrap() as usize];
    // Value 110 there: opacity 0.1 per millimetre over an eighth of the cell, white.
    assert_eq!(c.rgb, [255; 3]);
    assert!((c.density.to_f32() * 8.0 / Opacity::default().density(0.1) - 1.0).abs() < 1e-3);
    let [r, _, _, a] = c.premultiplied(1.0);
    assert!((r - a).abs() < 1e-6, "premultiplied");
    // A cell with no opacity is no splat, even where the minimum leaves nothing out: the
    // first layer's cells reach 23.75 at most, below the ramp.
    for min in [-1.0, f32::NAN] {
        let tf = TransferFunction::ramp(100.0, 200.0, [1.0; 4]);
        let classified = classify(&volume, &tf, min).unwrap();
        for id in 0..6 {
            assert_eq!(classified.grid.rank(id), None, "minimum {min}, voxel {id}");
        }
        assert!(classified.grid.rank(23).is_some());
    }
    let all_clear = CpuVolume {
        values: vec![-5.0; 24].into(),
        ..volume
    };
    let none = classify(
        &all_clear,
        &TransferFunction::ramp(100.0, 200.0, [1.0; 4]),
        0.0,
    )
    .unwrap();
    assert!(none.grid.is_empty());
}

#[test]
fn histogram_quantiles_match_a_sort_to_a_bin() {
    // Background zeros, then values spread unevenly over 1..=4000.
    let mut values: Vec<u16> = vec![0; 5000];
    values.extend((1..=4000u32).map(|i| ((i * i) / 4000).max(1) as u16));
    let h = Histogram::of(&Voxels::U16(values.clone())).unwrap();
    assert_eq!((h.lo, h.hi), (0.0, 4000.0));
    let mut above: Vec<u16> = values.into_iter().filter(|v| *v > 0).collect();
    above.sort_unstable();
    let bin = 4000.0 / h.counts.len() as f32;
    for q in [0.1, 0.5, 0.9, 0.995] {
        let sorted = f32::from(above[((q * above.len() as f64).ceil() as usize).max(1) - 1]);
        let got = h.quantile(q);
        assert!((got - sorted).abs() <= bin, "q {q}: {got} against {sorted}");
    }
    assert_eq!(h.coarse(64).iter().sum::<u64>(), 4000);
    assert_eq!(Histogram::of(&Voxels::U8(vec![7; 10])), None);
}

/// The shared-lerp interpolation at a fine voxel's eight cell points gives, bit for bit, what
/// one trilinear interpolation a point gives, for every fine voxel of factors 1 to 8.
#[test]
fn eight_cell_points_interpolate_as_eight_single_points() {
    let mut block = Block::default();
    let mut state = 12345u32;
    for trial in 0..50 {
        for layer in block.values.iter_mut() {
            for line in layer.iter_mut() {
                for v in line.iter_mut() {
                    state = state.wrapping_mul(1664525).wrapping_add(1013904223);
                    *v = (state >> 8) as f32 / 65536.0 - 128.0 + trial as f32;
                }
            }
        }
        for f in 1..=8 {
            let samples = Samples::new(f);
            for jx in 0..f {
                for jy in 0..f {
                    for jz in 0..f {
                        let at = [&samples.at[jx], &samples.at[jy], &samples.at[jz]];
                        let shared = block.lerp_2x2x2(at);
                        for (corner, value) in shared.iter().enumerate() {
                            let (ix, tx) = at[0][corner & 1];
                            let (iy, ty) = at[1][corner >> 1 & 1];
                            let (iz, tz) = at[2][corner >> 2 & 1];
                            let single = block.lerp([ix, iy, iz], [tx, ty, tz]);
                            assert_eq!(value.to_bits(), single.to_bits(), "f {f}, corner {corner}");
                        }
                    }
                }
            }
        }
    }
}

/// A block slid along x from the voxel before holds what a block loaded afresh holds, at the
/// faces too, whichever voxels a walk skips.
#[test]
fn a_block_slid_along_x_is_the_block_loaded_afresh() {
    let dims = [7u32, 6, 5];
    let n = dims.iter().product::<u32>() as usize;
    let values: Vec<u16> = (0..n as u32)
        .map(|i| (i.wrapping_mul(2654435761) >> 20) as u16)
        .collect();
    let mut slid = Block::default();
    let mut loaded = 0;
    for z in 0..5 {
        for y in 0..6 {
            for x in 0..7 {
                // Skip some voxels, as the walk skips clear ones.
                if (x * 3 + y * 5 + z) % 4 == 3 {
                    continue;
                }
                slid.load(&values, dims, [x, y, z]);
                let mut fresh = Block::default();
                fresh.load(&values, dims, [x, y, z]);
                assert_eq!(slid.values, fresh.values, "voxel {x}, {y}, {z}");
                loaded += 1;
            }
        }
    }
    assert!(loaded > 100);
}

#[test]
fn the_least_mean_extinction_is_the_minimum_opacitys() {
    // A cell is left out where its mean extinction is at or below the threshold: exactly
    // where the opacity `1 - exp(-mean)` is at or below the minimum.
    for min in [0.0f32, 1.0 / 255.0, 0.01, 0.3, 0.9, 0.999] {
        let t = f64::from(least_mean(min));
        for mean in [t * (1.0 - 1e-4), t * (1.0 + 1e-4) + 1e-9] {
            let alpha = -(-mean).exp_m1();
            assert_eq!(
                mean <= t,
                alpha <= f64::from(min),
                "min {min}, mean {mean}: opacity {alpha}"
            );
        }
    }
    // Every opacity is at or below 1; none is at or below a negative minimum; NaN leaves
    // nothing out.
    assert_eq!(least_mean(1.0), f32::INFINITY);
    assert_eq!(least_mean(2.0), f32::INFINITY);
    assert!(least_mean(-0.1) < 0.0);
    assert_eq!(least_mean(f32::NAN), f32::NEG_INFINITY);
}

#[test]
fn weighted_sums_are_the_sums_of_single_samples() {
    // The one-segment path (a ramp) and the searching path (three points) against the sums
    // of the table's single lookups, over values below, inside and above the function, and
    // NaN.
    let [ramp, three] = ramp_and_three();
    let values = [
        -5.0,
        60.0,
        60.3,
        97.25,
        150.0,
        189.99,
        190.0,
        f32::NAN,
        12.5,
        90.0,
        199.0,
        400.0,
        0.0,
        75.5,
        130.0,
        255.0,
    ];
    for tf in [&ramp, &three] {
        let table = ExtinctionTable::new(tf);
        for eight in values.chunks_exact(8) {
            let eight: [f32; 8] = eight.try_into().unwrap();
            let got = table.weighted_sums(eight);
            let mut want = [0.0f64; 4];
            for &v in &eight {
                let [r, g, b, d] = table.sample(v).map(f64::from);
                want[0] += d * r;
                want[1] += d * g;
                want[2] += d * b;
                want[3] += d;
            }
            for c in 0..4 {
                assert!(
                    (f64::from(got[c]) - want[c]).abs() <= 1e-5 * want[c].max(1.0),
                    "{eight:?}: {got:?} against {want:?}"
                );
            }
        }
    }
}

#[test]
fn a_gradient_is_the_central_differences_at_every_voxel() {
    // Every voxel of a small grid of scattered values, faces and edges included, against
    // differences written out with clamped neighbours, in u8 and in f32 (the same values).
    let dims = [5u32, 4, 3];
    let bytes: Vec<u8> = (0..60u32).map(|i| (i * 37 % 251) as u8).collect();
    let value = |x: i64, y: i64, z: i64| {
        let c = |v: i64, n: u32| v.clamp(0, i64::from(n) - 1) as usize;
        f32::from(bytes[c(x, dims[0]) + 5 * (c(y, dims[1]) + 4 * c(z, dims[2]))])
    };
    for values in [
        Voxels::from(bytes.clone()),
        Voxels::from(bytes.iter().map(|&b| f32::from(b)).collect::<Vec<f32>>()),
    ] {
        let volume = CpuVolume {
            dims,
            spacing: [1.0; 3],
            origin: [0.0; 3],
            direction: DMat3::IDENTITY,
            values,
        };
        for id in 0..60u32 {
            let k = [id % 5, id / 5 % 4, id / 20];
            let [x, y, z] = k.map(i64::from);
            // Central inside, one-sided at a face: the span between the clamped neighbours.
            let d = |lo: f32, hi: f32, span: i64| {
                if span == 0 {
                    0.0
                } else {
                    (hi - lo) / span as f32
                }
            };
            let span = |c: i64, n: u32| (c + 1).min(i64::from(n) - 1) - (c - 1).max(0);
            let g = glam::Vec3::new(
                d(value(x - 1, y, z), value(x + 1, y, z), span(x, dims[0])),
                d(value(x, y - 1, z), value(x, y + 1, z), span(y, dims[1])),
                d(value(x, y, z - 1), value(x, y, z + 1), span(z, dims[2])),
            );
            let want = (-g)
                .try_normalize()
                .map(|n| n.to_array().map(|v| (v * 127.0).round() as i8 as u8));
            assert_eq!(
                gradient_snorm8(&volume, k),
                want,
                "voxel {k:?}, gradient {g}"
            );
        }
    }
}

#[test]
fn a_voxel_whose_neighbours_are_pairwise_equal_takes_its_neighbourhoods_gradient() {
    // A 3 x 3 x 3 grid rising along x in every row but the middle row along y, which is flat:
    // the centre's six neighbours are pairwise equal, but the field around it rises along x.
    let bytes: Vec<u8> = (0..27u32)
        .map(|i| {
            let [x, y] = [i % 3, i / 3 % 3];
            if y == 1 { 50 } else { (x * 10) as u8 }
        })
        .collect();
    let volume = CpuVolume {
        dims: [3; 3],
        spacing: [1.0; 3],
        origin: [0.0; 3],
        direction: DMat3::IDENTITY,
        values: Voxels::from(bytes),
    };
    // Rising along x: the normal points down it (from dense to less dense).
    let down_x = Some([(-127i8) as u8, 0, 0]);
    assert_eq!(gradient_snorm8(&volume, [1, 1, 1]), down_x);
    // A face voxel has no whole neighbourhood: no gradient where its differences are zero.
    assert_eq!(gradient_snorm8(&volume, [0, 1, 1]), None);
    // A flat neighbourhood: none either.
    let flat = CpuVolume {
        values: Voxels::from(vec![7u8; 27]),
        ..volume.clone()
    };
    assert_eq!(gradient_snorm8(&flat, [1, 1, 1]), None);
    // Where the central differences are not zero they are kept: at (1, 0, 1), 10 along x
    // and 40 along y (one-sided at the face), the normal -(10, 40, 0) / 41.2.
    assert_eq!(
        gradient_snorm8(&volume, [1, 0, 1]),
        Some([(-31i8) as u8, (-123i8) as u8, 0])
    );
}

#[test]
fn a_ramps_row_sums_are_each_voxels_own_bit_for_bit() {
    // Stretches of every length around the vector's eight voxels, with samples below, inside
    // and above the ramp, exactly on its ends and bins, NaN, infinities and negative zero,
    // and open voxels scattered, in runs, or in no block of eight: the sums taken a row at a
    // time (AVX2 where the processor has it) against each voxel's own `weighted_sums`.
    let ramps = [
        TransferFunction::ramp(60.0, 190.0, [1.0, 0.93, 0.85, 0.6]),
        TransferFunction::ramp(-1000.0, 3000.0, [0.2, 0.5, 1.0, 0.999]),
        TransferFunction::ramp(0.0, 1e-3, [1.0, 0.0, 0.5, 1.0]),
        TransferFunction::ramp(100.0, 100.0, [1.0, 1.0, 1.0, 0.5]),
    ];
    let special = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -0.0,
        0.0,
        60.0,
        190.0,
        100.0,
        3000.0,
        -1000.0,
        1e-3,
        60.0 + 130.0 / 256.0,
    ];
    let mut hash = 0x2545_f491u32;
    let mut next = || {
        hash ^= hash << 13;
        hash ^= hash >> 17;
        hash ^= hash << 5;
        hash
    };
    let mut rows = RowSamples::default();
    let mut checked = 0;
    for tf in &ramps {
        let table = ExtinctionTable::new(tf);
        assert!(table.ramp().is_some());
        for n in [1usize, 7, 8, 9, 15, 16, 17, 40, 67] {
            for pattern in 0..4 {
                for corner in &mut rows.corners {
                    corner.clear();
                    corner.extend((0..n).map(|_| {
                        let h = next();
                        if h % 5 == 0 {
                            special[(h >> 8) as usize % special.len()]
                        } else {
                            (h >> 8) as f32 / (1u32 << 24) as f32 * 4400.0 - 1200.0
                        }
                    }));
                }
                let open: Vec<u8> = (0..n)
                    .map(|j| match pattern {
                        0 => 1,
                        1 => u8::from(next() % 3 == 0),
                        2 => u8::from(j % 16 >= 8),
                        _ => u8::from(j + 1 == n),
                    })
                    .collect();
                if !rows.ramp_sums(&table, &open) {
                    // No AVX2 here (or turned off): the row path takes each voxel's own.
                    continue;
                }
                for j in (0..n).filter(|&j| open[j] != 0) {
                    let want = table.weighted_sums(rows.at(j));
                    let got = rows.sums_at(j);
                    assert_eq!(
                        got.map(f32::to_bits),
                        want.map(f32::to_bits),
                        "{n} voxels, pattern {pattern}, voxel {j}: {got:?} against {want:?}"
                    );
                    checked += 1;
                }
            }
        }
    }
    #[cfg(target_arch = "x86_64")]
    assert_eq!(checked > 0, crate::simd::has_avx2());
    #[cfg(not(target_arch = "x86_64"))]
    assert_eq!(checked, 0);
}

#[test]
fn a_halved_grid_measures_each_block_spread_as_a_plain_variance() {
    // A 7 x 4 x 5 grid (odd along x and z) of varied splats, some left out, halved along
    // each set of axes: each splat's spread against the variance of its block's
    // premultiplied colours, computed plainly in f64 (the voxels left out as clear).
    let dims = [7u32, 4, 5];
    let n = dims.iter().product::<u32>();
    let fine = varied_splats(
        dims,
        |id| id % 4 != 1 && id % 7 != 3,
        |id| 0.02 + 0.3 * (id % 6) as f32,
    );
    let mm = 0.8f32;
    let premultiplied = |id: u32| -> [f64; 4] {
        let Some(rank) = fine.grid.rank(id) else {
            return [0.0; 4];
        };
        let c = fine.colors[rank as usize];
        let a = 1.0 - (-f64::from(c.density.to_f32()) * f64::from(mm)).exp();
        [
            a * f64::from(c.rgb[0]) / 255.0,
            a * f64::from(c.rgb[1]) / 255.0,
            a * f64::from(c.rgb[2]) / 255.0,
            a,
        ]
    };
    let mut largest = 0.0f64;
    for axes in [
        [true, true, true],
        [true, false, false],
        [false, true, true],
        [true, false, true],
    ] {
        let step = axes.map(|h| if h { 2 } else { 1 });
        let (coarse, spreads) = fine.halved_measured(axes, None, Some(mm)).unwrap();
        assert_eq!(spreads.len(), coarse.grid.len());
        // A raised cancel flag gives the halving up; a lowered one changes nothing.
        let flag = |raised| std::sync::atomic::AtomicBool::new(raised);
        assert_eq!(
            fine.halved_unless_cancelled(axes, None, Some(mm), Some(&flag(true)))
                .err(),
            Some(GridError::Cancelled)
        );
        let (kept, kept_spreads) = fine
            .halved_unless_cancelled(axes, None, Some(mm), Some(&flag(false)))
            .unwrap();
        assert!(kept.grid.ids().eq(coarse.grid.ids()));
        assert_eq!(kept_spreads, spreads);
        // The same splats as the halving that measures nothing.
        let plain = fine.halved_along(axes, None).unwrap();
        assert!(plain.grid.ids().eq(coarse.grid.ids()));
        assert!(plain.colors.iter().zip(&coarse.colors).all(|(p, c)| p == c));
        let out = coarse.grid.dims();
        for (id, spread) in coarse.grid.ids().zip(&spreads) {
            let b = [id % out[0], id / out[0] % out[1], id / out[0] / out[1]];
            let mut block = Vec::new();
            for v in 0..n {
                let k = [v % dims[0], v / dims[0] % dims[1], v / dims[0] / dims[1]];
                if (0..3).all(|a| k[a] / step[a] == b[a]) {
                    block.push(premultiplied(v));
                }
            }
            let count = block.len() as f64;
            let mean: [f64; 4] =
                std::array::from_fn(|c| block.iter().map(|p| p[c]).sum::<f64>() / count);
            let want = block
                .iter()
                .map(|p| (0..4).map(|c| (p[c] - mean[c]).powi(2)).sum::<f64>())
                .sum::<f64>()
                / count;
            largest = largest.max(want);
            assert!(
                (f64::from(*spread) - want).abs() < 1e-5,
                "axes {axes:?}, block {b:?}: {spread} against {want}"
            );
        }
    }
    // The grid's colours vary enough for the comparison to mean something.
    assert!(largest > 0.05, "{largest}");
}

#[test]
fn a_region_settled_by_blocks_holds_the_bricks_settled_one_by_one() {
    // Bricks whose centre lies within a ball, in a grid of odd size; a block is settled where
    // its box lies wholly within the ball or wholly outside it.
    let dims = [70, 45, 33];
    let side = 4;
    let (c, r) = ([30.0f64, 20.0, 14.0], 17.0f64);
    let centre_in = |b: [u32; 3]| {
        let d2: f64 = (0..3)
            .map(|a| (f64::from(b[a] * side) + f64::from(side) / 2.0 - c[a]).powi(2))
            .sum();
        d2 <= r * r
    };
    let brick_by_brick = Region::new(dims, side, centre_in).unwrap();
    let blocks = Region::by_blocks(dims, side, |lo, hi| {
        if (0..3).all(|a| hi[a] - lo[a] == 1) {
            return Some(centre_in(lo));
        }
        // The nearest and the farthest brick centre of the block from the ball's centre.
        let (mut near, mut far) = (0.0, 0.0);
        for a in 0..3 {
            let first = f64::from(lo[a] * side) + f64::from(side) / 2.0;
            let last = f64::from((hi[a] - 1) * side) + f64::from(side) / 2.0;
            let n = (c[a].clamp(first, last) - c[a]).abs();
            let f = (first - c[a]).abs().max((last - c[a]).abs());
            near += n * n;
            far += f * f;
        }
        if far <= r * r {
            Some(true)
        } else if near > r * r {
            Some(false)
        } else {
            None
        }
    })
    .unwrap();
    assert_eq!(blocks, brick_by_brick);
    assert!(brick_by_brick.bricks_covered() > 100 && !brick_by_brick.is_whole());
    // A test that never settles a block is asked brick by brick; a single brick it cannot
    // settle is kept.
    let unsure = Region::by_blocks(dims, side, |lo, hi| {
        ((0..3).all(|a| hi[a] - lo[a] == 1) && !centre_in(lo)).then_some(false)
    })
    .unwrap();
    assert_eq!(unsure, brick_by_brick);
    assert!(Region::by_blocks(dims, 0, |_, _| Some(true)).is_none());
}
