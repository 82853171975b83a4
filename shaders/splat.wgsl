// One splat per significant voxel: an ellipsoidal Gaussian projected in perspective with the
// local affine approximation (EWA), premultiplied "over" in instance order, depth-tested
// against the meshes without writing depth. The footprint is shaders/footprint.wgsl, prepended
// to this file (src/splat/footprint.rs on the CPU), so GPU frames can be checked against the
// CPU compositors.
// Keep in sync with SplatUniforms in src/render/splat_pass.rs.

struct Splat {
    // Rows of the index-offset -> camera matrix (x right, y up, z forward), world units.
    m0: vec4<f32>,
    m1: vec4<f32>,
    m2: vec4<f32>,
    // xyz: the eye in voxel index coordinates; w: splats nearer than this are left out.
    eye: vec4<f32>,
    // Rows of the camera-space covariance of a splat (sigma^2 M M^T).
    cov0: vec4<f32>,
    cov1: vec4<f32>,
    cov2: vec4<f32>,
    // x, y: image centre in pixels; z: focal length in pixels (perspective) or pixels per
    // world unit (orthographic); w: screen-space variance added to every footprint.
    screen: vec4<f32>,
    // x, y: image size; z: cut-off of the Gaussian's exponent (radius^2 / sigma^2);
    // w: 1 for orthographic.
    size: vec4<f32>,
    // x: perspective depth scale (near plane); orthographic: y near, z far; w: millimetres one
    // index step spans along the view (a splat's opacity is 1 - exp(-density * w)).
    depth: vec4<f32>,
    // Grid size; w: clip planes in use.
    dims: vec4<u32>,
    // Rows of the index-space gradient -> camera-space normal matrix (R L^-T); n0.w is the
    // shading strength (0: flat colour, 1: fully headlight-shaded).
    n0: vec4<f32>,
    n1: vec4<f32>,
    n2: vec4<f32>,
    // Clip planes in camera space (x right, y up, z forward, eye at the origin): a splat is
    // kept where dot(xyz, p) <= w for each; dims.w counts them. The scene's planes and crop
    // box, then in perspective the four beside the view (src/splat/footprint.rs,
    // `beside_the_view`).
    clip: array<vec4<f32>, 16>,
}

@group(0) @binding(0) var<uniform> u: Splat;
// Per significant voxel, in id order, the tile compositor's 8-byte texel (src/splat/tiled/
// texels.rs): x holds straight RGB8 and the gradient's x, y holds its y and z (snorm8, all zero
// where undefined) and the density as an f16 in its high half. This and the bitmap below are
// lists held row by row in 2-D textures: a storage buffer holds less on some adapters (128 MiB
// on lavapipe, 16M texels).
@group(0) @binding(1) var texels: texture_2d<u32>;
// The grid's bitmap with its rank index (`PagedBits::to_gpu_words` in src/grid/pages.rs): three
// offsets (page ranks, word ranks, words), the page table, then those three.
@group(0) @binding(7) var bitmap: texture_2d<u32>;

// Element `i` of a list held row by row in `t`.
fn at(t: texture_2d<u32>, i: u32) -> vec4<u32> {
    let w = textureDimensions(t).x;
    return textureLoad(t, vec2<u32>(i % w, i / w), 0);
}

// Word `i` of the bitmap's list.
fn word(i: u32) -> u32 {
    return at(bitmap, i).x;
}

// Words of 64 voxels a page of the bitmap (`PAGE_WORDS` in src/grid/pages.rs).
const PAGE_WORDS: u32 = 16u;

// The texel of voxel `id`: its rank among the significant voxels from the bitmap, as
// `PagedBits::rank` finds it. Zero (no density, so left out) for a voxel that is not
// significant; the orders hold only significant ones.
fn texel_of(id: u32) -> vec2<u32> {
    let w = id / 64u;
    let page = 3u + w / PAGE_WORDS;
    if page >= word(0u) {
        return vec2<u32>(0u);
    }
    let slot = word(page);
    if slot == 0xffffffffu {
        return vec2<u32>(0u);
    }
    let i = slot * PAGE_WORDS + w % PAGE_WORDS;
    let lo = word(word(2u) + 2u * i);
    let hi = word(word(2u) + 2u * i + 1u);
    let bit = id % 64u;
    var below = 0u;
    var found = false;
    if bit < 32u {
        below = countOneBits(lo & ((1u << bit) - 1u));
        found = ((lo >> bit) & 1u) == 1u;
    } else {
        below = countOneBits(lo) + countOneBits(hi & ((1u << (bit - 32u)) - 1u));
        found = ((hi >> (bit - 32u)) & 1u) == 1u;
    }
    if !found {
        return vec2<u32>(0u);
    }
    return at(texels, word(word(0u) + slot) + word(word(1u) + i) + below).xy;
}

// A non-negative IEEE half, given by its bits, as f32 (written out: `unpack2x16float` needs a
// capability not every device has). Infinity and NaN (never written) come out as 2^17, which
// makes any splat opaque.
fn half_bits_to_f32(h: u32) -> f32 {
    let e = (h >> 10u) & 0x1fu;
    let m = h & 0x3ffu;
    if e == 0u {
        return f32(m) * 5.9604645e-8;
    }
    if e == 31u {
        return 131072.0;
    }
    return bitcast<f32>(((e + 112u) << 23u) | (m << 13u));
}

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    // Pixel offset from the footprint centre.
    @location(0) offset: vec2<f32>,
    @location(1) @interpolate(flat) conic: vec3<f32>,
    @location(2) @interpolate(flat) color: vec4<f32>,
}

fn discarded() -> VsOut {
    var out: VsOut;
    out.clip = vec4<f32>(2.0, 2.0, 2.0, 1.0);
    out.offset = vec2<f32>(0.0);
    out.conic = vec3<f32>(0.0);
    out.color = vec4<f32>(0.0);
    return out;
}

@vertex
fn vs_main(@builtin(vertex_index) corner: u32, @location(0) id: u32) -> VsOut {
    let n = u.dims.xyz;
    let k = vec3<u32>(id % n.x, (id / n.x) % n.y, id / (n.x * n.y));
    let texel = texel_of(id);
    let density = half_bits_to_f32(texel.y >> 16u);
    let peak = 1.0 - exp(-density * u.depth.w);
    let d = vec3<f32>(k) - u.eye.xyz;
    let p = vec3<f32>(dot(u.m0.xyz, d), dot(u.m1.xyz, d), dot(u.m2.xyz, d));
    let ortho = u.size.w > 0.5;
    if !(peak > 0.0) || (!ortho && p.z <= u.eye.w) || (ortho && p.z <= u.depth.y) {
        return discarded();
    }
    for (var i = 0u; i < u.dims.w; i++) {
        if dot(u.clip[i].xyz, p) > u.clip[i].w {
            return discarded();
        }
    }
    var z = clamp((u.depth.z - p.z) / (u.depth.z - u.depth.y), 0.0, 1.0);
    if !ortho {
        z = u.depth.x * (1.0 / p.z);
    }
    let cov = mat3x3<f32>(u.cov0.xyz, u.cov1.xyz, u.cov2.xyz);
    let fp = footprint(p, cov, u.screen.z, u.screen.xy, u.screen.w, ortho);
    if !fp.ok {
        return discarded();
    }
    let centre = fp.centre;
    let a = fp.cov.x;
    let c = fp.cov.z;
    // The ellipse q = cut-off spans exactly +-radius*sqrt(a) by +-radius*sqrt(c) pixels: the
    // quad is its bounding box and a hair (`RECT_MARGIN` in src/splat/tiled/project.rs), so
    // that it rasterises the pixels whose centres the ellipse may hold and no more.
    let radius = sqrt(u.size.z);
    let corner_sign = vec2<f32>(f32(corner & 1u) * 2.0 - 1.0, f32((corner >> 1u) & 1u) * 2.0 - 1.0);
    let offset = corner_sign * (radius * sqrt(vec2<f32>(a, c)) + 0.01);
    let pixel = centre + offset;
    var out: VsOut;
    out.clip = vec4<f32>(pixel.x / u.size.x * 2.0 - 1.0, 1.0 - pixel.y / u.size.y * 2.0, z, 1.0);
    out.offset = offset;
    out.conic = footprint_conic(fp);
    var rgb = unpack4x8unorm(texel.x).xyz;
    let strength = u.n0.w;
    let g = vec3<f32>(unpack4x8snorm(texel.x).w, unpack4x8snorm(texel.y).xy);
    if strength > 0.0 {
        if any(g != vec3<f32>(0.0)) {
            let n = vec3<f32>(dot(u.n0.xyz, g), dot(u.n1.xyz, g), dot(u.n2.xyz, g));
            // Headlight, two-sided: a surface facing the eye either way is lit.
            let lambert = abs(normalize(n).z);
            rgb *= 1.0 - strength + strength * lambert;
        }
    }
    // Mip-Splatting's 2-D filter: the pixel variance widens the footprint, and the opacity
    // shrinks so that its integral over the image is kept.
    let alpha = peak * fp.kept;
    out.color = vec4<f32>(rgb * alpha, alpha);
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    let d = in.offset;
    let q = in.conic.x * d.x * d.x + 2.0 * in.conic.y * d.x * d.y + in.conic.z * d.y * d.y;
    if q > u.size.z {
        discard;
    }
    return in.color * exp(-0.5 * q);
}
