//! The `splatscene` command line: parsing and dispatch; each command lives in `cli/`.

use anyhow::Result;
use clap::{Parser, Subcommand};

mod cli;

#[derive(Parser)]
#[command(
    name = "splatscene",
    version,
    about = "Shoulder-prosthesis planning scenes: CT splats in IP-PBTF order"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Let files named inside mesh files (glTF buffers, OBJ material libraries) lie outside
    /// the mesh file's folder; refused by default, so that a mesh from elsewhere cannot read
    /// any file of this machine.
    #[arg(long, global = true)]
    allow_outside_paths: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Write the draw order of a dense grid as little-endian u32 voxel ids, first drawn first.
    Order(cli::order::OrderArgs),
    /// Compare every ordering's run time and image error along a camera path.
    Orderings(cli::orderings::OrderingsArgs),
    /// Render a scene file (the built-in shoulder scene without one) to a PNG.
    Render(cli::render::RenderArgs),
    /// Pick what lies under a pixel: prints the hit as JSON (or that nothing was hit).
    Pick(cli::pick::PickArgs),
    /// Measure a distance or an angle between picked pixels or given points, as JSON.
    Measure(cli::measure::MeasureArgs),
    /// What a mesh's surface touches in the volume, as JSON: its area by value class (for CT:
    /// soft tissue or air, cancellous and cortical bone) and the value under it.
    Contact(cli::contact::ContactArgs),
    /// Open a viewer window: orbit, pick, select and move meshes, measure, undo, save the plan,
    /// switch orderings and transfer functions.
    #[command(after_help = splatscene::viewer::keys_help())]
    View(cli::view::ViewerArgs),
    /// Render the pictures a manifest lists, many cases and views in one process (volumes
    /// classified once per job), resumable, and sharded over a Slurm array with --shard.
    Batch(cli::batch::BatchArgs),
    /// Describe volumes as JSON: size, spacing, origin, direction, scalar type, minimum,
    /// maximum and mean (one object for one file, an array for several). A DICOM series is
    /// given as its folder, a .dat or .nhdr volume as its header.
    Info(cli::info::InfoArgs),
}

fn main() -> Result<()> {
    quiet_device_select();
    let cli = Cli::parse();
    splatscene::mesh::allow_outside_paths(cli.allow_outside_paths);
    match cli.command {
        Command::Order(args) => cli::order::run_order(args),
        Command::Orderings(args) => cli::orderings::run_orderings(args),
        Command::Render(args) => cli::render::run_render(args),
        Command::Pick(args) => cli::pick::run_pick(args),
        Command::Measure(args) => cli::measure::run_measure(args),
        Command::Contact(args) => cli::contact::run_contact(args),
        Command::View(args) => cli::view::run_viewer(args),
        Command::Info(args) => cli::info::run_info(args),
        Command::Batch(args) => cli::batch::run_batch(args),
    }
}

/// Mesa's device-select Vulkan layer complains about XDG_RUNTIME_DIR on headless machines;
/// it is noise for a command-line renderer.
#[allow(unsafe_code)]
fn quiet_device_select() {
    if std::env::var_os("NODEVICE_SELECT").is_none() {
        // SAFETY: called first thing in main, before any other thread exists.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}
