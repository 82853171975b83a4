//! `splatscene batch`: every picture a manifest asks for, rendered by one process that loads
//! and classifies each job's volumes once and keeps one GPU context; resumable (a job whose
//! outputs are there and whose inputs hash as before is left alone), and shardable over a
//! cluster's array tasks, whose indexes `--merge` joins.

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use splatscene::annotate::Annotations;
use splatscene::render::{
    Compositor, DepthMode, FrameOptions, GpuContext, LevelOfDetail, RenderError, Renderer,
    encode_png,
};
use splatscene::scene::file::{LoadedScene, camera as scene_camera, named_view_camera};
use splatscene::scene::{NodeContent, NodeId, Scene};

use splatscene::pick::contact::{Classes, contact};
use splatscene::render::encode_png_with_text;

use super::slice::{Wanted, calibration_chunks, slice_figure, window as slice_window};
use splatscene::pick::measure::draw_scene_measurements;

use super::render::{depth_files, figure_image};
use index::{CameraRecord, FileHash, Index, InputRecord, JobRecord, OutputRecord, Status, Timings};
use manifest::{Content, PlannedJob, ViewKind};

pub mod index;
pub mod manifest;

/// `splatscene batch`.
#[derive(clap::Args)]
pub struct BatchArgs {
    /// The manifest (TOML): its jobs, each a scene or a volume with meshes, and the views,
    /// sizes, orderings and contents to draw them in.
    #[arg(required_unless_present = "merge")]
    manifest: Option<PathBuf>,
    /// The output folder: the pictures and the index (index.json, or index-K-of-N.json for a
    /// shard); by default a folder named after the manifest (planning-report for
    /// planning-report.toml) in the current folder.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run shard K of N: the K-th job and every N-th after it (K from 1 to N). Inside a Slurm
    /// array job, SLURM_ARRAY_TASK_ID and SLURM_ARRAY_TASK_COUNT give it when this is absent.
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
    /// Render every job, also those whose outputs are there from the same inputs.
    #[arg(long)]
    force: bool,
    /// Check the manifest and list what each job would write; render nothing.
    #[arg(long)]
    check: bool,
    /// Join the shard indexes in this output folder into its index.json.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["manifest", "out", "shard", "force", "check"])]
    merge: Option<PathBuf>,
    /// Who composites the splats: auto (the CPU tile compositor where the GPU adapter is
    /// itself a CPU, else the GPU's splat pass), gpu (the splat pass), cpu (the tile
    /// compositor on the CPU) or gpu-tiles (the tile compositor as GPU compute passes).
    #[arg(long, default_value = "auto")]
    compositor: Compositor,
    /// Level of detail: `on` draws each volume from the level of its pyramid whose voxels are
    /// about a pixel apart, each 16^3-voxel brick by its own distance;
    /// `volume` one level a volume, by where it comes nearest the eye; `off` from its own grid;
    /// `auto` as `render --lod auto`: as `on`, with a level of the pyramid made only where it
    /// saves more drawing than its making costs in the one picture (else a finer level or
    /// the own grid drawn there), grids coarser than the pixels still refined (a job's
    /// pictures are redrawn when this changes)
    #[arg(long, default_value = "auto")]
    lod: LevelOfDetail,
}

/// Runs `splatscene batch`.
pub fn run_batch(args: BatchArgs) -> Result<()> {
    if let Some(dir) = &args.merge {
        let index = index::merge(dir)?;
        let s = &index.summary;
        eprintln!(
            "merged {} shard indexes into {}: {} jobs rendered, {} up to date, {} failed, {} pending",
            index.merged_shards.unwrap_or(0),
            dir.join("index.json").display(),
            s.rendered,
            s.up_to_date,
            s.failed,
            s.pending
        );
        return finish(&index, &dir.join("index.json"));
    }
    let Some(manifest_path) = &args.manifest else {
        bail!("give a manifest, or --merge DIR");
    };
    let out = &match &args.out {
        Some(out) => out.clone(),
        None => {
            let stem = manifest_path
                .file_stem()
                .with_context(|| format!("{}: no file name", manifest_path.display()))?;
            let out = PathBuf::from(stem);
            if !args.check {
                eprintln!("writing into {}", out.display());
            }
            out
        }
    };
    let shard = shard_from(args.shard.as_deref(), &|k| std::env::var(k).ok())?;
    let manifest = manifest::read(manifest_path)?;
    let base = manifest_path.parent().unwrap_or(Path::new("."));
    let jobs = manifest::plan(&manifest, base).map_err(|problems| {
        let list: Vec<String> = problems.iter().map(|p| format!("  {p}")).collect();
        anyhow::anyhow!(
            "{}: {} problem{} found; nothing was rendered:\n{}",
            manifest_path.display(),
            problems.len(),
            if problems.len() == 1 { "" } else { "s" },
            list.join("\n")
        )
    })?;
    let total_jobs = jobs.len();
    let index_path = out.join(index::index_name(shard));
    refuse_named_inputs(&jobs, out, &index_path)?;
    let mine: Vec<PlannedJob> = match shard {
        Some((k, n)) => jobs
            .into_iter()
            .filter(|j| j.position % n == k - 1)
            .collect(),
        None => jobs,
    };
    if args.check {
        for job in &mine {
            eprintln!(
                "job {} ({}): {} pictures",
                job.position + 1,
                job.name,
                job.items.len()
            );
            for item in &job.items {
                let depth = item
                    .depth
                    .as_ref()
                    .map_or(String::new(), |d| format!(" and {}", d.display()));
                eprintln!("  {}{depth}", item.image.display());
            }
        }
        eprintln!(
            "{} of the manifest's {total_jobs} jobs{}; the manifest is sound",
            mine.len(),
            shard.map_or(String::new(), |(k, n)| format!(" (shard {k} of {n})"))
        );
        return Ok(());
    }
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create", out.display()))?;
    let _lock = lock(&index_path)?;
    let earlier = if args.force {
        Default::default()
    } else {
        index::finished_jobs(out)?
    };
    let manifest_bytes = splatscene::input::read_regular(manifest_path, 4 << 20)
        .with_context(|| format!("{}: cannot read", manifest_path.display()))?;
    let gpu = Gpu::new(args.compositor);
    if !gpu.cpu_alone {
        // The GPU compositor, or `auto` where a GPU may exist: every job needs the answer.
        gpu.get()?;
    }
    let mut index = Index {
        splatscene: env!("CARGO_PKG_VERSION").into(),
        manifest: FileHash {
            path: std::path::absolute(manifest_path)
                .unwrap_or_else(|_| manifest_path.clone())
                .display()
                .to_string(),
            blake3: blake3::hash(&manifest_bytes).to_hex().to_string(),
        },
        manifest_jobs: total_jobs,
        shard: shard.map(|(k, n)| [k, n]),
        merged_shards: None,
        device: gpu.describe(),
        compositor: compositor_name(args.compositor).into(),
        jobs: mine
            .iter()
            .map(|j| JobRecord {
                job: j.position + 1,
                name: j.name.clone(),
                status: Status::Pending,
                hash: None,
                inputs: Vec::new(),
                outputs: Vec::new(),
                timings_ms: None,
                error: None,
                contact: None,
            })
            .collect(),
        summary: Default::default(),
    };
    index.count();
    index.write(&index_path)?;

    let pictures: usize = mine.iter().map(|j| j.items.len()).sum();
    let bar = progress_bar(pictures as u64);
    let fresh_renderer = || {
        let mut renderer = Renderer::with_compositor(args.compositor);
        renderer.set_lod(args.lod);
        renderer
    };
    let mut renderer = fresh_renderer();
    let settings = Settings {
        out,
        compositor: args.compositor,
        level_of_detail: args.lod != LevelOfDetail::Off,
        levels_by_brick: matches!(args.lod, LevelOfDetail::Auto | LevelOfDetail::On),
        levels_for_one_frame: args.lod == LevelOfDetail::Auto,
        gpu: &gpu,
    };
    for (slot, job) in mine.iter().enumerate() {
        bar.set_message(job.name.clone());
        let started = Instant::now();
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            run_job(job, &settings, &earlier, &mut renderer, &bar)
        }));
        let record = match outcome {
            Ok(record) => record,
            Err(panic) => {
                // The renderer may be left half-way through a frame: start afresh.
                renderer = fresh_renderer();
                let text = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| (*s).to_owned()))
                    .unwrap_or_else(|| "unknown".into());
                failed(job, None, format!("internal error (panic): {text}"))
            }
        };
        let done = slot + 1;
        let line = match record.status {
            Status::Failed => format!(
                "job {} ({}) failed: {}",
                job.position + 1,
                job.name,
                record.error.as_deref().unwrap_or("")
            ),
            Status::UpToDate => format!(
                "job {} ({}): {} pictures up to date",
                job.position + 1,
                job.name,
                job.items.len()
            ),
            _ => format!(
                "job {} ({}): {} pictures in {:.1} s",
                job.position + 1,
                job.name,
                job.items.len(),
                started.elapsed().as_secs_f64()
            ),
        };
        // The index first: a job said to be done is done on disk.
        index.jobs[slot] = record;
        index.device = gpu.describe();
        index.count();
        index.write(&index_path)?;
        bar.suspend(|| eprintln!("[{done}/{}] {line}", mine.len()));
        // A failed job's remaining pictures still count toward the bar's end.
        let drawn = (bar.position() as usize).min(pictures);
        let expected: usize = mine[..=slot].iter().map(|j| j.items.len()).sum();
        bar.inc(expected.saturating_sub(drawn) as u64);
    }
    bar.finish_and_clear();
    let s = &index.summary;
    eprintln!(
        "{} jobs: {} rendered, {} up to date, {} failed; index {}",
        index.jobs.len(),
        s.rendered,
        s.up_to_date,
        s.failed,
        index_path.display()
    );
    finish(&index, &index_path)
}

/// Refuses, before anything is drawn, a batch whose outputs (the index included) would
/// replace one of its inputs: the manifest, a scene file, a file a job names, or a file in a
/// folder a job reads (a DICOM series). Files the inputs name in turn (a header's data file, a
/// glTF's buffers) are known once a job is loaded: each job checks its outputs against
/// everything read so far before it draws ([`run_job`]), and every write checks again.
fn refuse_named_inputs(jobs: &[PlannedJob], out: &Path, index_path: &Path) -> Result<()> {
    use splatscene::input::record_input;
    for job in jobs {
        if let Some(scene) = &job.scene_path {
            record_input(scene);
        }
        for path in job.file.named_paths(Path::new(".")) {
            match std::fs::read_dir(&path) {
                Ok(entries) => entries
                    .flatten()
                    .filter(|e| e.file_type().is_ok_and(|t| !t.is_dir()))
                    .for_each(|e| record_input(&e.path())),
                Err(_) => record_input(&path),
            }
        }
    }
    splatscene::output::check_not_input(index_path)?;
    for job in jobs {
        for file in job.outputs() {
            splatscene::output::check_not_input(&out.join(file)).with_context(|| {
                format!(
                    "job {} ({}); nothing was rendered",
                    job.position + 1,
                    job.name
                )
            })?;
        }
    }
    Ok(())
}

/// The exit status: an error when any job failed or was not reached.
fn finish(index: &Index, path: &Path) -> Result<()> {
    let s = &index.summary;
    if s.failed + s.pending > 0 {
        bail!(
            "{} of {} jobs failed{}; see {}",
            s.failed + s.pending,
            index.jobs.len(),
            if s.pending > 0 {
                format!(" or were not reached ({} pending)", s.pending)
            } else {
                String::new()
            },
            path.display()
        );
    }
    Ok(())
}

fn compositor_name(c: Compositor) -> &'static str {
    match c {
        Compositor::Auto => "auto",
        Compositor::Gpu => "gpu",
        Compositor::Cpu => "cpu",
        Compositor::GpuTiles => "gpu-tiles",
    }
}

/// The shard to run: `--shard K/N`, else a Slurm array task's (`env` reads the environment).
fn shard_from(
    arg: Option<&str>,
    env: &dyn Fn(&str) -> Option<String>,
) -> Result<Option<(usize, usize)>> {
    if let Some(text) = arg {
        let (k, n) = text
            .split_once('/')
            .and_then(|(k, n)| {
                Some((
                    k.trim().parse::<usize>().ok()?,
                    n.trim().parse::<usize>().ok()?,
                ))
            })
            .with_context(|| format!("--shard {text:?}: expected K/N, such as 2/4"))?;
        if n == 0 {
            bail!("--shard {text}: N, the number of shards, must be at least 1");
        }
        if n > index::MAX_SHARDS {
            bail!(
                "--shard {text}: at most {} shards (a Slurm array is at most 4,000,001 tasks, and every shard writes an index)",
                index::MAX_SHARDS
            );
        }
        if k == 0 || k > n {
            bail!("--shard {text}: K counts the shards from 1 to N (here 1 to {n})");
        }
        return Ok(Some((k, n)));
    }
    let (id, count) = match (env("SLURM_ARRAY_TASK_ID"), env("SLURM_ARRAY_TASK_COUNT")) {
        (Some(id), Some(count)) => (id, count),
        (None, None) => return Ok(None),
        (Some(id), None) => bail!(
            "SLURM_ARRAY_TASK_ID={id} is set but SLURM_ARRAY_TASK_COUNT is not, so this task's shard is unknown; give --shard K/N (or unset SLURM_ARRAY_TASK_ID to run the whole batch)"
        ),
        (None, Some(count)) => bail!(
            "SLURM_ARRAY_TASK_COUNT={count} is set but SLURM_ARRAY_TASK_ID is not, so this task's shard is unknown; give --shard K/N (or unset SLURM_ARRAY_TASK_COUNT to run the whole batch)"
        ),
    };
    let number = |name: &str, text: &str| {
        text.trim()
            .parse::<usize>()
            .with_context(|| format!("{name}={text:?} is not a number"))
    };
    let id = number("SLURM_ARRAY_TASK_ID", &id)?;
    let count = number("SLURM_ARRAY_TASK_COUNT", &count)?;
    let min = match env("SLURM_ARRAY_TASK_MIN") {
        Some(m) => number("SLURM_ARRAY_TASK_MIN", &m)?,
        None => 0,
    };
    if let Some(step) = env("SLURM_ARRAY_TASK_STEP")
        && number("SLURM_ARRAY_TASK_STEP", &step)? != 1
    {
        bail!(
            "SLURM_ARRAY_TASK_STEP={step}: the batch shards over an array of consecutive task ids (--array=1-N or 0-(N-1)); give --shard K/N for other arrays"
        );
    }
    if count == 0 || id < min || id - min >= count {
        bail!(
            "SLURM_ARRAY_TASK_ID={id} does not lie among SLURM_ARRAY_TASK_COUNT={count} tasks from SLURM_ARRAY_TASK_MIN={min}; give --shard K/N"
        );
    }
    if count > index::MAX_SHARDS {
        bail!(
            "SLURM_ARRAY_TASK_COUNT={count}: at most {} shards",
            index::MAX_SHARDS
        );
    }
    let shard = (id - min + 1, count);
    eprintln!("shard {} of {} (Slurm array task {id})", shard.0, shard.1);
    Ok(Some(shard))
}

/// Holds the lock on an index for this process's life, so that two processes never run the
/// same shard into one folder (a killed process's lock goes with it).
fn lock(index: &Path) -> Result<std::fs::File> {
    let name = index.file_name().unwrap_or_default().to_string_lossy();
    let path = index.with_file_name(format!(".{name}.lock"));
    use std::os::unix::fs::OpenOptionsExt;
    refuse_link(&path)?;
    // O_NOFOLLOW: a link at the lock's name is refused, not opened into another file.
    let file = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .custom_flags(libc::O_NOFOLLOW)
        .open(&path)
        .with_context(|| format!("{}: cannot create", path.display()))?;
    match file.try_lock() {
        Ok(()) => Ok(file),
        Err(std::fs::TryLockError::WouldBlock) => bail!(
            "another batch is writing {} (it holds {}); wait for it, or give this one another shard or folder",
            index.display(),
            path.display()
        ),
        Err(std::fs::TryLockError::Error(e)) => {
            Err(e).with_context(|| format!("{}: cannot lock", path.display()))
        }
    }
}

fn progress_bar(len: u64) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(
        Some(len),
        if std::io::stderr().is_terminal() {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        },
    );
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {pos}/{len} pictures [{wide_bar}] {rate}, {eta} left, {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .with_key(
            "rate",
            |state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = write!(w, "{:.1} pictures/s", state.per_sec());
            },
        )
        .progress_chars("=> "),
    );
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}

/// What every job shares.
struct Settings<'a> {
    out: &'a Path,
    compositor: Compositor,
    level_of_detail: bool,
    /// Each brick at its own level (`--lod on` and `auto`), not one level a volume
    /// (`--lod volume`).
    levels_by_brick: bool,
    /// Levels of the pyramid made only where they pay within the picture (`--lod auto`).
    levels_for_one_frame: bool,
    gpu: &'a Gpu,
}

/// The batch's GPU context, looked for once: before the first job where every job needs the
/// answer, else at the first job with meshes. A batch of volumes alone composited on the CPU
/// ([`Compositor::volumes_without_adapter`]) then never loads an adapter.
struct Gpu {
    /// The volumes are composited on the CPU whatever adapter is found.
    cpu_alone: bool,
    compositor: Compositor,
    ctx: std::cell::OnceCell<Option<GpuContext>>,
}

impl Gpu {
    fn new(compositor: Compositor) -> Self {
        Self {
            cpu_alone: compositor.volumes_without_adapter(),
            compositor,
            ctx: std::cell::OnceCell::new(),
        }
    }

    /// The context, looked for on the first call; none where no adapter is found and the
    /// compositor may do without one (said once on stderr).
    fn get(&self) -> Result<Option<&GpuContext>> {
        if let Some(ctx) = self.ctx.get() {
            return Ok(ctx.as_ref());
        }
        let ctx = match GpuContext::headless() {
            Ok(ctx) => Some(ctx),
            Err(e @ RenderError::NoAdapter(_)) if self.compositor != Compositor::Gpu => {
                eprintln!(
                    "{e}\njobs without meshes are composited on the CPU; jobs with meshes fail"
                );
                None
            }
            Err(e) => return Err(e.into()),
        };
        Ok(self.ctx.get_or_init(|| ctx).as_ref())
    }

    /// The context for drawing a scene with `meshes` or not: looked for where it has meshes
    /// or the volumes are not composited on the CPU alone; none for a scene of volumes alone
    /// composited on the CPU.
    fn for_scene(&self, meshes: bool) -> Result<Option<&GpuContext>> {
        if self.cpu_alone && !meshes {
            return Ok(None);
        }
        self.get()
    }

    /// The device for the index: the adapter, or what stood in for it.
    fn describe(&self) -> String {
        match self.ctx.get() {
            Some(Some(ctx)) => ctx.describe(),
            Some(None) => "no GPU adapter".into(),
            None => "none looked for (volumes on the CPU)".into(),
        }
    }
}

/// Whether `scene` draws meshes (its own, or overlays), which need a GPU adapter.
fn has_meshes(scene: &Scene) -> bool {
    scene.meshes().chain(scene.overlays()).next().is_some()
}

fn failed(job: &PlannedJob, partial: Option<JobRecord>, error: String) -> JobRecord {
    let mut record = partial.unwrap_or_else(|| JobRecord {
        job: job.position + 1,
        name: job.name.clone(),
        status: Status::Failed,
        hash: None,
        inputs: Vec::new(),
        outputs: Vec::new(),
        timings_ms: None,
        error: None,
        contact: None,
    });
    record.status = Status::Failed;
    record.error = Some(error);
    record
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Renders one job, or finds it up to date. On failure, the record as far as it got.
fn run_job(
    job: &PlannedJob,
    settings: &Settings,
    earlier: &std::collections::HashMap<String, JobRecord>,
    renderer: &mut Renderer,
    bar: &ProgressBar,
) -> JobRecord {
    let started = Instant::now();
    let mut record = JobRecord {
        job: job.position + 1,
        name: job.name.clone(),
        status: Status::Rendered,
        hash: None,
        inputs: Vec::new(),
        outputs: Vec::new(),
        timings_ms: None,
        error: None,
        contact: None,
    };
    let mut timings = Timings::default();
    let loaded = match job.file.load(&job.source, Path::new(".")) {
        Ok(loaded) => loaded,
        Err(e) => return failed(job, None, format!("{:#}", anyhow::Error::from(e))),
    };
    timings.load = ms(started.elapsed());
    // Everything the job read is known now: none of it may be written.
    for file in job.outputs() {
        if let Err(e) = splatscene::output::check_not_input(&settings.out.join(file)) {
            return failed(job, None, e.to_string());
        }
    }
    let hashing = Instant::now();
    let (inputs, hash) = match job_hash(job, &loaded, settings) {
        Ok(h) => h,
        Err(e) => return failed(job, None, format!("{e:#}")),
    };
    record.inputs = inputs;
    record.hash = Some(hash.clone());
    if let Some(done) = earlier.get(&hash)
        && index::outputs_intact(settings.out, done)
    {
        let mut kept = done.clone();
        kept.job = record.job;
        kept.name = record.name;
        kept.status = Status::UpToDate;
        kept.error = None;
        bar.inc(job.items.len() as u64);
        return kept;
    }
    timings.hash = ms(hashing.elapsed());
    let result = render_job(
        job,
        settings,
        &loaded,
        renderer,
        bar,
        &mut record,
        &mut timings,
    );
    timings.total = ms(started.elapsed());
    record.timings_ms = Some(timings);
    match result {
        Ok(()) => record,
        Err(e) => failed(job, Some(record), format!("{e:#}")),
    }
}

fn render_job(
    job: &PlannedJob,
    settings: &Settings,
    loaded: &LoadedScene,
    renderer: &mut Renderer,
    bar: &ProgressBar,
    record: &mut JobRecord,
    timings: &mut Timings,
) -> Result<()> {
    let full = &loaded.scene;
    if has_meshes(full) && settings.gpu.for_scene(true)?.is_none() {
        bail!("the job has meshes, which need a GPU adapter, and there is none");
    }
    let parts = match &job.annotate {
        Some(p) => Some(Annotations::parse_parts(p).map_err(anyhow::Error::msg)?),
        None => None,
    };
    let base = full.camera.context("the scene has no camera")?;
    let mut scenes: Vec<(Content, Scene)> = Vec::new();
    let mut labels = Vec::new();
    // A JSON file the job writes beside its pictures, and its record.
    let mut write_json = |file: &Path, kind: &str, json: String| -> Result<()> {
        write_output(settings.out, file, json.as_bytes())?;
        record.outputs.push(OutputRecord {
            file: slashed(file),
            kind: kind.into(),
            blake3: blake3::hash(json.as_bytes()).to_hex().to_string(),
            view: None,
            content: None,
            ordering: None,
            size: None,
            camera: None,
            slice: None,
        });
        Ok(())
    };
    if let Some(file) = &job.measurements {
        write_json(file, "measurements", measurements_json(full)?)?;
    }
    let mut contact_report = None;
    if let Some(file) = &job.contact {
        let classes = full
            .volumes()
            .next()
            .map_or_else(Classes::none, |(_, v, _)| Classes::for_volume(&v.volume));
        let report = serde_json::to_value(contact(full, None, &classes)?)?;
        write_json(file, "contact", serde_json::to_string_pretty(&report)?)?;
        contact_report = Some(report);
    }
    record.contact = contact_report;
    if !job.slices.is_empty() {
        let window = slice_window(full, &job.file);
        for (spec, figure) in &job.slices {
            let wanted = Wanted {
                spec: *spec,
                mesh: None,
                mm_per_pixel: None,
            };
            let (image, calibration) =
                slice_figure(full, &wanted, base.target, window, parts.as_ref())
                    .with_context(|| format!("slice {spec}"))?;
            let png = encode_png_with_text(&image, &calibration_chunks(&calibration))?;
            let json = serde_json::to_string_pretty(&calibration)?;
            for (file, kind, bytes) in [
                (figure.clone(), "slice", png.as_slice()),
                (
                    figure.with_extension("json"),
                    "slice-calibration",
                    json.as_bytes(),
                ),
            ] {
                write_output(settings.out, &file, bytes)?;
                record.outputs.push(OutputRecord {
                    file: slashed(&file),
                    kind: kind.into(),
                    blake3: blake3::hash(bytes).to_hex().to_string(),
                    view: None,
                    content: None,
                    ordering: None,
                    size: (kind == "slice").then_some([image.width(), image.height()]),
                    camera: None,
                    slice: Some(spec.to_string()),
                });
            }
        }
    }
    for item in &job.items {
        let scene = match scenes.iter().find(|(c, _)| *c == item.content) {
            Some((_, s)) => s,
            None => {
                let mut scene = content_scene(full, item.content)?;
                labels = draw_scene_measurements(&mut scene).map_err(anyhow::Error::msg)?;
                scenes.push((item.content, scene));
                &scenes.last().context("a scene was just added")?.1
            }
        };
        let view = &job.views[item.view];
        let aspect = f64::from(item.size.0) / f64::from(item.size.1);
        // Named and fitted views fit what this picture draws (a picture of the meshes alone
        // fits the meshes, not the volume left out); the scene's own camera is the same for
        // every content.
        let camera = match &view.kind {
            ViewKind::Scene => base,
            ViewKind::Named(v) => {
                let mut c = named_view_camera(scene, v, base.projection, aspect);
                c.near = base.near;
                c
            }
            ViewKind::Camera(spec) => {
                scene_camera(Some(spec), scene, aspect).map_err(anyhow::Error::msg)?
            }
        };
        let options = FrameOptions {
            ordering: Some(item.ordering),
            background: if job.transparent {
                None
            } else {
                loaded.background
            },
            measure: true,
            preview: 0,
            volume_divisor: 1,
        };
        let drawing = Instant::now();
        // A picture's scene may hold meshes its job's scene did not (the markers of its
        // measurements), or leave the job's meshes out.
        let shot = match settings.gpu.for_scene(has_meshes(scene))? {
            Some(ctx) => renderer.screenshot(ctx, scene, &camera, item.size, &options)?,
            None => renderer.screenshot_without_gpu(scene, &camera, item.size, &options)?,
        };
        let classify = ms(shot.report.timings.classify);
        timings.classify += classify;
        timings.render += ms(drawing.elapsed()) - classify;
        let writing = Instant::now();
        // As `render` draws them: measurement values unless the parts leave them out.
        let mut item_parts = parts.clone();
        let item_labels = match &item_parts {
            Some(p) if !p.measurements => &[][..],
            _ => &labels[..],
        };
        if item_parts.is_none() && !item_labels.is_empty() {
            item_parts =
                Some(Annotations::parse_parts("measurements").map_err(anyhow::Error::msg)?);
        }
        if let Some(caption) = &item.caption {
            let p = item_parts
                .get_or_insert_with(|| Annotations::parse_parts("none").unwrap_or_default());
            p.caption = Some(caption.clone());
        }
        let (image, _) = figure_image(&shot, full, &camera, item_parts.as_ref(), item_labels)?;
        let describe = |file: &Path, kind: &str, bytes: &[u8]| OutputRecord {
            file: slashed(file),
            kind: kind.into(),
            blake3: blake3::hash(bytes).to_hex().to_string(),
            view: Some(view.name.clone()),
            content: Some(item.content.name().into()),
            ordering: Some(item.ordering.name().into()),
            size: Some([item.size.0, item.size.1]),
            camera: Some(CameraRecord::of(&camera)),
            slice: None,
        };
        let png = encode_png(&image)?;
        write_output(settings.out, &item.image, &png)?;
        record.outputs.push(describe(&item.image, "image", &png));
        if let Some(depth) = &item.depth {
            let mode = match job.depth_mode.as_deref() {
                Some("surface") => DepthMode::Surface,
                Some(_) => DepthMode::Mesh,
                None if scene.meshes().next().is_some() => DepthMode::Mesh,
                None => DepthMode::Surface,
            };
            let (png, calibration) = depth_files(&shot, scene, mode, job.surface_opacity)?;
            let json = serde_json::to_string_pretty(&calibration)?;
            let sidecar = depth.with_extension("json");
            write_output(settings.out, depth, &png)?;
            write_output(settings.out, &sidecar, json.as_bytes())?;
            record.outputs.push(describe(depth, "depth", &png));
            record
                .outputs
                .push(describe(&sidecar, "depth-calibration", json.as_bytes()));
        }
        timings.write += ms(writing.elapsed());
        bar.inc(1);
    }
    Ok(())
}

/// A relative path with `/` between its folders, as the index writes it.
fn slashed(file: &Path) -> String {
    file.components()
        .map(|c| c.as_os_str().to_string_lossy())
        .collect::<Vec<_>>()
        .join("/")
}

/// The scene's measurements as JSON: each with its label, kind, world points and value.
fn measurements_json(scene: &Scene) -> Result<String> {
    let mut list = Vec::new();
    for (i, m) in scene.measurements.iter().enumerate() {
        let value = scene
            .measure(m)
            .map_err(|e| anyhow::anyhow!("measurement {}: {e}", i + 1))?;
        let mut entry = serde_json::to_value(&value)?;
        if let Some(object) = entry.as_object_mut() {
            object.insert("label".into(), m.label.clone().into());
            let name = |id: Option<NodeId>| {
                id.and_then(|id| scene.node(id).ok())
                    .map(|n| n.name.clone())
            };
            object.insert("node".into(), name(m.node).into());
            if !m.anchors.is_empty() {
                let nodes: Vec<Option<String>> = m.anchors.iter().map(|a| name(*a)).collect();
                object.insert("nodes".into(), nodes.into());
            }
        }
        list.push(entry);
    }
    Ok(serde_json::to_string_pretty(&serde_json::json!({
        "frame": "RAS",
        "units": "points in millimetres; angles in degrees",
        "measurements": list,
    }))?)
}

/// Writes one output file inside the output folder, making its folders. A symbolic link met
/// inside the folder (at the file or at a folder on its way) is refused, never followed: the
/// batch writes plain files inside its own folder only.
fn write_output(out: &Path, file: &Path, bytes: &[u8]) -> Result<()> {
    let mut path = out.to_path_buf();
    for component in file.components() {
        path.push(component);
        refuse_link(&path)?;
    }
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("{}: cannot create", parent.display()))?;
    }
    splatscene::output::write_atomic(&path, bytes)?;
    Ok(())
}

/// Refuses `path` when it is a symbolic link: a batch's files inside its output folder are
/// never written through one into another folder.
pub(crate) fn refuse_link(path: &Path) -> Result<()> {
    if let Ok(meta) = std::fs::symlink_metadata(path)
        && meta.file_type().is_symlink()
    {
        let target = std::fs::read_link(path).unwrap_or_default();
        bail!(
            "{} is a symbolic link (to {}); the batch writes plain files inside its output folder and never through a link: remove the link",
            path.display(),
            target.display()
        );
    }
    Ok(())
}

/// The scene with the volumes (for `meshes`) or the meshes (for `volumes`) emptied out; node
/// ids stay as they are, so the renderer keeps what it made for the nodes that remain.
fn content_scene(full: &Scene, content: Content) -> Result<Scene> {
    let mut scene = full.clone();
    let drop: Vec<NodeId> = match content {
        Content::All => return Ok(scene),
        Content::Meshes => full.volumes().map(|(id, _, _)| id).collect(),
        Content::Volumes => full.meshes().map(|(id, _, _)| id).collect(),
    };
    for id in drop {
        scene.set_content(id, NodeContent::Empty)?;
    }
    Ok(scene)
}

/// The job's inputs with their content hashes, and the job hash: BLAKE3 over the version, the
/// compositor, the job's settings (paths as the manifest writes them) and the input hashes.
fn job_hash(
    job: &PlannedJob,
    loaded: &LoadedScene,
    settings: &Settings<'_>,
) -> Result<(Vec<InputRecord>, String)> {
    let scene = &loaded.scene;
    let mut inputs = Vec::new();
    if let Some(path) = &job.scene_path {
        let bytes =
            std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
        inputs.push(InputRecord {
            kind: "scene".into(),
            path: path.display().to_string(),
            blake3: blake3::hash(&bytes).to_hex().to_string(),
        });
    }
    // Volumes are the first root nodes, in file order; each mesh file is the root after them.
    let roots: Vec<NodeId> = (0..scene.nodes().len())
        .map(NodeId)
        .filter(|id| scene.nodes()[id.0].parent().is_none())
        .collect();
    let volume_ids: Vec<NodeId> = scene.volumes().map(|(id, _, _)| id).collect();
    for (spec, id) in job.file.volumes.iter().zip(&volume_ids) {
        let NodeContent::Volume(node) = &scene.nodes()[id.0].content else {
            continue;
        };
        let v = &node.volume;
        let mut h = blake3::Hasher::new();
        for d in v.dims {
            h.update(&d.to_le_bytes());
        }
        for x in v
            .spacing
            .iter()
            .chain(&v.origin)
            .chain(&v.direction.to_cols_array())
        {
            h.update(&x.to_le_bytes());
        }
        // The values as f32 whatever type holds them, so that a volume's hash does not
        // depend on how it is held.
        let mut run = vec![0.0f32; v.values.len().min(1 << 20)];
        for start in (0..v.values.len()).step_by(1 << 20) {
            let n = run.len().min(v.values.len() - start);
            v.values.read(start, &mut run[..n]);
            h.update(bytemuck::cast_slice(&run[..n]));
        }
        inputs.push(InputRecord {
            kind: "volume".into(),
            path: spec.path.clone(),
            blake3: h.finalize().to_hex().to_string(),
        });
    }
    for (spec, root) in job
        .file
        .meshes
        .iter()
        .zip(roots.iter().skip(job.file.volumes.len()))
    {
        let mut h = blake3::Hasher::new();
        for &child in scene.nodes()[root.0].children() {
            let node = &scene.nodes()[child.0];
            if let NodeContent::Mesh(m) = &node.content {
                h.update(bytemuck::cast_slice(&m.mesh.positions));
                h.update(bytemuck::cast_slice(&m.mesh.normals));
                h.update(bytemuck::cast_slice(&m.mesh.indices));
                h.update(bytemuck::cast_slice(&m.material.base_color));
                h.update(&m.material.roughness.to_le_bytes());
                h.update(&m.material.metallic.to_le_bytes());
                for x in node.local().to_cols_array() {
                    h.update(&x.to_le_bytes());
                }
            }
        }
        inputs.push(InputRecord {
            kind: "mesh".into(),
            path: spec.path.clone(),
            blake3: h.finalize().to_hex().to_string(),
        });
    }
    // The scene as loaded, paths left out: the content hashes stand for the files.
    let mut file = job.file.clone();
    for v in &mut file.volumes {
        v.path.clear();
    }
    for m in &mut file.meshes {
        m.path.clear();
    }
    let settings = serde_json::json!({
        "splatscene": env!("CARGO_PKG_VERSION"),
        "compositor": compositor_name(settings.compositor),
        "level_of_detail": settings.level_of_detail,
        "levels_by_brick": settings.levels_by_brick,
        "levels_for_one_frame": settings.levels_for_one_frame,
        "job": job.spec,
        "scene": file,
        "inputs": inputs.iter().map(|i| &i.blake3).collect::<Vec<_>>(),
    });
    let hash = blake3::hash(serde_json::to_string(&settings)?.as_bytes());
    Ok((inputs, hash.to_hex().to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env_of(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let pairs: Vec<(String, String)> = pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        move |k| pairs.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone())
    }

    #[test]
    fn shards_are_checked() {
        let none = env_of(&[]);
        assert_eq!(shard_from(Some("2/4"), &none).unwrap(), Some((2, 4)));
        assert_eq!(shard_from(Some("1/1"), &none).unwrap(), Some((1, 1)));
        for bad in [
            "3/2",
            "0/0",
            "0/2",
            "2",
            "a/b",
            "1/0",
            "-1/2",
            "1/18446744073709551615",
            "1/4000002",
        ] {
            let e = shard_from(Some(bad), &none).unwrap_err().to_string();
            assert!(e.contains("--shard"), "{bad}: {e}");
        }
        assert_eq!(shard_from(None, &none).unwrap(), None);
    }

    #[test]
    fn slurm_array_tasks_give_the_shard() {
        // --array=0-3 and --array=1-4 both make shards 1 to 4.
        let zero = env_of(&[
            ("SLURM_ARRAY_TASK_ID", "0"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_STEP", "1"),
        ]);
        assert_eq!(shard_from(None, &zero).unwrap(), Some((1, 4)));
        let one = env_of(&[
            ("SLURM_ARRAY_TASK_ID", "4"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
        ]);
        assert_eq!(shard_from(None, &one).unwrap(), Some((4, 4)));
        // --shard wins over the environment.
        assert_eq!(shard_from(Some("2/3"), &one).unwrap(), Some((2, 3)));
        let stepped = env_of(&[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "2"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
        ]);
        assert!(shard_from(None, &stepped).is_err());
        let outside = env_of(&[
            ("SLURM_ARRAY_TASK_ID", "7"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
        ]);
        assert!(shard_from(None, &outside).is_err());
        // One of the pair without the other is refused, not a run of the whole batch.
        for pair in [
            &[("SLURM_ARRAY_TASK_ID", "3")][..],
            &[("SLURM_ARRAY_TASK_COUNT", "4")][..],
        ] {
            let e = shard_from(None, &env_of(pair)).unwrap_err().to_string();
            assert!(e.contains("--shard K/N"), "{e}");
        }
        let huge = env_of(&[
            ("SLURM_ARRAY_TASK_ID", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "18446744073709551615"),
        ]);
        assert!(shard_from(None, &huge).is_err());
    }
}
