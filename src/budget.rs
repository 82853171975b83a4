//! Sizes that a file or an argument controls, checked before anything is allocated: image
//! sizes, and volume sizes against the machine's memory.
//!
//! Every loader, the scene-file and batch-manifest readers, the command line and the CPU
//! compositor take their limits from here, so that a header claiming a huge grid or an
//! argument asking for a huge image is refused at once with a message that names the size,
//! instead of wrapping, aborting on an allocation, or swapping for minutes.
//!
//! The memory budget is what Linux says it can give without swapping (`MemAvailable`, or what
//! the process's control group allows where that is less), or the
//! number of bytes in `SPLATSCENE_MEMORY_LIMIT` (a plain count, or with a `K`, `M`, `G` or `T`
//! suffix, powers of 1024) where that is set. A volume is loaded only when drawing it fits:
//! its value as held (1, 2 or 4 bytes, see [`crate::volume::Voxels`]) and
//! [`DRAW_BYTES_PER_VOXEL`] more a voxel, so that a small compressed file declaring billions of
//! voxels is refused from its header rather than inflated first and refused later.

use std::fmt;
use std::path::{Component, Path, PathBuf};

use thiserror::Error;

/// The longest side of an image, in pixels (wgpu's texture limit on the adapters we use).
pub const MAX_SIDE: u32 = 16384;

/// The most pixels in one image (8192 x 8192: 1 GiB of f32 RGBA in the CPU compositors).
pub const MAX_PIXELS: u64 = 1 << 26;

/// Bytes a voxel costs from loading to drawing besides its value, before the significant ones
/// are known: the significance bitmap and its ranks, the clear-range labels of the slices
/// being classified, rounded up. What each significant voxel adds ([`SPLAT_BYTES`]) is checked
/// after classification against the memory left then ([`check_memory_left`]), so that a large
/// grid that is mostly empty is not refused, and the GPU
/// passes check their texels (8 bytes a splat) before building them. Measured peaks
/// of a whole `render` with the CPU tiles, in BENCHMARKS.md ("Values held as stored"): 2.96
/// bytes a voxel for the 8-bit LIDC2 CT resampled to 512 x 512 x 532 with 5.4M splats (1 for
/// the value, 1.2 for the splats at [`SPLAT_BYTES`] each).
pub const DRAW_BYTES_PER_VOXEL: u64 = 1;

/// Bytes a significant voxel costs once classified, on top of [`DRAW_BYTES_PER_VOXEL`]: its
/// colour (5, twice while the slabs' lists are joined), its texel for the CPU tiles (8, its
/// memory touched only where its brick is read), its place in the draw order (4), and an
/// eighth of that again for the coarser levels of detail; rounded up. Measured, the 0.75 mm
/// abdomen CT with a window of soft tissue (41.2M splats of 86.5M voxels, one view from
/// behind, 7M of them read) peaked at 13.5 bytes a splat over its 8-bit values (BENCHMARKS.md,
/// "Texels written as they are read"); a view that reads every texel holds about 6 more.
pub const SPLAT_BYTES: u64 = 30;

/// Bytes a splat of a level of detail costs: its colour (5), its texel (8, made as its brick
/// is first read) and its place in the draw order (4), rounded up. A level is made only where
/// the memory left holds a splat at this size for each splat of the level it is halved from
/// (a level has at most as many); the levels a turning view keeps between frames are what
/// the budget's estimate of one picture leaves out. Measured, the dense ball 512^3 turned 7
/// degrees a frame for 20 frames held 1.0-1.1 GB against 584 MB for one picture, with about
/// 27M splats in the levels it kept (BENCHMARKS.md, "Uneven levels kept by their splats").
pub const LEVEL_SPLAT_BYTES: u64 = 18;

/// The environment variable that sets the memory budget in bytes.
pub const MEMORY_LIMIT_VAR: &str = "SPLATSCENE_MEMORY_LIMIT";

/// A size refused before any allocation.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum SizeError {
    /// An image with no pixels on a side.
    #[error("a {width}x{height} image has no pixels")]
    EmptyImage {
        /// Width asked for.
        width: u64,
        /// Height asked for.
        height: u64,
    },
    /// An image past [`MAX_SIDE`] or [`MAX_PIXELS`].
    #[error(
        "a {width}x{height} image is too large: at most {MAX_SIDE} pixels a side and {MAX_PIXELS} pixels in all (8192x8192)"
    )]
    ImageTooLarge {
        /// Width asked for.
        width: u64,
        /// Height asked for.
        height: u64,
    },
    /// More memory than the budget.
    #[error(
        "{what} needs {} of memory and {} is available (set {MEMORY_LIMIT_VAR} to a byte count to allow more)",
        bytes_words(*needed),
        bytes_words(*budget)
    )]
    OverBudget {
        /// What needs it, in words.
        what: String,
        /// Bytes needed ([`u64::MAX`] where the product overflows).
        needed: u64,
        /// The budget.
        budget: u64,
    },
}

/// Bytes in words: `1.5 GiB`, `312.0 MiB`, `17 bytes`; [`u64::MAX`] is "more than 16 EiB".
pub fn bytes_words(bytes: u64) -> String {
    if bytes == u64::MAX {
        return "more than 16 EiB".into();
    }
    let units = ["KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut value = bytes as f64;
    let mut unit = None;
    for u in units {
        if value < 1024.0 {
            break;
        }
        value /= 1024.0;
        unit = Some(u);
    }
    match unit {
        None => format!("{bytes} bytes"),
        Some(u) => format!("{value:.1} {u}"),
    }
}

/// Checks an image size against [`MAX_SIDE`] and [`MAX_PIXELS`]; returns its pixel count.
pub fn check_image(width: u64, height: u64) -> Result<u64, SizeError> {
    if width == 0 || height == 0 {
        return Err(SizeError::EmptyImage { width, height });
    }
    if width > u64::from(MAX_SIDE) || height > u64::from(MAX_SIDE) || width * height > MAX_PIXELS {
        return Err(SizeError::ImageTooLarge { width, height });
    }
    Ok(width * height)
}

/// Memory Linux can give this process without swapping: `MemAvailable` in `/proc/meminfo`, or
/// less where the process's control groups allow less (their memory controllers): a Slurm job's
/// allocation or a container's limit, which `MemAvailable` does not see (a job given 8 GiB on a
/// 256 GiB node is killed at 8 GiB). `None` where neither says.
pub fn available_memory() -> Option<u64> {
    let system = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|info| {
            let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
            let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
            kib.checked_mul(1024)
        });
    let group = std::fs::read_to_string("/proc/self/cgroup")
        .ok()
        .and_then(|groups| cgroup_room(Path::new("/sys/fs/cgroup"), &groups));
    match (system, group) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// What the memory controllers of control groups allow a process still, its groups listed as
/// `/proc/self/cgroup` lists them (`groups`) and their files under `root` (`/sys/fs/cgroup`):
/// the least, over its group and every group above it that sets a limit (cgroup v2's
/// `memory.max`, v1's `memory.limit_in_bytes` under `memory/`), of that limit less what the
/// group uses (`memory.current`, `memory.usage_in_bytes`), its page cache (`file`,
/// `total_cache` in `memory.stat`) not counted as used, as `MemAvailable` counts the cache as
/// available: a batch that has read many files holds their pages in its group until memory
/// is wanted. `None` where
/// no group sets a limit or the files cannot be read. (Read here rather than through a crate:
/// three small files a level, and the crates that read them bring a process-wide model of
/// cgroups this one question does not need.)
fn cgroup_room(root: &Path, groups: &str) -> Option<u64> {
    let mut least: Option<u64> = None;
    for line in groups.lines() {
        let mut fields = line.splitn(3, ':');
        let (Some(_), Some(controllers), Some(path)) =
            (fields.next(), fields.next(), fields.next())
        else {
            continue;
        };
        let (dir, files) = if controllers.is_empty() {
            (root.to_path_buf(), V2_FILES)
        } else if controllers.split(',').any(|c| c == "memory") {
            (root.join("memory"), V1_FILES)
        } else {
            continue;
        };
        let mut group = PathBuf::from(path.trim_start_matches('/'));
        loop {
            if group
                .components()
                .any(|c| !matches!(c, Component::Normal(_)))
            {
                break;
            }
            if let Some(room) = group_room(&dir.join(&group), files) {
                least = Some(least.map_or(room, |l| l.min(room)));
            }
            if !group.pop() {
                break;
            }
        }
    }
    least
}

/// A memory controller's files: its limit, its use, and the name of its page cache in
/// `memory.stat`.
type GroupFiles = (&'static str, &'static str, &'static str);
const V2_FILES: GroupFiles = ("memory.max", "memory.current", "file");
const V1_FILES: GroupFiles = (
    "memory.limit_in_bytes",
    "memory.usage_in_bytes",
    "total_cache",
);

/// What group `dir` allows still; `None` where it sets no limit (v2's `max`) or says nothing.
fn group_room(dir: &Path, (limit, usage, cache): GroupFiles) -> Option<u64> {
    let read = |name: &str| std::fs::read_to_string(dir.join(name)).ok();
    let limit: u64 = read(limit)?.trim().parse().ok()?;
    let used: u64 = read(usage)?.trim().parse().ok()?;
    let cache: u64 = read("memory.stat")
        .and_then(|stat| {
            stat.lines().find_map(|l| {
                let (key, value) = l.split_once(' ')?;
                (key == cache).then(|| value.trim().parse().ok())?
            })
        })
        .unwrap_or(0);
    Some(limit.saturating_sub(used.saturating_sub(cache)))
}

/// The memory budget: [`MEMORY_LIMIT_VAR`] where set and valid, else the available memory,
/// else 8 GiB where the system does not say.
pub fn memory_budget() -> u64 {
    std::env::var(MEMORY_LIMIT_VAR)
        .ok()
        .and_then(|v| parse_bytes(&v))
        .or_else(available_memory)
        .unwrap_or(8 << 30)
}

/// What this process may still take: with [`MEMORY_LIMIT_VAR`] set, that limit less what the
/// process holds now (its resident set, `VmRSS`); else the available memory, which already
/// counts what the process holds; else [`memory_budget`]. Asked before memory that a frame
/// can do without is taken (a level of detail, which a finer level stands in for).
pub fn headroom() -> u64 {
    match std::env::var(MEMORY_LIMIT_VAR)
        .ok()
        .and_then(|v| parse_bytes(&v))
    {
        Some(limit) => limit.saturating_sub(resident_bytes().unwrap_or(0)),
        None => available_memory().unwrap_or_else(memory_budget),
    }
}

/// This process's resident set, from `/proc/self/status` (`None` where there is none).
fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    kib.checked_mul(1024)
}

/// A byte count as [`MEMORY_LIMIT_VAR`] takes it: digits with an optional `K`, `M`, `G` or `T`
/// (powers of 1024, an optional `iB` or `B` after it).
pub fn parse_bytes(text: &str) -> Option<u64> {
    let t = text.trim();
    let t = t
        .strip_suffix("iB")
        .or_else(|| t.strip_suffix('B'))
        .unwrap_or(t);
    let (digits, shift) = match t.char_indices().last()? {
        (i, 'K' | 'k') => (&t[..i], 10),
        (i, 'M' | 'm') => (&t[..i], 20),
        (i, 'G' | 'g') => (&t[..i], 30),
        (i, 'T' | 't') => (&t[..i], 40),
        _ => (t, 0),
    };
    let n: u64 = digits.trim().parse().ok()?;
    n.checked_mul(1u64 << shift)
}

/// Checks that `count` items of `each` bytes fit the memory budget; `what` names them in the
/// error ("the volume file.nii.gz's 4294967296 voxels").
pub fn check_memory(what: impl fmt::Display, count: u64, each: u64) -> Result<u64, SizeError> {
    check_within(what, count.saturating_mul(each), memory_budget())
}

/// Checks that `count` items of `each` bytes fit the memory left to the process
/// ([`headroom`]): what the volume's loading check did not count, asked once the process
/// holds the volume. With [`MEMORY_LIMIT_VAR`] set, what the process holds counts against
/// the limit, so that the limit bounds the whole drawing and not each part of it alone.
pub fn check_memory_left(what: impl fmt::Display, count: u64, each: u64) -> Result<u64, SizeError> {
    check_within(what, count.saturating_mul(each), headroom())
}

/// `needed` bytes against `budget` bytes: the bytes, or the error naming both.
fn check_within(what: impl fmt::Display, needed: u64, budget: u64) -> Result<u64, SizeError> {
    if needed > budget {
        return Err(SizeError::OverBudget {
            what: what.to_string(),
            needed,
            budget,
        });
    }
    Ok(needed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn images_are_bounded_on_each_side_and_in_all() {
        assert_eq!(check_image(8192, 8192), Ok(1 << 26));
        assert_eq!(check_image(16384, 4096), Ok(1 << 26));
        assert!(matches!(
            check_image(16385, 1),
            Err(SizeError::ImageTooLarge { .. })
        ));
        assert!(matches!(
            check_image(8192, 8193),
            Err(SizeError::ImageTooLarge { .. })
        ));
        assert!(matches!(
            check_image(0, 5),
            Err(SizeError::EmptyImage { .. })
        ));
        // No overflow on absurd sizes.
        assert!(check_image(u64::MAX, u64::MAX).is_err());
    }

    #[test]
    fn byte_counts_read_and_written() {
        assert_eq!(parse_bytes("1024"), Some(1024));
        assert_eq!(parse_bytes("2G"), Some(2 << 30));
        assert_eq!(parse_bytes("3 MiB"), Some(3 << 20));
        assert_eq!(parse_bytes("5KB"), Some(5 << 10));
        assert_eq!(parse_bytes("lots"), None);
        assert_eq!(parse_bytes("99999999999T"), None);
        assert_eq!(bytes_words(17), "17 bytes");
        assert_eq!(bytes_words(3 << 29), "1.5 GiB");
        assert_eq!(bytes_words(u64::MAX), "more than 16 EiB");
    }

    #[test]
    fn memory_past_the_budget_is_refused_with_both_figures() {
        let err = check_memory("the test's voxels", u64::MAX / 2, 4).unwrap_err();
        let text = err.to_string();
        assert!(text.contains("the test's voxels"), "{text}");
        assert!(text.contains(MEMORY_LIMIT_VAR), "{text}");
        assert!(check_memory("a few voxels", 10, 4).is_ok());
    }

    /// Writes `files` (path under `root`, text) for [`cgroup_room`] to read.
    fn groups_of(files: &[(&str, &str)]) -> tempfile::TempDir {
        let root = tempfile::tempdir().unwrap();
        for (path, text) in files {
            let path = root.path().join(path);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, text).unwrap();
        }
        root
    }

    #[test]
    fn a_control_groups_limit_above_the_process_bounds_its_memory() {
        // cgroup v2, as Slurm sets a job's memory: the limit on the job, none on its step;
        // the job's page cache not counted as used.
        let root = groups_of(&[
            ("job_7/memory.max", "8000\n"),
            ("job_7/memory.current", "3000\n"),
            (
                "job_7/memory.stat",
                "anon 2400\nfile 500\nactive_file 100\n",
            ),
            ("job_7/step_0/memory.max", "max\n"),
            ("job_7/step_0/memory.current", "2000\n"),
        ]);
        assert_eq!(cgroup_room(root.path(), "0::/job_7/step_0\n"), Some(5500));
        // A tighter limit lower down wins.
        std::fs::write(root.path().join("job_7/step_0/memory.max"), "4000").unwrap();
        assert_eq!(cgroup_room(root.path(), "0::/job_7/step_0\n"), Some(2000));
        // Used past the limit: nothing left, not an underflow.
        std::fs::write(root.path().join("job_7/step_0/memory.max"), "1000").unwrap();
        assert_eq!(cgroup_room(root.path(), "0::/job_7/step_0\n"), Some(0));
        // No limit anywhere.
        let open = groups_of(&[("a/memory.max", "max"), ("a/memory.current", "10")]);
        assert_eq!(cgroup_room(open.path(), "0::/a\n"), None);
    }

    #[test]
    fn a_v1_memory_controller_is_read_beside_the_others() {
        let root = groups_of(&[
            ("memory/slurm/uid_0/memory.limit_in_bytes", "4000"),
            ("memory/slurm/uid_0/memory.usage_in_bytes", "1000"),
            (
                "memory/slurm/uid_0/memory.stat",
                "cache 300\ntotal_cache 100\n",
            ),
            ("memory/memory.limit_in_bytes", "9223372036854771712"),
            ("memory/memory.usage_in_bytes", "50000"),
        ]);
        let groups = "9:name=systemd:/\n4:memory:/slurm/uid_0\n1:cpu,cpuacct:/x\n0::/\n";
        assert_eq!(cgroup_room(root.path(), groups), Some(3100));
        // Lines that mean nothing, or climb out of the root, are passed over.
        let odd = "garbage\n4:memory:/../../etc\n::\n4:memory\n";
        assert_eq!(cgroup_room(root.path(), odd), None);
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn the_resident_set_counts_memory_just_touched() {
        // Other tests run beside this one and free what they held: only what this one holds
        // while it reads is sure to be counted.
        let touched = vec![1u8; 64 << 20];
        let resident = resident_bytes().unwrap();
        assert!(
            std::hint::black_box(&touched)
                .iter()
                .step_by(4096)
                .all(|&b| b == 1)
        );
        assert!(resident >= 64 << 20, "{resident}");
    }
}
