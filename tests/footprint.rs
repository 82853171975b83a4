//! The splat footprint three ways, held to each other: the shared function in f64 (the
//! reference compositor's), in f32 (the tile compositor's), and its WGSL mirror
//! (`shaders/footprint.wgsl`, which the splat pass prepends to its shader) run as a compute
//! shader on whatever adapter wgpu finds (lavapipe in CI). The cases are random covariances,
//! depths, focal lengths and both projections, plus degenerate ones.

use splatscene::render::GpuContext;
use splatscene::splat::footprint::{Footprint, Lens, footprint};
use wgpu::util::DeviceExt;

/// One case, as the compute shader reads it: `p` (w unused), the covariance's rows, and
/// (focal, centre x, centre y, pixel variance), (orthographic, 0, 0, 0).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Case {
    p: [f32; 4],
    cov: [[f32; 4]; 3],
    lens: [f32; 4],
    flags: [f32; 4],
}

const KERNEL: &str = r"
struct Case { p: vec4<f32>, cov0: vec4<f32>, cov1: vec4<f32>, cov2: vec4<f32>, lens: vec4<f32>, flags: vec4<f32> }
@group(0) @binding(0) var<storage, read> cases: array<Case>;
@group(0) @binding(1) var<storage, read_write> out: array<vec4<f32>>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= arrayLength(&cases) {
        return;
    }
    let c = cases[i];
    let cov = mat3x3<f32>(c.cov0.xyz, c.cov1.xyz, c.cov2.xyz);
    let fp = footprint(c.p.xyz, cov, c.lens.x, c.lens.yz, c.lens.w, c.flags.x > 0.5);
    out[3u * i] = vec4<f32>(fp.centre, fp.kept, select(0.0, 1.0, fp.ok));
    out[3u * i + 1u] = vec4<f32>(fp.cov, 0.0);
    var conic = vec3<f32>(0.0);
    if fp.ok {
        conic = footprint_conic(fp);
    }
    out[3u * i + 2u] = vec4<f32>(conic, 0.0);
}
";

/// A small deterministic generator (SplitMix64), so the cases are the same every run.
struct Random(u64);

impl Random {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn between(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

/// Random well-conditioned cases (covariances `s^2 M M^T` of a random `M`, as a grid's
/// splats have) and a few that have no footprint.
fn cases() -> Vec<Case> {
    let mut random = Random(29);
    let mut out = Vec::new();
    for i in 0..512 {
        let m: [[f64; 3]; 3] =
            std::array::from_fn(|_| std::array::from_fn(|_| random.between(-1.0, 1.0)));
        let s2 = random.between(0.05, 2.0).powi(2);
        // M M^T is positive semi-definite; a little of the identity keeps it definite.
        let cov: [[f64; 3]; 3] = std::array::from_fn(|r| {
            std::array::from_fn(|c| {
                let mm: f64 = (0..3).map(|k| m[r][k] * m[c][k]).sum();
                s2 * (mm + if r == c { 0.05 } else { 0.0 })
            })
        });
        let orthographic = i % 3 == 0;
        let z = random.between(2.0, 500.0);
        let p = [
            random.between(-0.4, 0.4) * z,
            random.between(-0.4, 0.4) * z,
            z,
        ];
        let focal = if orthographic {
            random.between(0.5, 8.0)
        } else {
            random.between(100.0, 2000.0)
        };
        let variance = if i % 2 == 0 {
            0.3
        } else {
            random.between(0.0, 1.0)
        };
        out.push(case(p, cov, [focal, 256.0, 200.0, variance], orthographic));
    }
    // No footprint: no covariance and no pixel variance; NaN.
    out.push(case(
        [0.0, 0.0, 10.0],
        [[0.0; 3]; 3],
        [500.0, 64.0, 64.0, 0.0],
        false,
    ));
    out.push(case(
        [0.0, 0.0, 10.0],
        [[f64::NAN; 3]; 3],
        [500.0, 64.0, 64.0, 0.3],
        false,
    ));
    out
}

fn case(p: [f64; 3], cov: [[f64; 3]; 3], lens: [f64; 4], orthographic: bool) -> Case {
    Case {
        p: [p[0] as f32, p[1] as f32, p[2] as f32, 0.0],
        cov: cov.map(|r| [r[0] as f32, r[1] as f32, r[2] as f32, 0.0]),
        lens: lens.map(|v| v as f32),
        flags: [f32::from(u8::from(orthographic)), 0.0, 0.0, 0.0],
    }
}

/// The case's footprint by the shared function, in f64 from the f32 inputs the others see.
fn in_f64(c: &Case) -> Option<Footprint<f64>> {
    let p = [0, 1, 2].map(|i| f64::from(c.p[i]));
    let cov = c.cov.map(|r| [0, 1, 2].map(|i| f64::from(r[i])));
    let lens = Lens {
        focal: f64::from(c.lens[0]),
        centre: [f64::from(c.lens[1]), f64::from(c.lens[2])],
        pixel_variance: f64::from(c.lens[3]),
        orthographic: c.flags[0] > 0.5,
    };
    footprint(p, &cov, &lens)
}

/// The case's footprint by the shared function in f32, as the tile compositor calls it.
fn in_f32(c: &Case) -> Option<Footprint<f32>> {
    let p = [c.p[0], c.p[1], c.p[2]];
    let cov = c.cov.map(|r| [r[0], r[1], r[2]]);
    let lens = Lens {
        focal: c.lens[0],
        centre: [c.lens[1], c.lens[2]],
        pixel_variance: c.lens[3],
        orthographic: c.flags[0] > 0.5,
    };
    footprint(p, &cov, &lens)
}

/// Whether `got` is `want` within `rel` of the larger of `|want|` and `scale`.
fn close(got: f64, want: f64, rel: f64, scale: f64) -> bool {
    (got - want).abs() <= rel * want.abs().max(scale)
}

/// The shader's outputs: per case, (centre x, centre y, kept, ok), (a, b, c, 0), conic.
fn run_on_gpu(ctx: &GpuContext, cases: &[Case]) -> Vec<[f32; 4]> {
    let source = format!("{}\n{KERNEL}", include_str!("../shaders/footprint.wgsl"));
    let device = &ctx.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("footprint test"),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("footprint test"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("cases"),
        contents: bytemuck::cast_slice(cases),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = (cases.len() * 3 * 16) as u64;
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("footprints"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("footprint test"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: output.as_entire_binding(),
            },
        ],
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups((cases.len() as u32).div_ceil(64), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&output, 0, &readback, 0, size);
    ctx.queue.submit([encoder.finish()]);
    let (sender, receiver) = std::sync::mpsc::channel();
    readback.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = sender.send(r);
    });
    ctx.wait().unwrap();
    receiver.recv().unwrap().unwrap();
    let mapped = readback.get_mapped_range(..).unwrap();
    let out = bytemuck::cast_slice::<u8, [f32; 4]>(&mapped).to_vec();
    drop(mapped);
    readback.unmap();
    out
}

#[test]
fn the_footprint_is_the_same_in_f64_f32_and_the_shader() {
    let cases = cases();
    let ctx = GpuContext::headless().expect("a GPU adapter (install mesa-vulkan-drivers)");
    let gpu = run_on_gpu(&ctx, &cases);
    let mut compared = 0;
    for (i, c) in cases.iter().enumerate() {
        let (wide, single) = (in_f64(c), in_f32(c));
        let [head, cov, conic] = [gpu[3 * i], gpu[3 * i + 1], gpu[3 * i + 2]];
        let gpu_ok = head[3] > 0.5;
        assert_eq!(
            wide.is_some(),
            single.is_some(),
            "case {i}: f64 {wide:?}, f32 {single:?}"
        );
        assert_eq!(
            wide.is_some(),
            gpu_ok,
            "case {i}: f64 {wide:?}, shader {head:?} {cov:?}"
        );
        let (Some(wide), Some(single)) = (wide, single) else {
            continue;
        };
        compared += 1;
        // Centres to a thousandth of a pixel (of a scale of 1,000 pixels), covariances and
        // conics to 1e-3 of the largest entry; the kept share to 2e-3, since its square root
        // turns the f32 rounding of a sub-pixel splat's own determinant near 0 (about 1e-7 of
        // the widened one) into a few 1e-4.
        let scale = |v: [f64; 3]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let wide_conic = wide.conic();
        for (name, got) in [
            (
                "f32",
                [
                    single.centre.map(f64::from).to_vec(),
                    single.cov.map(f64::from).to_vec(),
                    single.conic().map(f64::from).to_vec(),
                    vec![f64::from(single.kept)],
                ],
            ),
            (
                "shader",
                [
                    vec![f64::from(head[0]), f64::from(head[1])],
                    cov[..3].iter().map(|&v| f64::from(v)).collect(),
                    conic[..3].iter().map(|&v| f64::from(v)).collect(),
                    vec![f64::from(head[2])],
                ],
            ),
        ] {
            let [centre, cov, conic, kept] = &got;
            for k in 0..2 {
                assert!(
                    close(centre[k], wide.centre[k], 1e-5, 1000.0),
                    "case {i} {name}: centre {centre:?}, f64 {:?}",
                    wide.centre
                );
            }
            for k in 0..3 {
                assert!(
                    close(cov[k], wide.cov[k], 1e-4, scale(wide.cov)),
                    "case {i} {name}: covariance {cov:?}, f64 {:?}",
                    wide.cov
                );
                assert!(
                    close(conic[k], wide_conic[k], 1e-3, scale(wide_conic)),
                    "case {i} {name}: conic {conic:?}, f64 {wide_conic:?}"
                );
            }
            assert!(
                (kept[0] - wide.kept).abs() < 2e-3,
                "case {i} {name}: kept {}, f64 {}",
                kept[0],
                wide.kept
            );
        }
    }
    // Every generated case has a footprint; the two degenerate ones have none.
    assert_eq!(compared, cases.len() - 2);
}
