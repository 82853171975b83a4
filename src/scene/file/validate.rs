//! The values of a scene file, checked where the file is read: every number finite and in its
//! range, every direction non-zero, every key one that has an effect where it stands. Each
//! problem is a message naming the key (and the node) and saying what is wrong.

use super::{
    CameraSpec, LightsSpec, MeshSpec, OutputSpec, SceneFile, SliceFileSpec, TransformSpec,
    VolumeSpec,
};

/// Largest image side, as the renderer's textures allow.
pub const MAX_SIDE: u32 = crate::budget::MAX_SIDE;
/// Largest image, in pixels: 64 megapixels, about 1 GiB of frame and depth buffers.
pub const MAX_PIXELS: u64 = crate::budget::MAX_PIXELS;
/// Directional lights the shaders take.
pub const MAX_DIRECTIONAL_LIGHTS: usize = 4;

/// The first problem with the file's values, as a message for people.
pub fn check(file: &SceneFile) -> Result<(), String> {
    output(&file.output)?;
    if let Some(camera) = &file.camera {
        self::camera(camera)?;
    }
    lights(&file.lights)?;
    for (i, v) in file.volumes.iter().enumerate() {
        let node = v
            .name
            .clone()
            .unwrap_or_else(|| format!("volume {}", i + 1));
        volume(v).map_err(|e| format!("{node}: {e}"))?;
    }
    for (i, m) in file.meshes.iter().enumerate() {
        let node = m.name.clone().unwrap_or_else(|| format!("mesh {}", i + 1));
        mesh(m).map_err(|e| format!("{node}: {e}"))?;
    }
    for (i, s) in file.slices.iter().enumerate() {
        slice(s).map_err(|e| format!("slice {} ({}): {e}", i + 1, s.plane))?;
    }
    Ok(())
}

fn slice(s: &SliceFileSpec) -> Result<(), String> {
    if let Some(mm) = s.mm_per_pixel {
        positive("mm_per_pixel", mm)?;
    }
    if s.mesh.is_some() && !s.plane.kind.follows_implant() {
        return Err(format!(
            "mesh has no effect on a {} plane; only implant-long and implant-cross follow a mesh",
            s.plane.kind.name()
        ));
    }
    Ok(())
}

/// The numbers, written as a TOML array.
fn list<T: std::fmt::Display>(values: &[T]) -> String {
    let words: Vec<String> = values.iter().map(|v| v.to_string()).collect();
    format!("[{}]", words.join(", "))
}

fn finite<const N: usize>(key: &str, values: &[f64; N]) -> Result<(), String> {
    if values.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(format!("{key} {} is not finite", list(values)))
    }
}

fn direction(key: &str, values: &[f64; 3]) -> Result<(), String> {
    finite(key, values)?;
    if values.iter().all(|v| *v == 0.0) {
        return Err(format!("{key} {} has no direction", list(values)));
    }
    Ok(())
}

/// A number in `lo..=hi` (each bound included).
fn within(key: &str, value: f64, lo: f64, hi: f64) -> Result<(), String> {
    if value.is_finite() && (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(format!("{key} {value} is not a number from {lo} to {hi}"))
    }
}

fn positive(key: &str, value: f64) -> Result<(), String> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(format!("{key} {value} is not a positive number"))
    }
}

fn colour(key: &str, values: &[f32]) -> Result<(), String> {
    if values
        .iter()
        .all(|v| v.is_finite() && (0.0..=1.0).contains(v))
    {
        Ok(())
    } else {
        Err(format!(
            "{key} {} must hold numbers from 0 to 1",
            list(values)
        ))
    }
}

fn output(o: &OutputSpec) -> Result<(), String> {
    if let Some([w, h]) = o.size {
        if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
            return Err(format!(
                "output.size [{w}, {h}]: each side must be 1 to {MAX_SIDE} pixels"
            ));
        }
        if u64::from(w) * u64::from(h) > MAX_PIXELS {
            return Err(format!(
                "output.size [{w}, {h}]: more than {MAX_PIXELS} pixels in one image"
            ));
        }
    }
    if let Some(background) = &o.background {
        colour("output.background", background)?;
        if o.transparent {
            return Err("output.background has no effect with output.transparent".into());
        }
    }
    Ok(())
}

fn camera(c: &CameraSpec) -> Result<(), String> {
    for (key, value) in [("camera.eye", &c.eye), ("camera.target", &c.target)] {
        if let Some(v) = value {
            finite(key, v)?;
        }
    }
    if let Some(up) = &c.up {
        direction("camera.up", up)?;
    }
    if let Some(from) = &c.view_from {
        direction("camera.view_from", from)?;
    }
    if let Some(fov) = c.fov {
        if !(fov.is_finite() && (0.1..=170.0).contains(&fov)) {
            return Err(format!(
                "camera.fov {fov} is not an angle from 0.1 to 170 degrees"
            ));
        }
        if c.orthographic_height.is_some() {
            return Err(
                "camera.fov has no effect with camera.orthographic_height (orthographic)".into(),
            );
        }
    }
    if let Some(h) = c.orthographic_height {
        positive("camera.orthographic_height", h)?;
    }
    if let Some(near) = c.near {
        positive("camera.near", near)?;
    }
    Ok(())
}

fn lights(l: &LightsSpec) -> Result<(), String> {
    for (key, value) in [
        ("lights.headlight", l.headlight),
        ("lights.ambient", l.ambient),
    ] {
        if let Some(v) = value
            && !(v.is_finite() && v >= 0.0)
        {
            return Err(format!("{key} {v} is not a number from 0 up"));
        }
    }
    if let Some(list) = &l.directional {
        if list.len() > MAX_DIRECTIONAL_LIGHTS {
            return Err(format!(
                "lights.directional: {} lights, but the shaders take {MAX_DIRECTIONAL_LIGHTS}",
                list.len()
            ));
        }
        for (i, light) in list.iter().enumerate() {
            direction(
                &format!("lights.directional {}: direction", i + 1),
                &light.direction,
            )?;
            if !light.color.iter().all(|c| c.is_finite() && *c >= 0.0) {
                return Err(format!(
                    "lights.directional {}: color {} must hold numbers from 0 up",
                    i + 1,
                    self::list(&light.color)
                ));
            }
        }
    }
    Ok(())
}

fn transform(t: &TransformSpec) -> Result<(), String> {
    for (key, value) in [
        ("transform.translate", &t.translate),
        ("transform.rotate_degrees", &t.rotate_degrees),
        ("transform.scale", &t.scale),
    ] {
        if let Some(v) = value {
            finite(key, v)?;
        }
    }
    if let Some(scale) = &t.scale
        && scale.contains(&0.0)
    {
        return Err(format!(
            "transform.scale {} flattens the node to nothing",
            list(scale)
        ));
    }
    if let Some(m) = &t.matrix {
        if !m.iter().all(|v| v.is_finite()) {
            return Err("transform.matrix holds a number that is not finite".into());
        }
        // Column-major: the last row is elements 3, 7, 11 and 15.
        // Rounding in a matrix written by a program is allowed; anything more is refused.
        let last_row = [m[3], m[7], m[11], m[15]];
        let affine = last_row
            .iter()
            .zip([0.0, 0.0, 0.0, 1.0])
            .all(|(v, want)| (v - want).abs() <= 1e-9);
        if !affine {
            return Err(format!(
                "transform.matrix has the last row {}, not 0, 0, 0, 1: a projective matrix cannot place a node (the matrix is column-major: elements 4, 8, 12 and 16 make the last row; the translation is elements 13 to 15)",
                last_row.map(|v| v.to_string()).join(", ")
            ));
        }
        if t.translate.is_some() || t.rotate_degrees.is_some() || t.scale.is_some() {
            return Err(
                "transform.matrix replaces translate, rotate_degrees and scale; give one or the other"
                    .into(),
            );
        }
    }
    Ok(())
}

fn volume(v: &VolumeSpec) -> Result<(), String> {
    transform(&v.transform)?;
    let builtin = v.path.starts_with("builtin:");
    if builtin {
        let raw = [
            ("dims", v.dims.is_some()),
            ("scalar", v.scalar.is_some()),
            ("header_bytes", v.header_bytes.is_some()),
            ("spacing", v.spacing.is_some()),
            ("origin", v.origin.is_some()),
            ("orientation", v.orientation.is_some()),
            ("series", v.series.is_some()),
            ("skip_unreadable", v.skip_unreadable.is_some()),
            ("frame", v.frame.is_some()),
            ("nifti_transform", v.nifti_transform.is_some()),
            ("coordinate_frame", v.coordinate_frame.is_some()),
        ];
        if let Some((key, _)) = raw.iter().find(|(_, given)| *given) {
            return Err(format!(
                "{key} describes a volume file; {} is built in",
                v.path
            ));
        }
    } else {
        let phantom = [
            ("resect_humeral_head", v.resect_humeral_head),
            (
                "cut_away_anterior_humerus",
                v.cut_away_anterior_humerus.is_some(),
            ),
        ];
        if let Some((key, _)) = phantom.iter().find(|(_, given)| *given) {
            return Err(format!("{key} applies to builtin:shoulder-phantom only"));
        }
    }
    if let Some(s) = &v.spacing {
        for x in s {
            positive("spacing", *x)?;
        }
    }
    if let Some(o) = &v.origin {
        finite("origin", o)?;
    }
    if let Some(shift) = v.shift
        && !shift.is_finite()
    {
        return Err(format!("shift {shift} is not finite"));
    }
    if let Some([level, width]) = v.level_width {
        if !level.is_finite() {
            return Err(format!("level_width: level {level} is not finite"));
        }
        positive("level_width: width", f64::from(width))?;
    }
    if let Some(r) = v.opacity_reference_mm {
        positive("opacity_reference_mm", r)?;
    }
    for (key, value) in [
        ("shading", v.shading),
        ("shell", v.shell),
        ("min_opacity", v.min_opacity),
    ] {
        if let Some(x) = value {
            within(key, f64::from(x), 0.0, 1.0)?;
        }
    }
    if let Some(c) = &v.color {
        colour("color", c)?;
    }
    if let Some(d) = v.cut_away_anterior_humerus {
        positive("cut_away_anterior_humerus", d)?;
    }
    Ok(())
}

fn mesh(m: &MeshSpec) -> Result<(), String> {
    transform(&m.transform)?;
    if let Some(c) = &m.color {
        if !matches!(c.len(), 3 | 4) {
            return Err(format!(
                "color {} must hold 3 (RGB) or 4 (RGBA) numbers",
                list(c)
            ));
        }
        colour("color", c)?;
    }
    for (key, value) in [
        ("opacity", m.opacity),
        ("roughness", m.roughness),
        ("metallic", m.metallic),
    ] {
        if let Some(x) = value {
            within(key, f64::from(x), 0.0, 1.0)?;
        }
    }
    Ok(())
}

/// Where an array in the file as `written` holds more elements than the same array as `read`
/// into the scene's types: a message naming its key (`key` is the path so far).
pub fn extra_elements(written: &toml::Value, read: &toml::Value, key: &str) -> Option<String> {
    use toml::Value;
    let at = |name: &str| match key {
        "" => name.to_owned(),
        _ => format!("{key}.{name}"),
    };
    match (written, read) {
        (Value::Table(a), Value::Table(b)) => a
            .iter()
            .find_map(|(name, v)| b.get(name).and_then(|w| extra_elements(v, w, &at(name)))),
        (Value::Array(a), Value::Array(b)) if a.len() != b.len() => Some(format!(
            "{key} holds {} values where it takes {}",
            a.len(),
            b.len()
        )),
        (Value::Array(a), Value::Array(b)) => a
            .iter()
            .zip(b)
            .enumerate()
            .find_map(|(i, (v, w))| extra_elements(v, w, &format!("{key}[{}]", i + 1))),
        _ => None,
    }
}
