//! Parsers of the command line's values: number pairs and triples, image sizes, opacities.
//! Each refuses what cannot mean anything (NaN, infinity, an image without pixels) with a
//! message that names the value.

fn parse_triple<T: std::str::FromStr>(s: &str) -> Result<[T; 3], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!("expected three comma-separated numbers, got {s:?}"));
    }
    let mut out = Vec::with_capacity(3);
    for p in parts {
        out.push(
            p.parse::<T>()
                .map_err(|_| format!("{p:?} is not a valid number"))?,
        );
    }
    out.try_into()
        .map_err(|_| "expected three numbers".to_owned())
}

pub(crate) fn parse_f64x2(s: &str) -> Result<[f64; 2], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [a, b] = parts.as_slice() else {
        return Err(format!("expected two comma-separated numbers, got {s:?}"));
    };
    let parse = |v: &str| {
        v.parse::<f64>()
            .map_err(|_| format!("{v:?} is not a valid number"))
    };
    let pair = [parse(a)?, parse(b)?];
    finite(s, &pair)?;
    Ok(pair)
}

/// Refuses NaN and infinite numbers in the argument `s`.
fn finite(s: &str, values: &[f64]) -> Result<(), String> {
    match values.iter().find(|v| !v.is_finite()) {
        Some(v) => Err(format!("{v} in {s:?} is not finite")),
        None => Ok(()),
    }
}

/// A finite number.
pub(crate) fn parse_finite_f32(s: &str) -> Result<f32, String> {
    let v: f32 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a valid number"))?;
    finite(s, &[f64::from(v)])?;
    Ok(v)
}

/// An opacity, from 0 to 1.
pub(crate) fn parse_opacity(s: &str) -> Result<f32, String> {
    let v = parse_finite_f32(s)?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is not an opacity from 0 to 1"))
    }
}

pub(crate) fn parse_f32x2(s: &str) -> Result<[f32; 2], String> {
    let [a, b] = parse_f64x2(s)?;
    let pair = [a as f32, b as f32];
    finite(s, &[f64::from(pair[0]), f64::from(pair[1])])?;
    Ok(pair)
}

pub(crate) fn parse_u32x2(s: &str) -> Result<[u32; 2], String> {
    let [a, b] = parse_f64x2(s)?;
    let whole =
        |v: f64| (v >= 0.0 && v.fract() == 0.0 && v <= f64::from(u32::MAX)).then_some(v as u32);
    match (whole(a), whole(b)) {
        (Some(a), Some(b)) => Ok([a, b]),
        _ => Err(format!("expected two whole numbers, got {s:?}")),
    }
}

pub(crate) fn parse_u32x3(s: &str) -> Result<[u32; 3], String> {
    parse_triple(s)
}

pub(crate) fn parse_f64x3(s: &str) -> Result<[f64; 3], String> {
    let triple = parse_triple(s)?;
    finite(s, &triple)?;
    Ok(triple)
}

pub(crate) fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("expected WxH, got {s:?}"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("{v:?} is not a pixel count"))
    };
    let (w, h) = (parse(w)?, parse(h)?);
    if w == 0 || h == 0 {
        return Err("the image needs at least one pixel each way".into());
    }
    // The renderer's textures and the compositor's buffers bound an image.
    splatscene::budget::check_image(w.into(), h.into()).map_err(|e| e.to_string())?;
    Ok((w, h))
}
