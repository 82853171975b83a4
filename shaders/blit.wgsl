// Copies the offscreen colour target to a window's surface, pixel for pixel: one triangle
// that covers the screen, and a load of the texel under each fragment; an overlay (annotations,
// straight alpha) is blended over it where it covers the fragment.
// Keep in sync with src/render/blit.rs.

@group(0) @binding(0) var source: texture_2d<f32>;
@group(0) @binding(1) var overlay: texture_2d<f32>;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs_main(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let at = vec2<i32>(p.xy);
    let c = textureLoad(source, at, 0);
    let size = vec2<i32>(textureDimensions(overlay));
    var o = vec4<f32>(0.0);
    if (at.x < size.x && at.y < size.y) {
        o = textureLoad(overlay, at, 0);
    }
    return vec4<f32>(mix(c.rgb, o.rgb, o.a), 1.0);
}
