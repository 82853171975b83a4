//! `splatscene contact`: what a mesh's surface touches in the volume, as JSON.

use anyhow::{Result, bail};

use splatscene::pick::contact::{Classes, contact};

use super::input::InputArgs;

/// `splatscene contact`.
#[derive(clap::Args)]
pub struct ContactArgs {
    #[command(flatten)]
    input: InputArgs,
    /// Class edges, increasing (values, HU for CT): `200,700` makes below 200, 200 to 700,
    /// and 700 and above. Default for CT: soft tissue or air below 200 HU, cancellous bone
    /// to 700, cortical bone above.
    #[arg(long, value_parser = parse_edges, allow_hyphen_values = true)]
    classes: Option<Edges>,
}

/// Class edges as given.
#[derive(Clone)]
struct Edges(Vec<f64>);

/// Comma-separated numbers.
fn parse_edges(s: &str) -> Result<Edges, String> {
    s.split(',')
        .map(|v| {
            v.trim()
                .parse::<f64>()
                .map_err(|_| format!("{v:?} is not a number (give edges such as 200,700)"))
        })
        .collect::<Result<Vec<_>, _>>()
        .map(Edges)
}

/// Measures the contact and prints it. A `--mesh` that names no file but a mesh of the scene
/// chooses that mesh; else the first mesh added with `--mesh`, else the scene's first mesh.
pub fn run_contact(mut args: ContactArgs) -> Result<()> {
    let (files, names): (Vec<_>, Vec<_>) = std::mem::take(&mut args.input.meshes)
        .into_iter()
        .partition(|p| p.exists());
    if names.len() > 1 {
        bail!(
            "--mesh: {} and {} are no files; name one mesh of the scene to measure",
            names[0].display(),
            names[1].display()
        );
    }
    let added = files
        .first()
        .and_then(|p| p.file_name())
        .map(|n| n.to_string_lossy().into_owned());
    args.input.meshes = files;
    let (loaded, _) = args.input.load()?;
    let scene = &loaded.scene;
    let chosen = names
        .first()
        .map(|n| n.to_string_lossy().into_owned())
        .or(added);
    let classes = match &args.classes {
        Some(Edges(edges)) => Classes::from_edges(edges)?,
        None => {
            let volume = scene.volumes().next();
            let classes =
                volume.map_or_else(Classes::none, |(_, v, _)| Classes::for_volume(&v.volume));
            if classes.is_empty() && volume.is_some() {
                eprintln!(
                    "note: the volume is not CT (no values at air's -1000 HU): no classes without --classes"
                );
            }
            classes
        }
    };
    let report = contact(scene, chosen.as_deref(), &classes)?;
    println!("{}", serde_json::to_string_pretty(&report)?);
    Ok(())
}
