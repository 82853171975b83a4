// A splat's footprint on the screen: `footprint` in src/splat/footprint.rs, line by line.
// Prepended to the shaders that use it (src/render/splat_pass.rs); tests/footprint.rs holds
// the two to each other.

struct Footprint {
    // Centre in pixels (x right, y down).
    centre: vec2<f32>,
    // The screen covariance [[a, b], [b, c]], the pixel variance added, as (a, b, c).
    cov: vec3<f32>,
    // The share of the splat's opacity the widened footprint keeps.
    kept: f32,
    // Whether the footprint is an ellipse (a positive determinant).
    ok: bool,
}

// The footprint of a splat centred at `p` in camera space (x right, y up, z forward), its
// camera-space covariance `cov` (symmetric), through a lens of focal length `focal` (pixels,
// or pixels per world unit when `ortho`), image centre `centre` and pixel variance `v`.
fn footprint(p: vec3<f32>, cov: mat3x3<f32>, focal: f32, centre: vec2<f32>, v: f32, ortho: bool) -> Footprint {
    let f = focal;
    var j0 = vec3<f32>(f, 0.0, 0.0);
    var j1 = vec3<f32>(0.0, -f, 0.0);
    var at = vec2<f32>(centre.x + f * p.x, centre.y - f * p.y);
    if !ortho {
        let iz = 1.0 / p.z;
        j0 = vec3<f32>(f * iz, 0.0, -f * p.x * iz * iz);
        j1 = vec3<f32>(0.0, -f * iz, f * p.y * iz * iz);
        at = vec2<f32>(centre.x + f * p.x * iz, centre.y - f * p.y * iz);
    }
    let a = dot(j0, cov * j0) + v;
    let b = dot(j0, cov * j1);
    let c = dot(j1, cov * j1) + v;
    let det = a * c - b * b;
    let own = (a - v) * (c - v) - b * b;
    var kept = 0.0;
    if own > 0.0 {
        kept = min(sqrt(own / det), 1.0);
    }
    return Footprint(at, vec3<f32>(a, b, c), kept, det > 0.0);
}

// The footprint's conic: the inverse of its covariance, (a', b', c') with
// q = a' dx^2 + 2 b' dx dy + c' dy^2.
fn footprint_conic(fp: Footprint) -> vec3<f32> {
    let inv_det = 1.0 / (fp.cov.x * fp.cov.z - fp.cov.y * fp.cov.y);
    return vec3<f32>(fp.cov.z * inv_det, -fp.cov.y * inv_det, fp.cov.x * inv_det);
}
