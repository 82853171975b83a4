//! Annotation text never overlaps and stays inside the picture: edge letters, the marker's
//! letters, the scale bar, a long caption and crowded measurement labels, in every direction
//! the camera can look along (26, axes and diagonals) and at small and large sizes.

use glam::DVec3;
use image::RgbaImage;
use splatscene::annotate::{Annotations, Label, annotate_image};
use splatscene::scene::patient::PatientFrame;
use splatscene::scene::{Projection, SceneCamera};

/// Whether two rectangles share more than a sliver (anti-aliasing may touch at edges).
fn overlap(a: [f32; 4], b: [f32; 4]) -> bool {
    let w = a[2].min(b[2]) - a[0].max(b[0]);
    let h = a[3].min(b[3]) - a[1].max(b[1]);
    w > 0.5 && h > 0.5
}

/// A pixel in the measurement labels' yellow.
fn yellow(p: &image::Rgba<u8>) -> bool {
    p[0] > 200 && p[1] > 150 && p[2] < 120 && p[3] > 0
}

fn labels() -> Vec<Label> {
    let mut labels: Vec<Label> = (1..=6)
        .map(|i| Label {
            at: DVec3::ZERO,
            text: format!("{i}: {}.5 mm", 10 * i),
        })
        .collect();
    for (i, p) in [
        DVec3::new(30.0, 0.0, 0.0),
        DVec3::new(0.0, 30.0, 0.0),
        DVec3::new(0.0, 0.0, 30.0),
    ]
    .into_iter()
    .enumerate()
    {
        labels.push(Label {
            at: p,
            text: format!("angle {}: 131.9°", i + 1),
        });
    }
    labels
}

#[test]
fn text_never_overlaps_and_stays_inside_in_every_direction() {
    let parts = Annotations {
        caption: Some(
            "Right shoulder, stem seated 2 mm proud, anterolateral view of the planned construct"
                .into(),
        ),
        ..Annotations::default()
    };
    let mut checked = 0;
    let mut seen_crowded = false;
    for (w, h) in [(96u32, 72u32), (320, 240), (800, 600)] {
        for i in 0..27 {
            let d = DVec3::new(
                f64::from(i % 3) - 1.0,
                f64::from((i / 3) % 3) - 1.0,
                f64::from(i / 9) - 1.0,
            );
            if d == DVec3::ZERO {
                continue;
            }
            let mut camera = SceneCamera::look_at(-150.0 * d.normalize(), DVec3::ZERO);
            camera.projection = Projection::Perspective {
                fov_y_degrees: 30.0,
            };
            let mut image = RgbaImage::new(w, h);
            let labels = labels();
            let drawn = annotate_image(
                &mut image,
                &camera,
                &PatientFrame::default(),
                &labels,
                &parts,
            )
            .unwrap();
            let where_ = format!("{w}x{h} looking along {d}");
            // Everything drawn or said to be left out.
            let placed = drawn
                .texts
                .iter()
                .filter(|(t, _)| labels.iter().any(|l| &l.text == t))
                .count();
            let dropped = drawn
                .dropped
                .iter()
                .filter(|t| labels.iter().any(|l| &l.text == *t))
                .count();
            assert_eq!(placed + dropped, labels.len(), "{where_}");
            seen_crowded |= !drawn.dropped.is_empty();
            // Room enough: nothing is left out to keep the text apart.
            if w >= 320 {
                assert!(drawn.marker && drawn.scale.is_some(), "{where_}");
            }
            if w >= 800 {
                assert!(drawn.dropped.is_empty(), "{where_}: {:?}", drawn.dropped);
            }
            for (i, (a, ra)) in drawn.texts.iter().enumerate() {
                assert!(
                    ra[0] >= -0.5
                        && ra[1] >= -0.5
                        && ra[2] <= w as f32 + 0.5
                        && ra[3] <= h as f32 + 0.5,
                    "{where_}: {a:?} at {ra:?} leaves the picture"
                );
                for (b, rb) in &drawn.texts[..i] {
                    assert!(
                        !overlap(*ra, *rb),
                        "{where_}: {a:?} at {ra:?} over {b:?} at {rb:?}"
                    );
                }
            }
            // Each label drawn where it says: its yellow is inside its rectangle.
            for (text, r) in drawn
                .texts
                .iter()
                .filter(|(t, _)| labels.iter().any(|l| &l.text == t))
            {
                let inside = (r[1].max(0.0) as u32..(r[3] as u32).min(h))
                    .flat_map(|y| (r[0].max(0.0) as u32..(r[2] as u32).min(w)).map(move |x| (x, y)))
                    .filter(|&(x, y)| yellow(image.get_pixel(x, y)))
                    .count();
                assert!(inside > 4, "{where_}: {text:?} not drawn at {r:?}");
            }
            checked += 1;
        }
    }
    assert_eq!(checked, 78);
    assert!(seen_crowded, "the smallest pictures leave labels out");
}

#[test]
fn a_long_caption_is_shortened_to_the_picture_and_kept_below_the_top_letter() {
    let parts = Annotations {
        caption: Some("A caption far longer than the small picture it is written on".into()),
        ..Annotations::default()
    };
    let camera = SceneCamera::look_at(DVec3::new(0.0, 150.0, 0.0), DVec3::ZERO);
    let mut image = RgbaImage::new(160, 120);
    let drawn = annotate_image(&mut image, &camera, &PatientFrame::default(), &[], &parts).unwrap();
    let (caption, r) = drawn
        .texts
        .iter()
        .find(|(t, _)| t.starts_with("A caption"))
        .unwrap();
    assert!(caption.ends_with('…'), "{caption}");
    assert!(r[2] <= 160.0, "{r:?}");
    let top = drawn
        .texts
        .iter()
        .find(|(t, _)| t == &drawn.edge_letters[2])
        .unwrap()
        .1;
    assert!(r[1] >= top[3], "caption {r:?} below the top letter {top:?}");
}
