// The tile compositor (src/splat/tiled/) as three compute passes, appended to
// shaders/footprint.wgsl and shaders/splat.wgsl (whose uniforms `u`, texels and helpers it
// shares; src/render/tile_pass.rs builds it).
//
// The draw order is walked nearest first in batches, as on the CPU. A batch is one or more
// pieces, nearest first: stretches of the draw orders of the grids the volumes draw from (a
// volume's one level, or the levels of a volume drawn brick by brick, whose runs alternate).
// Per batch:
// - `project`, a dispatch a piece, places each splat of the piece (its centre, conic,
//   premultiplied colour, reversed depth and pixel rectangle, exactly as `tiled::project`
//   does), one thread a splat, and writes the rectangle that holds the footprints of every 32
//   consecutive splats (a span);
// - `bound_blocks` writes the rectangle that holds the spans of every 64 consecutive spans (a
//   block);
// - `composite` runs one workgroup an 8x8-pixel tile, one thread a pixel. Binning is done in
//   three levels inside the workgroup, keeping the draw order: the blocks whose rectangle
//   meets the tile, in order, then a block at a time its spans that meet the tile, then, two
//   such spans at a time, their splats that meet the tile, in order. Each
//   pixel takes them front to back with the "under" operator `C += (1 - A) c; A += (1 - A) a`
//   and stops at the opacity `batch.opaque`; a tile whose pixels have all stopped stops.
// The accumulated layer (premultiplied RGBA a pixel) persists across batches; src/render/
// tile_pass.rs lays it over the meshes at the end.

// Every thread of a tile tests every splat that meets the tile, so a smaller tile wastes fewer
// tests on splats a few pixels wide. On an NVIDIA H200, 8x8 tiles against 16x16: the engine
// refined to 8.5M splats in 23 ms against 29, its own grid's 1.1M in 4.3 against 3.7-4.0.
const TILE: u32 = 8u;
// Threads of a compositing workgroup, one a pixel of its tile.
const LANES: u32 = TILE * TILE;
const GROUP: u32 = 256u;
// Splats a rectangle bounds (`SPAN` in src/render/tile_pass.rs), and spans in a group. In the
// grid orders consecutive splats run along a row of voxels, which an oblique view lays
// diagonally over the image: a rectangle of 32 such splats meets a few tiles, one of 256 meets
// a large square of them, each of which would then load all 256 to find its few.
const SPAN: u32 = 32u;
const SPANS: u32 = GROUP / SPAN;
// Spans a compositing round takes, one splat a thread.
const ROUND_SPANS: u32 = LANES / SPAN;
// Spans a block's rectangle bounds (`BLOCK_SPANS` in src/render/tile_pass.rs): one a thread
// of a compositing workgroup, so that a tile tests a block's spans in one round. Without
// blocks every tile tested every span's rectangle; on an NVIDIA H200 the blocks took the
// engine's splat stage at its own grid from 4.1 to 3.5 ms (BENCHMARKS.md).
const BLOCK_SPANS: u32 = LANES;

// A splat on the screen (`Projected` in src/splat/tiled/project.rs).
struct Projected {
    // Centre in pixels; conic a' and b'.
    a: vec4<f32>,
    // Premultiplied colour.
    color: vec4<f32>,
    // Conic c' and the reversed depth, as bits; the pixel rectangle, inclusive, as
    // x0 | x1 << 16 and y0 | y1 << 16 (x0 > x1 for a splat left out).
    b: vec4<u32>,
}

// A piece of a batch (projection: a stretch of one grid's draw order) or a whole batch
// (compositing: its pieces one after another, each padded to a whole group). Keep in sync with
// `BatchUniforms` in src/render/tile_pass.rs.
struct Batch {
    // Splats in the piece or the batch; the index, within the bound order, of the piece's
    // first (farthest) splat.
    count: u32,
    first: u32,
    // Image size in pixels.
    width: u32,
    height: u32,
    // Opacity that stops a pixel; cut-off of the Gaussian's exponent.
    opaque: f32,
    cutoff: f32,
    // Spans in the batch.
    spans: u32,
    // Where the piece's projected splats start in the batch's (a multiple of `GROUP`).
    out: u32,
}

@group(0) @binding(2) var<storage, read> order: array<u32>;
// A splat's peak opacity by the f16 bits of its density (`tiled::alpha_table`).
@group(0) @binding(3) var<storage, read> peak_alpha: array<f32>;
@group(0) @binding(4) var<storage, read_write> projected: array<Projected>;
@group(0) @binding(5) var<storage, read_write> group_rects: array<vec4<i32>>;
@group(0) @binding(6) var<uniform> batch: Batch;

// Per span of the group: its rectangle's lower x and y, then upper x and y.
var<workgroup> rect_lo: array<atomic<i32>, 16>;
var<workgroup> rect_hi: array<atomic<i32>, 16>;

fn left_out() -> Projected {
    return Projected(vec4<f32>(0.0), vec4<f32>(0.0), vec4<u32>(0u, 0u, 1u, 0u));
}

// `tiled::place` and `tiled::project`: the splat of voxel id `id` on the screen.
fn project_splat(id: u32) -> Projected {
    let n = u.dims.xyz;
    let k = vec3<u32>(id % n.x, (id / n.x) % n.y, id / (n.x * n.y));
    let d = vec3<f32>(k) - u.eye.xyz;
    let p = vec3<f32>(dot(u.m0.xyz, d), dot(u.m1.xyz, d), dot(u.m2.xyz, d));
    let ortho = u.size.w > 0.5;
    var depth = 0.0;
    if ortho {
        if p.z <= u.depth.y {
            return left_out();
        }
        depth = clamp((u.depth.z - p.z) / (u.depth.z - u.depth.y), 0.0, 1.0);
    } else {
        if p.z <= u.eye.w {
            return left_out();
        }
        depth = u.depth.x / p.z;
    }
    let cov = mat3x3<f32>(u.cov0.xyz, u.cov1.xyz, u.cov2.xyz);
    let fp = footprint(p, cov, u.screen.z, u.screen.xy, u.screen.w, ortho);
    if !fp.ok {
        return left_out();
    }
    let radius = sqrt(u.size.z);
    // The cut-off ellipse's bounding box and a hair (`RECT_MARGIN` in
    // src/splat/tiled/project.rs): the pixel loop tests the cut-off at each pixel.
    let ex = radius * sqrt(fp.cov.x) + 0.01;
    let ey = radius * sqrt(fp.cov.z) + 0.01;
    let w = f32(batch.width);
    let h = f32(batch.height);
    let x0 = max(i32(ceil(clamp(fp.centre.x - ex - 0.5, -1.0, w + 1.0))), 0);
    let x1 = min(i32(floor(clamp(fp.centre.x + ex - 0.5, -1.0, w + 1.0))), i32(batch.width) - 1);
    let y0 = max(i32(ceil(clamp(fp.centre.y - ey - 0.5, -1.0, h + 1.0))), 0);
    let y1 = min(i32(floor(clamp(fp.centre.y + ey - 0.5, -1.0, h + 1.0))), i32(batch.height) - 1);
    if x0 > x1 || y0 > y1 {
        return left_out();
    }
    let texel = texel_of(id);
    let peak = peak_alpha[texel.y >> 16u];
    if !(peak > 0.0) {
        return left_out();
    }
    for (var i = 0u; i < u.dims.w; i++) {
        if dot(u.clip[i].xyz, p) > u.clip[i].w {
            return left_out();
        }
    }
    var rgb = unpack4x8unorm(texel.x).xyz;
    let strength = u.n0.w;
    let g = vec3<f32>(unpack4x8snorm(texel.x).w, unpack4x8snorm(texel.y).xy);
    if strength > 0.0 && any(g != vec3<f32>(0.0)) {
        let nrm = vec3<f32>(dot(u.n0.xyz, g), dot(u.n1.xyz, g), dot(u.n2.xyz, g));
        let lambert = abs(normalize(nrm).z);
        rgb *= 1.0 - strength + strength * lambert;
    }
    let alpha = peak * fp.kept;
    let conic = footprint_conic(fp);
    return Projected(
        vec4<f32>(fp.centre, conic.x, conic.y),
        vec4<f32>(rgb * alpha, alpha),
        vec4<u32>(
            bitcast<u32>(conic.z),
            bitcast<u32>(depth),
            u32(x0) | (u32(x1) << 16u),
            u32(y0) | (u32(y1) << 16u),
        ),
    );
}

// One thread a splat of the piece, nearest first; each span's rectangle from its threads (an
// empty one, lower above upper, where none of its splats is drawn or the piece has ended).
// The threads past the piece's end fill its last group with splats left out, so that the
// next piece of the batch starts at a group.
@compute @workgroup_size(256)
fn project(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    if li < 2u * SPANS {
        atomicStore(&rect_lo[li], 0x3fffffff);
        atomicStore(&rect_hi[li], -1);
    }
    workgroupBarrier();
    let i = wg.x * GROUP + li;
    let span = 2u * (li / SPAN);
    var s = left_out();
    if i < batch.count {
        s = project_splat(order[batch.first + batch.count - 1u - i]);
        let x0 = i32(s.b.z & 0xffffu);
        let x1 = i32(s.b.z >> 16u);
        if x0 <= x1 {
            atomicMin(&rect_lo[span], x0);
            atomicMax(&rect_hi[span], x1);
            atomicMin(&rect_lo[span + 1u], i32(s.b.w & 0xffffu));
            atomicMax(&rect_hi[span + 1u], i32(s.b.w >> 16u));
        }
    }
    projected[batch.out + i] = s;
    workgroupBarrier();
    if li < SPANS {
        group_rects[(batch.out / GROUP + wg.x) * SPANS + li] = vec4<i32>(
            atomicLoad(&rect_lo[2u * li]),
            atomicLoad(&rect_lo[2u * li + 1u]),
            atomicLoad(&rect_hi[2u * li]),
            atomicLoad(&rect_hi[2u * li + 1u]),
        );
    }
}

// One thread a block of the batch: the rectangle of its spans' rectangles (an empty one where
// none of them is drawn).
@group(0) @binding(15) var<storage, read> block_spans: array<vec4<i32>>;
@group(0) @binding(16) var<storage, read_write> block_bounds: array<vec4<i32>>;
@group(0) @binding(17) var<uniform> blocking: Batch;

@compute @workgroup_size(64)
fn bound_blocks(@builtin(global_invocation_id) gid: vec3<u32>) {
    let b = gid.x;
    let first = b * BLOCK_SPANS;
    if first >= blocking.spans {
        return;
    }
    var lo = vec2<i32>(0x3fffffff);
    var hi = vec2<i32>(-1);
    for (var g = first; g < min(first + BLOCK_SPANS, blocking.spans); g++) {
        let r = block_spans[g];
        if r.x <= r.z && r.y <= r.w {
            lo = min(lo, r.xy);
            hi = max(hi, r.zw);
        }
    }
    block_bounds[b] = vec4<i32>(lo, hi);
}

@group(0) @binding(8) var<storage, read> splats: array<Projected>;
@group(0) @binding(9) var<storage, read> rects: array<vec4<i32>>;
@group(0) @binding(18) var<storage, read> blocks: array<vec4<i32>>;
@group(0) @binding(10) var<storage, read_write> layer: array<vec4<f32>>;
@group(0) @binding(11) var mesh_depth: texture_depth_2d;
@group(0) @binding(12) var<uniform> tiles: Batch;

var<workgroup> scan: array<u32, LANES>;
var<workgroup> total: u32;
var<workgroup> picked: array<u32, LANES>;
var<workgroup> picked_blocks: array<u32, LANES>;
var<workgroup> tile_splats: array<Projected, LANES>;
var<workgroup> open_pixels: atomic<u32>;
var<workgroup> still_open: u32;

// The inclusive prefix sum of `flag` over the workgroup's threads (Hillis and Steele); the sum
// of all of them in `total`, which the caller reads with `workgroupUniformLoad`.
fn prefix(li: u32, flag: u32) -> u32 {
    scan[li] = flag;
    for (var step = 1u; step < LANES; step <<= 1u) {
        workgroupBarrier();
        var v = scan[li];
        if li >= step {
            v += scan[li - step];
        }
        workgroupBarrier();
        scan[li] = v;
    }
    workgroupBarrier();
    if li == LANES - 1u {
        total = scan[LANES - 1u];
    }
    return scan[li];
}

// Whether the inclusive rectangle `r` (x0, y0, x1, y1) meets the tile whose first pixel is `t`.
fn meets(r: vec4<i32>, t: vec2<i32>) -> bool {
    return r.x <= r.z && r.y <= r.w && r.x <= t.x + i32(TILE) - 1 && r.z >= t.x && r.y <= t.y + i32(TILE) - 1
        && r.w >= t.y;
}

fn rect_of(s: Projected) -> vec4<i32> {
    return vec4<i32>(
        i32(s.b.z & 0xffffu),
        i32(s.b.w & 0xffffu),
        i32(s.b.z >> 16u),
        i32(s.b.w >> 16u),
    );
}

// How many of the tile's pixels are still open (every thread calls it).
fn count_open(li: u32, open: bool) -> u32 {
    if li == 0u {
        atomicStore(&open_pixels, 0u);
    }
    workgroupBarrier();
    if open {
        atomicAdd(&open_pixels, 1u);
    }
    workgroupBarrier();
    if li == 0u {
        still_open = atomicLoad(&open_pixels);
    }
    return workgroupUniformLoad(&still_open);
}

@compute @workgroup_size(8, 8)
fn composite(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let origin = vec2<i32>(wg.xy * TILE);
    let px = wg.xy * TILE + lid.xy;
    let inside = px.x < tiles.width && px.y < tiles.height;
    let at = px.y * tiles.width + px.x;
    var acc = vec4<f32>(0.0);
    var mesh = 0.0;
    if inside {
        acc = layer[at];
        mesh = textureLoad(mesh_depth, vec2<i32>(px), 0);
    }
    var open = inside && acc.w < tiles.opaque;
    let centre = vec2<f32>(px) + 0.5;
    var done = count_open(li, open) == 0u;
    let block_count = (tiles.spans + BLOCK_SPANS - 1u) / BLOCK_SPANS;
    for (var base = 0u; base < block_count && !done; base += LANES) {
        // The blocks of this stretch that meet the tile, in order.
        let b = base + li;
        var block_hit = 0u;
        if b < block_count && meets(blocks[b], origin) {
            block_hit = 1u;
        }
        let block_slot = prefix(li, block_hit);
        if block_hit == 1u {
            picked_blocks[block_slot - 1u] = b;
        }
        let met = workgroupUniformLoad(&total);
        for (var m = 0u; m < met && !done; m++) {
            // The spans of the block that meet the tile, in order.
            let g = workgroupUniformLoad(&picked_blocks[m]) * BLOCK_SPANS + li;
            var hit = 0u;
            if g < tiles.spans && meets(rects[g], origin) {
                hit = 1u;
            }
            let slot = prefix(li, hit);
            if hit == 1u {
                picked[slot - 1u] = g;
            }
            let spans = workgroupUniformLoad(&total);
            for (var j = 0u; j < spans && !done; j += ROUND_SPANS) {
                // The splats of the next two such spans that meet the tile, in order.
                let which = j + li / SPAN;
                var splat = left_out();
                var touch = 0u;
                if which < spans {
                    let s = picked[which] * SPAN + li % SPAN;
                    if s < tiles.count {
                        splat = splats[s];
                        if meets(rect_of(splat), origin) {
                            touch = 1u;
                        }
                    }
                }
                let place = prefix(li, touch);
                if touch == 1u {
                    tile_splats[place - 1u] = splat;
                }
                let n = workgroupUniformLoad(&total);
                for (var k = 0u; k < n; k++) {
                    let sp = tile_splats[k];
                    let r = rect_of(sp);
                    let p = vec2<i32>(px);
                    if open && p.x >= r.x && p.x <= r.z && p.y >= r.y && p.y <= r.w {
                        let dx = centre.x - sp.a.x;
                        let dy = centre.y - sp.a.y;
                        let q = (sp.a.z * dx + 2.0 * sp.a.w * dy) * dx
                            + bitcast<f32>(sp.b.x) * dy * dy;
                        if q <= tiles.cutoff && bitcast<f32>(sp.b.y) >= mesh {
                            let weight = (1.0 - acc.w) * exp(-0.5 * q);
                            acc += weight * sp.color;
                            open = acc.w < tiles.opaque;
                        }
                    }
                }
                done = count_open(li, open) == 0u;
            }
        }
    }
    if inside {
        layer[at] = acc;
    }
}

// Laying the layer over what lies under it: a triangle over the whole target, blended "over".
@group(0) @binding(13) var<storage, read> finished: array<vec4<f32>>;
@group(0) @binding(14) var<uniform> image: Batch;

@vertex
fn cover_vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let x = f32(i & 1u) * 4.0 - 1.0;
    let y = f32(i >> 1u) * 4.0 - 1.0;
    return vec4<f32>(x, y, 0.0, 1.0);
}

@fragment
fn cover_fs(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let p = vec2<u32>(pos.xy);
    return finished[p.y * image.width + p.x];
}
