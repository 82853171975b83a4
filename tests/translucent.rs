//! Translucent meshes: a mesh of opacity `a` is laid over what lies behind it (the splats and
//! the background; opaque meshes hide it), so that where it covers the picture its pixel is
//! `a` times its opaque colour plus `1 - a` times the picture without it. Checked on the
//! built-in scene with the GPU's splat pass and with the CPU tile compositor.

use std::path::Path;
use std::process::Command;

mod common;

fn render(dir: &Path, name: &str, mesh: &str, compositor: &str) -> image::RgbaImage {
    let scene = dir.join(format!("{name}.toml"));
    std::fs::write(
        &scene,
        format!(
            "[camera]\nview_from = [-0.3, -1.0, -0.35]\n\n[[volume]]\npath = \"builtin:shoulder-phantom\"\ntransfer = \"ct-bone\"\nresect_humeral_head = true\ncut_away_anterior_humerus = 30.0\n{mesh}"
        ),
    )
    .unwrap();
    let out = dir.join(format!("{name}-{compositor}.png"));
    let status = Command::new(env!("CARGO_BIN_EXE_splatscene"))
        .args(["render", scene.to_str().unwrap(), "--size", "160x120"])
        .args(["--compositor", compositor, "--out", out.to_str().unwrap()])
        .env("NODEVICE_SELECT", "1")
        .output()
        .unwrap();
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    image::open(&out).unwrap().to_rgba8()
}

#[test]
fn a_translucent_mesh_blends_over_what_lies_behind_it() {
    let dir = common::scratch("translucent");
    std::fs::create_dir_all(&dir).unwrap();
    let mesh = |opacity: f32| {
        format!(
            "\n[[mesh]]\npath = \"builtin:prosthesis\"\nseat = \"phantom\"\nopacity = {opacity}\n"
        )
    };
    for compositor in ["gpu", "cpu"] {
        let opaque = render(&dir, "opaque", &mesh(1.0), compositor);
        let half = render(&dir, "half", &mesh(0.5), compositor);
        let without = render(&dir, "without", "", compositor);
        // Pixels the opaque prosthesis changes clearly: where it shows.
        let mut covered = 0;
        let mut error = 0.0;
        for ((o, h), w) in opaque.pixels().zip(half.pixels()).zip(without.pixels()) {
            let differs = (0..3).any(|k| (f32::from(o[k]) - f32::from(w[k])).abs() > 40.0);
            if !differs {
                continue;
            }
            covered += 1;
            for k in 0..3 {
                let expected = 0.5 * (f32::from(o[k]) + f32::from(w[k]));
                error += (f32::from(h[k]) - expected).abs() / 255.0;
            }
        }
        assert!(
            covered > 200,
            "{compositor}: the prosthesis covers {covered} pixels"
        );
        let mean = error / (3.0 * covered as f32);
        // Rounding to 8 bits and the mesh's own edges blur this a little.
        assert!(
            mean < 0.02,
            "{compositor}: mean difference {mean} from the half-and-half blend over {covered} pixels"
        );
        assert_ne!(half, opaque);
    }
}
