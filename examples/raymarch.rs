//! The reference ray marcher of the tests (`tests/common/raymarch.rs`) on a raw volume, for the
//! fidelity figures in BENCHMARKS.md: the picture a grid-independent renderer should give.
//!
//! ```text
//! cargo run --release --example raymarch -- VOLUME.raw NX,NY,NZ SX,SY,SZ ORIENT LO,HI \
//!     EYE_X,EYE_Y,EYE_Z TARGET_X,TARGET_Y,TARGET_Z WxH STEP_MM OUT.png [RAYS [GRADIENT_MM]]
//! ```
//!
//! One ray a pixel, through its centre; with `RAYS`, `RAYS` x `RAYS` rays a pixel weighted as
//! the splats' screen low-pass weights them (a Gaussian of `SplatStyle::pixel_variance` square
//! pixels), the pixel a splat draws: one ray a pixel aliases fine structures that the
//! low-pass blurs, and on such pictures that difference alone nears the fidelity bar.
//!
//! Shading takes the field's gradient by central differences `GRADIENT_MM` either side of a
//! sample (default 0.25 mm). The distance is the same on every grid, so the reference is one
//! picture of the anatomy whatever grid it is stored on: a distance tied to the grid (half a
//! voxel) shades a 1.5 mm grid as if smoothed three times more than its 0.5 mm resampling,
//! and those two references differ by 0.05 RMSE where the 0.25 mm ones differ by 0.01
//! (BENCHMARKS.md, "The reference's gradient at one distance on every grid").
//!
//! The volume is u8, x fastest, placed as `splatscene render` places a raw file at origin 0
//! with orientation ORIENT (three letters, each axis's positive direction: RAS, LAI...); the
//! transfer function is the command line's `--window LO,HI` ramp (transparent at LO, colour
//! (1, 0.93, 0.85) at opacity 0.6 per millimetre from HI); shading 0.8 (the splats' default);
//! camera up the patient's superior axis, 35 degree field of view; the picture goes over the
//! default background (0.06, 0.07, 0.09).

#[path = "../tests/common/raymarch.rs"]
mod raymarch;

use glam::DVec3;

fn numbers<const N: usize>(text: &str) -> [f64; N] {
    let parts: Vec<f64> = text
        .split([',', 'x'])
        .map(|v| v.trim().parse().expect("a number"))
        .collect();
    parts.try_into().expect("the right count of numbers")
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if !(10..=12).contains(&args.len()) {
        eprintln!(
            "usage: raymarch VOLUME NX,NY,NZ SX,SY,SZ ORIENT LO,HI EYE TARGET WxH STEP OUT [RAYS [GRADIENT_MM]]"
        );
        std::process::exit(2);
    }
    let rays = args.get(10).map(|r| numbers::<1>(r)[0] as usize);
    let gradient_mm = args.get(11).map_or(0.25, |g| numbers::<1>(g)[0]);
    assert!(
        gradient_mm.is_finite() && gradient_mm > 0.0,
        "GRADIENT_MM is a positive distance"
    );
    let dims = numbers::<3>(&args[1]).map(|v| v as u32);
    let spacing = numbers::<3>(&args[2]);
    let sign: Vec<f64> = args[3]
        .chars()
        .zip(['R', 'A', 'S'])
        .map(|(c, positive)| if c == positive { 1.0 } else { -1.0 })
        .collect();
    let [lo, hi] = numbers::<2>(&args[4]);
    let eye = DVec3::from(numbers::<3>(&args[5]));
    let target = DVec3::from(numbers::<3>(&args[6]));
    let [w, h] = numbers::<2>(&args[7]).map(|v| v as u32);
    let step = numbers::<1>(&args[8])[0];
    let bytes = std::fs::read(&args[0]).expect("the volume");
    let values: Vec<f32> = bytes.iter().map(|&b| f32::from(b)).collect();
    let grid = raymarch::Grid {
        dims,
        spacing,
        origin: [0.0; 3],
        values: &values,
    };
    // World (x, y, z) = sign * index * spacing: the grid's own frame with its axes flipped.
    let flip = DVec3::new(sign[0], sign[1], sign[2]);
    let field = move |p: DVec3| grid.sample(p * flip);
    let far = DVec3::from(std::array::from_fn::<f64, 3, _>(|a| {
        (f64::from(dims[a]) - 1.0) * spacing[a]
    })) * flip;
    let bounds = (far.min(DVec3::ZERO), far.max(DVec3::ZERO));
    let color = [1.0, 0.93, 0.85];
    let points = [
        (lo as f32, [color[0], color[1], color[2], 0.0]),
        (hi as f32, [color[0], color[1], color[2], 0.6]),
    ];
    let volume = raymarch::Volume {
        field: &field,
        bounds,
        transfer: &points,
        reference_mm: 1.0,
        shading: 0.8,
        gradient_mm,
    };
    let camera = raymarch::Pinhole {
        eye,
        target,
        up: DVec3::Z,
        fov_y_degrees: 35.0,
        size: (w, h),
    };
    let started = std::time::Instant::now();
    let pixels = match rays {
        Some(rays) => {
            let variance = splatscene::splat::reference::SplatStyle::default().pixel_variance;
            raymarch::march_low_pass(&volume, &camera, step, rays.max(1), variance)
        }
        None => raymarch::march(&volume, &camera, step),
    };
    eprintln!("marched in {:.1} s", started.elapsed().as_secs_f64());
    let background = [0.06f32, 0.07, 0.09];
    let image = image::RgbImage::from_fn(w, h, |x, y| {
        let p = pixels[(y * w + x) as usize];
        image::Rgb(std::array::from_fn(|c| {
            let v = p[c] + (1.0 - p[3]) * background[c];
            (v.clamp(0.0, 1.0) * 255.0).round() as u8
        }))
    });
    image.save(&args[9]).expect("the picture written");
}
