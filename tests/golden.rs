//! Golden images: the built-in shoulder scene and the LIDC2 overlay example, compared with
//! images checked in under `tests/golden/`.
//!
//! Tolerance: a pixel counts as different when any channel differs by more than 3/255, and at
//! most 0.5% of pixels may differ. The goldens were made on lavapipe (llvmpipe, LLVM 15.0.6,
//! 256 bits), where frames repeat exactly; the budget leaves room for other rasterisers'
//! edge rules and float rounding. On a failure `NAME-actual.png` and `NAME-diff.png` (the
//! difference times 8) are written to cargo's test temporary folder, and the message says
//! where. `SPLATSCENE_BLESS=1` writes the current images as the new goldens.

use std::path::{Path, PathBuf};

use image::RgbaImage;
use splatscene::render::{FrameOptions, GpuContext, Renderer, frame_to_rgba8};
use splatscene::scene::Scene;
use splatscene::scene::file::load_scene_file;
use splatscene::scene::shoulder::shoulder_scene;

mod common;

const CHANNEL_THRESHOLD: u8 = 3;
const PIXEL_BUDGET: f64 = 0.005;

fn golden_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

fn render(scene: &Scene, size: (u32, u32), background: Option<[f32; 3]>) -> RgbaImage {
    let ctx = GpuContext::headless().expect("a GPU adapter (install mesa-vulkan-drivers)");
    let camera = scene.camera.expect("the scene has a camera");
    let options = FrameOptions {
        background,
        measure: false,
        ..Default::default()
    };
    let shot = Renderer::new()
        .screenshot(&ctx, scene, &camera, size, &options)
        .unwrap();
    frame_to_rgba8(&shot.frame)
}

/// Compares `actual` with the golden `name`; see the module documentation.
fn check_golden(name: &str, actual: &RgbaImage) {
    let path = golden_dir().join(format!("{name}.png"));
    if std::env::var_os("SPLATSCENE_BLESS").is_some() {
        actual.save(&path).unwrap();
        eprintln!("blessed {}", path.display());
        return;
    }
    let expected = image::open(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (SPLATSCENE_BLESS=1 makes it)", path.display()))
        .to_rgba8();
    assert_eq!(expected.dimensions(), actual.dimensions(), "{name}: size");
    let mut diff = RgbaImage::new(actual.width(), actual.height());
    let mut differing = 0usize;
    for ((e, a), d) in expected
        .pixels()
        .zip(actual.pixels())
        .zip(diff.pixels_mut())
    {
        let delta: [u8; 4] = std::array::from_fn(|c| e[c].abs_diff(a[c]));
        if delta.iter().any(|&v| v > CHANNEL_THRESHOLD) {
            differing += 1;
        }
        *d = image::Rgba([
            delta[0].saturating_mul(8),
            delta[1].saturating_mul(8),
            delta[2].saturating_mul(8),
            255,
        ]);
    }
    let share = differing as f64 / f64::from(actual.width() * actual.height());
    if share > PIXEL_BUDGET {
        let out = Path::new(env!("CARGO_TARGET_TMPDIR"));
        let (a, d) = (
            out.join(format!("{name}-actual.png")),
            out.join(format!("{name}-diff.png")),
        );
        actual.save(&a).unwrap();
        diff.save(&d).unwrap();
        panic!(
            "{name}: {:.3}% of pixels differ by more than {CHANNEL_THRESHOLD}/255 (budget {:.1}%); see {} and {}",
            share * 100.0,
            PIXEL_BUDGET * 100.0,
            a.display(),
            d.display()
        );
    }
}

#[test]
fn built_in_shoulder_scene() {
    let scene = shoulder_scene().unwrap();
    check_golden(
        "shoulder",
        &render(&scene, (320, 240), Some([0.06, 0.07, 0.09])),
    );
}

#[test]
fn rotated_anisotropic_volume() {
    // Patient orientation: the volume is placed by direction x spacing + origin.
    let volume = common::rotated_anisotropic();
    let centre = volume.geometry().unwrap().centre_world();
    let mut scene = common::volume_scene(volume, splatscene::order::Ordering::IpPbtfImplicit);
    let eye = centre + glam::DVec3::new(-18.0, -45.0, 33.0);
    scene.camera = Some(splatscene::scene::SceneCamera::look_at(eye, centre));
    // Cut open toward the viewer so that the inner shells show.
    let toward_eye = (eye - centre).normalize();
    let cut = splatscene::scene::ClipPlane::through(centre, toward_eye, false);
    scene.clipping.planes.push(cut);
    check_golden(
        "rotated-anisotropic",
        &render(&scene, (128, 112), Some([0.0, 0.0, 0.0])),
    );
}

#[test]
fn golden_check_catches_a_changed_picture() {
    // The check itself must fail on a real change: a moved camera. (Not while blessing,
    // which would write the moved picture as the shoulder's golden.)
    if std::env::var_os("SPLATSCENE_BLESS").is_some() {
        return;
    }
    let mut scene = shoulder_scene().unwrap();
    scene.camera = scene.camera.map(|c| c.orbit(25.0, 0.0));
    let moved = render(&scene, (320, 240), Some([0.06, 0.07, 0.09]));
    let caught = std::panic::catch_unwind(|| check_golden("shoulder", &moved));
    assert!(
        caught.is_err(),
        "a 25 degree orbit must not pass as the golden"
    );
}

/// The overlay example's scene: LIDC2 from `SPLATSCENE_DATA` with the prosthesis at a
/// humeral head.
#[test]
fn overlay_example_scene() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenes/overlay-lidc2.toml");
    let data = std::env::var_os("SPLATSCENE_DATA").map_or(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data"),
        PathBuf::from,
    );
    if !data.join("volumes/lidc2").is_dir() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{} is missing under CI: set SPLATSCENE_DATA",
            data.display()
        );
        eprintln!(
            "skipped: no LIDC2 under {} (set SPLATSCENE_DATA)",
            data.display()
        );
        return;
    }
    // SAFETY-free: the scene file resolves `data:` paths through SPLATSCENE_DATA or the
    // default, which is the repository's sibling folder when tests run from the crate root.
    let loaded = load_scene_file(&path).unwrap();
    check_golden(
        "overlay-lidc2",
        &render(&loaded.scene, (256, 256), loaded.background),
    );
}
