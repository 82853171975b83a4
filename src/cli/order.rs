//! `splatscene order`: the draw order of a dense grid, as little-endian voxel ids.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use glam::DVec3;
use splatscene::grid::SparseGrid;
use splatscene::order::{OrderOptions, Orderer, Ordering, ViewCase, VolumeGeometry};

use super::args::{parse_f64x3, parse_u32x3};
use super::files::write_replacing;

#[derive(clap::Args)]
pub(crate) struct OrderArgs {
    /// Grid size NX,NY,NZ.
    #[arg(long, value_parser = parse_u32x3)]
    dims: [u32; 3],
    /// Voxel spacing SX,SY,SZ.
    #[arg(long, value_parser = parse_f64x3, default_value = "1,1,1")]
    spacing: [f64; 3],
    /// Eye in voxel index coordinates (voxel centres at integers).
    #[arg(long, value_parser = parse_f64x3, allow_hyphen_values = true)]
    eye: [f64; 3],
    /// Target in voxel index coordinates; the grid centre by default.
    #[arg(long, value_parser = parse_f64x3, allow_hyphen_values = true)]
    target: Option<[f64; 3]>,
    /// btf, wbtf, pbtf, ip-pbtf, ip-pbtf-explicit, ip-pbtf-implicit, exact, bucketed, pyramid or
    /// rows.
    #[arg(long)]
    ordering: Ordering,
    /// Output file; standard output when absent.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Leave out voxels on or behind the plane through the eye.
    #[arg(long)]
    cull_behind_eye: bool,
    /// Bucket width of the bucketed order, in the units of --spacing; half the smallest
    /// spacing by default.
    #[arg(long)]
    bucket_width: Option<f64>,
}

/// Writes the order of a dense grid for the eye given, after checking it fits in memory.
pub(crate) fn run_order(args: OrderArgs) -> Result<()> {
    let geometry = VolumeGeometry::axis_aligned(args.dims, args.spacing, [0.0; 3])?;
    let to_world = |p: [f64; 3]| geometry.index_to_world_point(DVec3::from(p));
    let target = args.target.map_or(geometry.centre_world(), to_world);
    let view = ViewCase::new(&geometry, to_world(args.eye), target)?;
    let needed = splatscene::order::dense_order_bytes(args.dims, args.ordering);
    let available = splatscene::budget::memory_budget();
    if needed > available {
        let gib = |b: u64| b as f64 / f64::from(1u32 << 30);
        bail!(
            "--dims {},{},{}: the {} order of this dense grid needs about {:.1} GiB of memory; {:.1} GiB is available",
            args.dims[0],
            args.dims[1],
            args.dims[2],
            args.ordering,
            gib(needed),
            gib(available)
        );
    }
    let grid = SparseGrid::dense(args.dims)?;
    if args.bucket_width.is_some() && args.ordering != Ordering::Bucketed {
        bail!(
            "--bucket-width applies to the bucketed order only, not {}",
            args.ordering
        );
    }
    let options = OrderOptions {
        cull_behind_eye: args.cull_behind_eye,
        bucket_width: args.bucket_width,
    };
    let mut ids = Vec::new();
    let start = Instant::now();
    Orderer::new().order(&grid, &view, args.ordering, &options, &mut ids)?;
    let elapsed = start.elapsed();
    let bytes: Vec<u8> = ids.iter().flat_map(|id| id.to_le_bytes()).collect();
    match &args.out {
        Some(path) => write_replacing(path, &bytes)?,
        None => std::io::stdout()
            .lock()
            .write_all(&bytes)
            .context("writing the order to standard output")?,
    }
    eprintln!("{view}");
    eprintln!(
        "ordering {}: {} voxels in {:.3} ms",
        args.ordering,
        ids.len(),
        elapsed.as_secs_f64() * 1e3
    );
    Ok(())
}
