//! Writing the command line's outputs.

use std::path::Path;

use anyhow::Result;
use splatscene::output::{follow_links, write_atomic};

/// Writes `bytes` to `path` through a temporary file and a rename, so that a failed write
/// leaves any earlier file whole; says so when an existing file is replaced. A symbolic link
/// is followed and the file it names written; a device, pipe or socket (`/dev/null`, a FIFO)
/// is written into as it is, never replaced by a plain file.
pub(crate) fn write_replacing(path: &Path, bytes: &[u8]) -> Result<()> {
    // The file a link names is the one written, and the one to name.
    let target = follow_links(path)?;
    if write_atomic(&target, bytes)? {
        eprintln!("replaced the existing {}", target.display());
    }
    Ok(())
}
