//! The batch on a real Slurm: a single-node cluster started from Debian's `slurm-wlm` and
//! `munge` inside a scratch folder (`examples/slurm/local-cluster.sh`, no system service
//! touched), the example array job submitted over a manifest of several cases and views, its
//! shard indexes merged by the job `submit.sh` queues after it, and the result compared with the
//! same manifest run unsharded in one process: the same files, the same pixels. Then an array
//! task is killed part-way through its shard and the array resubmitted: it completes the batch
//! without redoing a finished job.
//!
//! Skipped with a message where the packages are missing or the test does not run as root
//! (slurmd runs jobs as their submitter and the local cluster as root); under CI (`CI` set)
//! missing packages fail it, since `.ci/run` installs them.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use serde_json::Value;

mod common;
use common::pictures::pictures;
use common::{have, ok, repo, scratch};

fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

/// A running local cluster, stopped when dropped (also when the test fails).
struct Cluster {
    dir: PathBuf,
    conf: PathBuf,
}

impl Cluster {
    fn start(dir: &Path) -> Self {
        let out = Command::new(repo("examples/slurm/local-cluster.sh"))
            .arg("start")
            .arg(dir)
            .output()
            .expect("run local-cluster.sh");
        let cluster = Self {
            dir: dir.to_path_buf(),
            conf: dir.join("slurm.conf"),
        };
        assert!(
            out.status.success(),
            "the local cluster did not start: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        cluster
    }

    /// A Slurm client command against this cluster, run from `cwd`, with the environment the
    /// array job needs: the binary and the shared data.
    fn command(&self, program: &str, cwd: &Path) -> Command {
        let mut c = Command::new(program);
        c.current_dir(cwd)
            .env("SLURM_CONF", &self.conf)
            .env("SPLATSCENE", env!("CARGO_BIN_EXE_splatscene"))
            .env("NODEVICE_SELECT", "1");
        c
    }

    fn run(&self, program: &str, args: &[&str], cwd: &Path) -> String {
        let out: Output = self
            .command(program, cwd)
            .args(args)
            .output()
            .unwrap_or_else(|e| panic!("{program}: {e}"));
        assert!(
            out.status.success(),
            "{program} {}: {}{}",
            args.join(" "),
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// Waits until none of `jobs` is queued or running.
    fn wait_for(&self, jobs: &[&str], cwd: &Path) {
        let started = Instant::now();
        loop {
            let queue = self.run("squeue", &["--noheader", "--format=%i %T"], cwd);
            let left: Vec<&str> = queue
                .lines()
                .filter(|l| {
                    jobs.iter()
                        .any(|j| l.starts_with(&format!("{j}_")) || l.starts_with(&format!("{j} ")))
                })
                .collect();
            if left.is_empty() {
                return;
            }
            assert!(
                started.elapsed() < Duration::from_secs(300),
                "jobs still queued after 300 s: {left:?}"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new(repo("examples/slurm/local-cluster.sh"))
            .arg("stop")
            .arg(&self.dir)
            .status();
    }
}

fn index(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

fn statuses(index: &Value) -> Vec<String> {
    index["jobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|j| {
            format!(
                "{} {}",
                j["name"].as_str().unwrap(),
                j["status"].as_str().unwrap()
            )
        })
        .collect()
}

/// Six cases over three shards: shard 2 holds a quick case (the 2nd) and a slow one (the
/// 5th, many pictures), so that its task can be killed between them.
fn manifest(dir: &Path) -> PathBuf {
    let n = 20i32;
    let mut ball = Vec::new();
    for z in 0..n {
        for y in 0..n {
            for x in 0..n {
                let d2 = (x - 10).pow(2) + (y - 9).pow(2) + (z - 11).pow(2);
                ball.push(if d2 < 40 { 220 } else { 5 });
            }
        }
    }
    std::fs::write(dir.join("ball.raw"), ball).unwrap();
    let scene = repo("examples/scenes/shoulder.toml");
    let ball = r#"volume = { path = "ball.raw", dims = [20, 20, 20], scalar = "u8" }"#;
    let text = format!(
        r#"
[defaults]
views = ["anterior", "right"]
sizes = [[96, 72]]

[[job]]
name = "shoulder"
scene = "{scene}"
contents = ["all", "meshes"]

[[job]]
name = "ball-quick"
{ball}

[[job]]
name = "ball-superior"
{ball}
views = ["superior"]

[[job]]
name = "shoulder-posterior"
scene = "{scene}"
views = ["posterior"]

[[job]]
name = "shoulder-slow"
scene = "{scene}"
views = ["anterior", "posterior", "left", "right", "superior", "inferior"]
sizes = [[640, 480], [800, 600]]
orderings = ["ip-pbtf", "btf", "pbtf"]

[[job]]
name = "ball-oblique"
{ball}
views = [{{ name = "oblique", view_from = [1, -1, -1] }}]
"#,
        scene = scene.display()
    );
    let path = dir.join("manifest.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn a_slurm_array_renders_what_one_process_renders_and_resumes_a_killed_task() {
    let tools = [
        "munged",
        "slurmctld",
        "slurmd",
        "sbatch",
        "squeue",
        "scancel",
    ];
    if let Some(missing) = tools.iter().find(|t| !have(t)) {
        assert!(
            std::env::var_os("CI").is_none(),
            "{missing} is missing: .ci/run installs slurm-wlm and munge"
        );
        eprintln!("skipped: {missing} not found (apt-get install slurm-wlm munge)");
        return;
    }
    if !is_root() {
        eprintln!("skipped: the local Slurm cluster runs as root");
        return;
    }
    let dir = scratch("slurm");
    let manifest = manifest(&dir);
    let m = manifest.to_str().unwrap();

    // The reference: the manifest unsharded, in one process.
    let whole = dir.join("whole");
    ok(&["batch", m, "--out", whole.to_str().unwrap()]);

    let cluster = Cluster::start(&dir.join("cluster"));
    let sbatch_script = repo("examples/slurm/planning-report.sbatch");
    let script = sbatch_script.to_str().unwrap();

    // The array and its merge job, as a user submits them.
    let shards = dir.join("shards");
    let said = cluster.run(
        repo("examples/slurm/submit.sh").to_str().unwrap(),
        &[m, shards.to_str().unwrap(), "3"],
        &dir,
    );
    let ids: Vec<&str> = said
        .split_whitespace()
        .filter(|w| w.chars().all(|c| c.is_ascii_digit()))
        .collect();
    assert_eq!(ids.len(), 2, "submit.sh said {said:?}");
    let (array, merge) = (ids[0], ids[1]);
    cluster.wait_for(&[array, merge], &dir);
    let merged = index(&shards.join("index.json"));
    assert_eq!(merged["merged_shards"], 3);
    assert_eq!(
        statuses(&merged),
        statuses(&index(&whole.join("index.json")))
    );
    assert_eq!(
        pictures(&shards),
        pictures(&whole),
        "the same files and pixels"
    );
    for k in 1..=3 {
        let shard = index(&shards.join(format!("index-{k}-of-3.json")));
        assert_eq!(shard["shard"], serde_json::json!([k, 3]));
    }

    // Kill shard 2 once it has finished its first case, while it draws its second.
    let killed = dir.join("killed");
    let k = killed.to_str().unwrap();
    let array = cluster.run("sbatch", &["--parsable", "--array=1-3", script, m, k], &dir);
    let array = array.trim().split(';').next().unwrap().to_owned();
    let shard2 = killed.join("index-2-of-3.json");
    let started = Instant::now();
    loop {
        if shard2.exists()
            && let Ok(text) = std::fs::read_to_string(&shard2)
            && let Ok(i) = serde_json::from_str::<Value>(&text)
            && i["jobs"][0]["status"] == "rendered"
        {
            break;
        }
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "shard 2 did not finish its first case"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    cluster.run("scancel", &[&format!("{array}_2")], &dir);
    cluster.wait_for(&[&array], &dir);
    let cut = index(&shard2);
    assert_eq!(
        statuses(&cut),
        ["ball-quick rendered", "shoulder-slow pending"],
        "shard 2 was killed between its cases"
    );
    let stderr = Command::new(env!("CARGO_BIN_EXE_splatscene"))
        .args(["batch", "--merge", k])
        .output()
        .unwrap();
    assert!(
        !stderr.status.success(),
        "an unfinished batch merges with a failing status"
    );

    // Resubmitted, the array finishes the batch and redoes nothing that was done.
    cluster.run(
        "sbatch",
        &["--parsable", "--wait", "--array=1-3", script, m, k],
        &dir,
    );
    ok(&["batch", "--merge", k]);
    assert_eq!(
        statuses(&index(&shard2)),
        ["ball-quick up-to-date", "shoulder-slow rendered"]
    );
    for other in ["index-1-of-3.json", "index-3-of-3.json"] {
        let i = index(&killed.join(other));
        assert!(
            statuses(&i).iter().all(|s| s.ends_with("up-to-date")),
            "{other}: {:?}",
            statuses(&i)
        );
    }
    assert_eq!(pictures(&killed), pictures(&whole));
    drop(cluster);
}
