// Opaque meshes with depth write, lit by a headlight, an ambient term and directional lights.
// Positions are relative to the eye (camera-relative rendering): far-away or huge-coordinate
// scenes keep f32 precision near the viewer.
// Keep in sync with FrameUniforms and ObjectUniforms in src/render/mesh_pass.rs.

struct Frame {
    // Camera-relative world -> clip (rotation and projection only; the eye is the origin).
    view_proj: mat4x4<f32>,
    // xyz: direction the camera looks (world), w: headlight intensity.
    forward: vec4<f32>,
    // x: ambient, y: number of directional lights, z: 1 for orthographic, w: clip planes.
    params: vec4<f32>,
    // Directional lights: xyz direction of travel (world, unit), then rgb colour.
    light_dir: array<vec4<f32>, 4>,
    light_color: array<vec4<f32>, 4>,
    // Clip planes in camera-relative world space: kept where dot(xyz, p) <= w. params.w counts.
    clip: array<vec4<f32>, 12>,
}

struct Object {
    // Model -> camera-relative world.
    model: mat4x4<f32>,
    // Inverse transpose of the model's linear part (columns in xyz).
    normal: mat4x4<f32>,
    base_color: vec4<f32>,
    // x: roughness, y: metallic.
    material: vec4<f32>,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(1) @binding(0) var<uniform> object: Object;

struct VsOut {
    // Invariant: translucent meshes are drawn twice (depth, then colour where the depth is
    // equal), and both draws must give the same depth.
    @invariant @builtin(position) clip: vec4<f32>,
    @location(0) rel: vec3<f32>,
    @location(1) normal: vec3<f32>,
    // The vertex's colour, multiplying the material's (white for a mesh without colours).
    @location(2) color: vec4<f32>,
}

@vertex
fn vs_main(
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
) -> VsOut {
    let rel = object.model * vec4<f32>(position, 1.0);
    var out: VsOut;
    out.clip = frame.view_proj * rel;
    out.rel = rel.xyz;
    out.normal = (object.normal * vec4<f32>(normal, 0.0)).xyz;
    out.color = color;
    return out;
}

fn shade(n: vec3<f32>, l: vec3<f32>, v: vec3<f32>, color: vec3<f32>) -> vec3<f32> {
    let roughness = clamp(object.material.x, 0.04, 1.0);
    let metallic = clamp(object.material.y, 0.0, 1.0);
    let diffuse = max(dot(n, l), 0.0) * (1.0 - 0.5 * metallic);
    let h = normalize(l + v);
    let shininess = 2.0 / (roughness * roughness * roughness * roughness) - 2.0;
    let spec_color = mix(vec3<f32>(0.04), object.base_color.rgb, metallic);
    let specular = pow(max(dot(n, h), 0.0), max(shininess, 1.0)) * step(0.0, dot(n, l));
    return diffuse * color + specular * spec_color * (1.0 - roughness * 0.5);
}

@fragment
fn fs_main(in: VsOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    for (var i = 0u; i < u32(frame.params.w); i++) {
        if dot(frame.clip[i].xyz, in.rel) > frame.clip[i].w {
            discard;
        }
    }
    var n = normalize(in.normal);
    if !front {
        n = -n;
    }
    var v = -normalize(in.rel);
    if frame.params.z > 0.5 {
        v = -frame.forward.xyz;
    }
    let base = object.base_color.rgb * in.color.rgb;
    // Metals have little diffuse light; a view-dependent sheen stands in for the reflected
    // surroundings so that they do not go dark.
    let metallic = clamp(object.material.y, 0.0, 1.0);
    let sheen = metallic * (0.35 + 0.45 * pow(1.0 - max(dot(n, v), 0.0), 2.0));
    var c = frame.params.x * base + sheen * base;
    c += frame.forward.w * shade(n, -frame.forward.xyz, v, base);
    let count = u32(frame.params.y);
    for (var i = 0u; i < count; i++) {
        c += frame.light_color[i].rgb * shade(n, -frame.light_dir[i].xyz, v, base);
    }
    // Premultiplied: an opaque mesh (alpha 1) writes its colour, a translucent one is
    // blended over what lies behind it.
    let a = clamp(object.base_color.a, 0.0, 1.0);
    return vec4<f32>(c * a, a);
}
