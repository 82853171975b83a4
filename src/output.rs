//! Writing output files: through a temporary of this process's own beside the target and a
//! rename, so that a failed write leaves any earlier file whole and a user's file at any other
//! name is never touched; links are followed to the file they name, and a device or named pipe
//! is written into as it is (a pipe that no process reads is refused, not waited on for ever).
//! No output is ever a file the process has read ([`check_not_input`]): an output that is an
//! input by any name or link is refused before it is written.

use std::io;
use std::path::{Path, PathBuf};

/// An output that could not be written, with the path concerned.
fn context(e: io::Error, what: &str, path: &Path) -> io::Error {
    io::Error::new(e.kind(), format!("{what} {}: {e}", path.display()))
}

/// Writes `bytes` to `path` through a temporary file of this process's own beside it and a
/// rename, so that neither a failed write nor another process writing the same file at once
/// leaves a partial file. Returns whether a file was replaced.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<bool> {
    static TEMPORARIES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    check_not_input(path)?;
    let path = &follow_links(path)?;
    if let Ok(meta) = std::fs::metadata(path)
        && !meta.is_file()
        && !meta.is_dir()
    {
        write_special(path, bytes).map_err(|e| context(e, "writing", path))?;
        return Ok(false);
    }
    let existed = path.exists();
    let name = path.file_name().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{}: the output path has no file name", path.display()),
        )
    })?;
    let n = TEMPORARIES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_file_name(format!(
        ".{}.{}-{n}.partial",
        name.to_string_lossy(),
        std::process::id()
    ));
    // Created exclusively: a file or a link already at the temporary's name is never
    // written through or replaced.
    if !write_new(&tmp, bytes)? {
        return Err(io::Error::new(
            io::ErrorKind::AlreadyExists,
            format!(
                "{}: something is already at this temporary's name",
                tmp.display()
            ),
        ));
    }
    if let Err(e) = std::fs::rename(&tmp, path) {
        let _ = std::fs::remove_file(&tmp);
        let what = format!("renaming {} to", tmp.display());
        return Err(context(e, &what, path));
    }
    Ok(existed)
}

/// Refuses `path` as an output where it is, by any name, hard link or chain of symbolic
/// links, a file this process has read as an input ([`crate::input`] records every one): an
/// [`io::ErrorKind::InvalidInput`] error naming both.
pub fn check_not_input(path: &Path) -> io::Result<()> {
    match crate::input::input_with_identity_of(path) {
        None => Ok(()),
        Some(input) => {
            let how = if input == path {
                String::new()
            } else {
                format!(" (read as {})", input.display())
            };
            Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "{}: this output is an input of this run{how}; writing it would replace the input, so choose another output name",
                    path.display()
                ),
            ))
        }
    }
}

/// How long a write into a named pipe waits for a process to open it for reading: long enough
/// for a reader started beside the run (`splatscene ... --out p & viewer p`) to get there,
/// short enough that a pipe nobody reads is an error, not a hang.
const PIPE_READER_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

/// Writes into a device, pipe or socket as it is. A named pipe that no process reads would
/// block the write for ever: it is opened without blocking, which fails at once with no reader,
/// and retried for up to [`PIPE_READER_WAIT`] before that is an error; then it is written to
/// as usual.
#[allow(unsafe_code)]
fn write_special(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    use std::io::Write;
    use std::os::unix::fs::OpenOptionsExt;
    use std::os::unix::io::AsRawFd;
    let started = std::time::Instant::now();
    let mut said = false;
    let mut file = loop {
        match std::fs::OpenOptions::new()
            .write(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(path)
        {
            Ok(file) => break file,
            Err(e) if e.raw_os_error() == Some(libc::ENXIO) => {
                if started.elapsed() >= PIPE_READER_WAIT {
                    return Err(std::io::Error::other(format!(
                        "no process is reading this named pipe (waited {} s for one)",
                        PIPE_READER_WAIT.as_secs()
                    )));
                }
                if !said && started.elapsed() >= std::time::Duration::from_millis(200) {
                    eprintln!(
                        "waiting up to {} s for a process to read {}",
                        PIPE_READER_WAIT.as_secs(),
                        path.display()
                    );
                    said = true;
                }
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            Err(e) => return Err(e),
        }
    };
    // Back to blocking writes, so that a pipe whose reader is slower than us is waited for.
    // SAFETY: fcntl on a descriptor this function owns, with flags it read from it.
    unsafe {
        let fd = file.as_raw_fd();
        let flags = libc::fcntl(fd, libc::F_GETFL);
        if flags >= 0 {
            libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_NONBLOCK);
        }
    }
    file.write_all(bytes)
}

/// `path`, or the file its chain of symbolic links names (which need not exist yet).
pub fn follow_links(path: &Path) -> io::Result<PathBuf> {
    let mut path = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&path) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let target =
                    std::fs::read_link(&path).map_err(|e| context(e, "reading the link", &path))?;
                path = match path.parent() {
                    Some(dir) if target.is_relative() => dir.join(target),
                    _ => target,
                };
            }
            _ => return Ok(path),
        }
    }
    Err(io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("{}: too many levels of symbolic links", path.display()),
    ))
}

/// Writes `bytes` to a new file at `path`, never through or over anything already there (a
/// file, or a link, dangling or not): `Ok(false)` where the name is taken.
pub fn write_new(path: &Path, bytes: &[u8]) -> io::Result<bool> {
    use std::io::Write;
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
    {
        Ok(mut file) => {
            if let Err(e) = file.write_all(bytes) {
                drop(file);
                let _ = std::fs::remove_file(path);
                return Err(context(e, "writing", path));
            }
            Ok(true)
        }
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => Ok(false),
        Err(e) => Err(context(e, "creating", path)),
    }
}
