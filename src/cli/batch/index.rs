//! The output folder's index: what each job read (with content hashes), wrote (with hashes and
//! cameras), how long it took and how it failed; one file per shard, joined by `--merge`.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};

use splatscene::scene::{Projection, SceneCamera};

use super::manifest::is_index_name;

/// A file and the BLAKE3 hash of its bytes.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FileHash {
    /// Where it is.
    pub path: String,
    /// BLAKE3 of its bytes, hex.
    pub blake3: String,
}

/// An input of a job and the hash of its content as loaded.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct InputRecord {
    /// `scene`, `volume` or `mesh`.
    pub kind: String,
    /// The path as the job names it.
    pub path: String,
    /// BLAKE3 of the content: a scene file's bytes; a volume's size, placement and values as
    /// loaded (so the hash does not depend on the file layout or format); a mesh's triangles,
    /// normals, materials and part transforms.
    pub blake3: String,
}

/// A camera as used.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct CameraRecord {
    /// Eye (world millimetres).
    pub eye: [f64; 3],
    /// Target.
    pub target: [f64; 3],
    /// Up on screen.
    pub up: [f64; 3],
    /// `perspective` or `orthographic`.
    pub projection: String,
    /// Vertical field of view in degrees (perspective).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fov_degrees: Option<f64>,
    /// Visible height in millimetres (orthographic).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_mm: Option<f64>,
}

impl CameraRecord {
    /// The record of `camera`.
    pub fn of(camera: &SceneCamera) -> Self {
        let (projection, fov_degrees, height_mm) = match camera.projection {
            Projection::Perspective { fov_y_degrees } => ("perspective", Some(fov_y_degrees), None),
            Projection::Orthographic { height } => ("orthographic", None, Some(height)),
        };
        Self {
            eye: camera.eye.to_array(),
            target: camera.target.to_array(),
            up: camera.up.to_array(),
            projection: projection.into(),
            fov_degrees,
            height_mm,
        }
    }
}

/// A file a job wrote.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct OutputRecord {
    /// The file, relative to the output folder, with `/` between folders.
    pub file: String,
    /// `image`, `depth`, `depth-calibration`, `measurements`, `contact`, `slice` or
    /// `slice-calibration`.
    pub kind: String,
    /// BLAKE3 of the file's bytes.
    pub blake3: String,
    /// The view's name (pictures).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view: Option<String>,
    /// `all`, `meshes` or `volumes` (pictures).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub content: Option<String>,
    /// The ordering (pictures).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ordering: Option<String>,
    /// Width and height (pictures).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size: Option<[u32; 2]>,
    /// The camera (pictures).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraRecord>,
    /// The slice's plane (slices and their calibration).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slice: Option<String>,
}

/// How a job ended.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum Status {
    /// Not reached (yet).
    Pending,
    /// Rendered now.
    Rendered,
    /// Its outputs were there, made from the same inputs: left alone.
    UpToDate,
    /// It failed; `error` says why.
    Failed,
}

/// Time spent on a job, in milliseconds.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct Timings {
    /// Reading the scene, volumes and meshes.
    pub load: f64,
    /// Hashing the inputs (and checking the outputs of an earlier run).
    pub hash: f64,
    /// Classifying the volumes (once for all the job's pictures).
    pub classify: f64,
    /// Drawing the pictures, classification excluded.
    pub render: f64,
    /// Annotating, encoding and writing the files.
    pub write: f64,
    /// The whole job.
    pub total: f64,
}

/// One job in the index.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct JobRecord {
    /// Position in the manifest, from 1.
    pub job: usize,
    /// The job's name.
    pub name: String,
    /// How it ended.
    pub status: Status,
    /// BLAKE3 of the job's settings and input hashes: equal hashes make equal outputs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hash: Option<String>,
    /// What it read.
    #[serde(default)]
    pub inputs: Vec<InputRecord>,
    /// What it wrote (for an up-to-date job, what an earlier run wrote and is still there).
    #[serde(default)]
    pub outputs: Vec<OutputRecord>,
    /// Time spent, in milliseconds (an up-to-date job's are the run's that rendered it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timings_ms: Option<Timings>,
    /// Why it failed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The contact of its first mesh with its volume, where the job asked for it (as
    /// `splatscene contact` prints it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contact: Option<serde_json::Value>,
}

/// How many jobs ended each way.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
pub struct Summary {
    /// Rendered by this run.
    pub rendered: usize,
    /// Left alone, already made.
    pub up_to_date: usize,
    /// Failed.
    pub failed: usize,
    /// Not reached.
    pub pending: usize,
}

/// An index file.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Index {
    /// The version of splatscene that wrote it.
    pub splatscene: String,
    /// The manifest.
    pub manifest: FileHash,
    /// Jobs in the manifest, all shards together.
    pub manifest_jobs: usize,
    /// `[K, N]` for shard K of N; absent for a whole batch or a merged index.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<[usize; 2]>,
    /// The number of shard indexes a merged index joins.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub merged_shards: Option<usize>,
    /// The device that drew (the GPU adapter, or none).
    pub device: String,
    /// `auto`, `gpu` or `cpu`.
    pub compositor: String,
    /// This index's jobs, in manifest order.
    pub jobs: Vec<JobRecord>,
    /// Counts of `jobs` by status.
    pub summary: Summary,
}

impl Index {
    /// Counts the jobs by status into `summary`.
    pub fn count(&mut self) {
        let mut s = Summary::default();
        for job in &self.jobs {
            match job.status {
                Status::Rendered => s.rendered += 1,
                Status::UpToDate => s.up_to_date += 1,
                Status::Failed => s.failed += 1,
                Status::Pending => s.pending += 1,
            }
        }
        self.summary = s;
    }

    /// Writes the index to `path` through a temporary file and a rename.
    pub fn write(&self, path: &Path) -> Result<()> {
        super::refuse_link(path)?;
        let text = serde_json::to_string_pretty(self)?;
        splatscene::output::write_atomic(path, text.as_bytes())?;
        Ok(())
    }

    /// Reads an index file.
    pub fn read(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read", path.display()))?;
        serde_json::from_str(&text)
            .with_context(|| format!("{}: not a batch index", path.display()))
    }
}

/// Most shards a batch is split into: above any Slurm array (4,000,001 tasks at most), so
/// that a count read from a command line or a file name never sizes anything by itself.
pub const MAX_SHARDS: usize = 4_000_001;

/// The index file's name for shard `K` of `N`, or the whole batch's.
pub fn index_name(shard: Option<(usize, usize)>) -> String {
    match shard {
        Some((k, n)) => format!("index-{k}-of-{n}.json"),
        None => "index.json".into(),
    }
}

/// `K` and `N` of a shard index's file name.
fn shard_of_name(name: &str) -> Option<(usize, usize)> {
    let rest = name.strip_prefix("index-")?.strip_suffix(".json")?;
    let (k, n) = rest.split_once("-of-")?;
    Some((k.parse().ok()?, n.parse().ok()?))
}

/// The index files in `dir`: the whole batch's and every shard's.
fn index_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(files),
        Err(e) => return Err(e).with_context(|| format!("{}: cannot list", dir.display())),
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if is_index_name(&name) && entry.file_type().is_ok_and(|t| t.is_file()) {
            files.push(entry.path());
        }
    }
    files.sort();
    Ok(files)
}

/// The jobs earlier runs finished, by job hash, from every index in `dir`. An index that cannot
/// be read is said and passed over: its jobs are rendered again.
pub fn finished_jobs(dir: &Path) -> Result<HashMap<String, JobRecord>> {
    let mut jobs = HashMap::new();
    for file in index_files(dir)? {
        match Index::read(&file) {
            Ok(index) => {
                for job in index.jobs {
                    if matches!(job.status, Status::Rendered | Status::UpToDate)
                        && let Some(hash) = job.hash.clone()
                    {
                        jobs.insert(hash, job);
                    }
                }
            }
            Err(e) => eprintln!("warning: {e:#}; its jobs will be rendered again"),
        }
    }
    Ok(jobs)
}

/// Whether every output of `job` is in `dir` with the bytes it had when written.
pub fn outputs_intact(dir: &Path, job: &JobRecord) -> bool {
    !job.outputs.is_empty()
        && job.outputs.iter().all(|o| {
            std::fs::read(dir.join(&o.file))
                .is_ok_and(|bytes| blake3::hash(&bytes).to_hex().as_str() == o.blake3)
        })
}

/// Joins the shard indexes in `dir` into `dir/index.json`; returns the merged index.
pub fn merge(dir: &Path) -> Result<Index> {
    let mut shards: Vec<((usize, usize), PathBuf)> = Vec::new();
    for file in index_files(dir)? {
        let name = file.file_name().unwrap_or_default().to_string_lossy();
        if let Some(kn) = shard_of_name(&name) {
            shards.push((kn, file));
        }
    }
    if shards.is_empty() {
        bail!(
            "{}: no shard indexes (index-K-of-N.json) to merge",
            dir.display()
        );
    }
    let counts: std::collections::BTreeSet<usize> = shards.iter().map(|((_, n), _)| *n).collect();
    if counts.len() > 1 {
        let list: Vec<String> = counts.iter().map(|n| n.to_string()).collect();
        bail!(
            "{}: shard indexes of batches split {} ways; remove those of the runs to leave out",
            dir.display(),
            list.join(" and ")
        );
    }
    let n = *counts.iter().next().unwrap_or(&1);
    if let Some(((k, _), file)) = shards
        .iter()
        .find(|((k, n), _)| *n > MAX_SHARDS || k > n || *k == 0)
    {
        bail!(
            "{}: not the index of a shard K of N with K from 1 to N and N at most {MAX_SHARDS} (K = {k}, N = {n}); remove it",
            file.display()
        );
    }
    // The missing shards, found in the shards present (sorted, without repeats): the cost
    // follows the files in the folder, never N.
    shards.sort_by_key(|((k, _), _)| *k);
    if let Some(pair) = shards.windows(2).find(|p| p[0].0 == p[1].0) {
        bail!(
            "{} and {} are both the index of shard {} of {n}; remove the one of the run to leave out",
            pair[0].1.display(),
            pair[1].1.display(),
            pair[0].0.0
        );
    }
    let missing_count = n - shards.len();
    if missing_count > 0 {
        let mut named = Vec::new();
        let mut next = 1;
        for ((k, _), _) in shards
            .iter()
            .chain(std::iter::once(&((n + 1, n), PathBuf::new())))
        {
            while next < *k && named.len() < 3 {
                named.push(index_name(Some((next, n))));
                next += 1;
            }
            if named.len() == 3 {
                break;
            }
            next = k + 1;
        }
        let more = if missing_count > named.len() {
            format!(" and {} more", missing_count - named.len())
        } else {
            String::new()
        };
        bail!(
            "{}: missing {}{more} (has that shard run?)",
            dir.display(),
            named.join(", ")
        );
    }
    let mut merged: Option<Index> = None;
    for (_, file) in &shards {
        let index = Index::read(file)?;
        match &mut merged {
            None => merged = Some(index),
            Some(m) => {
                if m.manifest.blake3 != index.manifest.blake3 {
                    bail!(
                        "{} was made from another manifest ({}) than {} ({}); rerun that shard",
                        file.display(),
                        index.manifest.path,
                        index_name(m.shard.map(|[k, n]| (k, n))),
                        m.manifest.path
                    );
                }
                if m.device != index.device {
                    m.device = format!("{}; {}", m.device, index.device);
                }
                m.jobs.extend(index.jobs);
            }
        }
    }
    let mut merged = merged.context("no shard index")?;
    merged.jobs.sort_by_key(|j| j.job);
    for pair in merged.jobs.windows(2) {
        if pair[0].job == pair[1].job {
            bail!(
                "job {} ({}) is in two shard indexes",
                pair[0].job,
                pair[0].name
            );
        }
    }
    if merged.jobs.len() != merged.manifest_jobs {
        bail!(
            "the shard indexes hold {} jobs of the manifest's {}",
            merged.jobs.len(),
            merged.manifest_jobs
        );
    }
    merged.shard = None;
    merged.merged_shards = Some(n);
    merged.count();
    merged.write(&dir.join("index.json"))?;
    Ok(merged)
}
