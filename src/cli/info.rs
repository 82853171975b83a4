//! `splatscene info`: volumes described as JSON.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

#[derive(clap::Args)]
pub(crate) struct InfoArgs {
    /// Volume files (or DICOM series folders).
    #[arg(required = true)]
    files: Vec<PathBuf>,
    #[command(flatten)]
    choices: super::input::VolumeChoices,
}

/// Prints the description of every volume named, one JSON object or an array.
pub(crate) fn run_info(args: InfoArgs) -> Result<()> {
    let options = args.choices.options()?;
    let mut infos = Vec::with_capacity(args.files.len());
    for file in &args.files {
        infos.push(info_of(file, &options)?);
    }
    let out = match infos.len() {
        1 => infos.remove(0),
        _ => serde_json::Value::Array(infos),
    };
    println!("{}", serde_json::to_string_pretty(&out)?);
    Ok(())
}

/// Folders below a folder that `info` looks into for DICOM series, at most.
const MAX_INFO_FOLDERS: usize = 10_000;

/// A volume's description; for a folder tree holding anything but one series in the folder
/// itself, the list of every DICOM series found below it.
fn info_of(
    path: &Path,
    options: &splatscene::volume::detect::LoadOptions,
) -> Result<serde_json::Value> {
    let describe = |path: &Path| -> Result<serde_json::Value> {
        let loaded = splatscene::volume::detect::load_volume_with(path, options)?;
        Ok(loaded.info(path))
    };
    if !path.is_dir() || options.series.is_some() {
        return describe(path);
    }
    let mut series = Vec::new();
    let mut folders = vec![path.to_path_buf()];
    let mut seen = 0;
    while let Some(dir) = folders.pop() {
        seen += 1;
        if seen > MAX_INFO_FOLDERS {
            bail!(
                "{}: more than {MAX_INFO_FOLDERS} folders below it",
                path.display()
            );
        }
        series.extend(splatscene::volume::dicom::list_series(&dir)?);
        let mut subfolders: Vec<PathBuf> = std::fs::read_dir(&dir)
            .with_context(|| format!("{}: cannot list", dir.display()))?
            .filter_map(|e| e.ok())
            // Links to folders are not followed, so a link loop cannot walk forever.
            .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
            .map(|e| e.path())
            .collect();
        subfolders.sort_unstable_by(|a, b| b.cmp(a));
        folders.extend(subfolders);
    }
    if let [only] = series.as_slice()
        && only.folder == path
    {
        return describe(path);
    }
    if series.is_empty() {
        bail!(
            "{}: no DICOM series in this folder or below it",
            path.display()
        );
    }
    Ok(serde_json::json!({
        "folder": path.display().to_string(),
        "series": series,
    }))
}
