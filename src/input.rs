//! Opening input files: every file a user names (a volume, a scene, a mesh, a glTF buffer, an
//! OBJ material library, a batch manifest) is opened through [`open_regular`], which refuses
//! anything but a regular file before a byte is read, so that a named pipe cannot block the
//! tool and a device cannot feed it without end.
//!
//! Every file opened so is also recorded by its identity (device and inode), so that an output
//! can be refused when it is a file this process has read: [`input_with_identity_of`]. The
//! record is the process's, not a value handed through every loader, because the loaders open
//! files at many depths (a NRRD's detached slices, a glTF's buffers, every file of a DICOM
//! folder) and an output check must see all of them; it holds a few dozen bytes per file.

use std::collections::HashMap;
use std::fs::{File, Metadata, OpenOptions};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::{LazyLock, Mutex};

/// A file's identity: the device and inode it lives at, the same through any link or name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct FileId {
    dev: u64,
    ino: u64,
}

impl FileId {
    /// The identity of the file `meta` describes.
    pub fn of(meta: &Metadata) -> Self {
        use std::os::unix::fs::MetadataExt;
        Self {
            dev: meta.dev(),
            ino: meta.ino(),
        }
    }
}

/// Every regular file opened for reading through this module, with the path it was opened by.
static OPENED: LazyLock<Mutex<HashMap<FileId, PathBuf>>> = LazyLock::new(Default::default);

/// Records `meta` (of the file opened at `path`) as an input of this process.
fn record(meta: &Metadata, path: &Path) {
    let id = FileId::of(meta);
    let mut opened = OPENED.lock().unwrap_or_else(|e| e.into_inner());
    opened.entry(id).or_insert_with(|| path.to_path_buf());
}

/// Records the file at `path` as an input without opening it through this module (a folder's
/// files listed by a reader of its own); nothing is recorded where it cannot be read.
pub fn record_input(path: &Path) {
    if let Ok(meta) = std::fs::metadata(path) {
        record(&meta, path);
    }
}

/// The path an input was read by, where `path` (links followed) is that same file: a file this
/// process has read, reached by the same name, another name, a hard link or a symbolic link.
pub fn input_with_identity_of(path: &Path) -> Option<PathBuf> {
    let id = FileId::of(&std::fs::metadata(path).ok()?);
    let opened = OPENED.lock().unwrap_or_else(|e| e.into_inner());
    opened.get(&id).cloned()
}

/// What kind of file `meta` describes, in words for an error message.
pub fn kind(meta: &Metadata) -> &'static str {
    let t = meta.file_type();
    if t.is_file() {
        return "a regular file";
    }
    if t.is_dir() {
        return "a folder";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return "a named pipe (FIFO)";
        }
        if t.is_socket() {
            return "a socket";
        }
        if t.is_char_device() {
            return "a character device";
        }
        if t.is_block_device() {
            return "a block device";
        }
    }
    "not a regular file"
}

/// Opens `path` for reading when it is a regular file (links followed); anything else is an
/// [`io::ErrorKind::InvalidInput`] error saying what it is. On Unix the file is opened
/// without blocking and its kind read from the open file, so that a FIFO never blocks the
/// open and nothing can swap the file between the check and the read.
pub fn open_regular(path: &Path) -> io::Result<File> {
    let mut options = OpenOptions::new();
    options.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        // O_NONBLOCK: opening a FIFO without a writer returns at once. Reads of regular files
        // ignore the flag.
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(not_regular(&meta));
    }
    record(&meta, path);
    Ok(file)
}

/// The error for a path that names something other than a regular file.
pub fn not_regular(meta: &Metadata) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("{}, not a regular file", kind(meta)),
    )
}

/// Reads the whole regular file at `path`, refusing one longer than `max` bytes before
/// reading it.
pub fn read_regular(path: &Path, max: u64) -> io::Result<Vec<u8>> {
    use std::io::Read;
    let file = open_regular(path)?;
    let len = file.metadata()?.len();
    if len > max {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("{len} bytes, more than the {max} read from such a file"),
        ));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    // One byte past the limit shows a file that grew meanwhile.
    file.take(max.saturating_add(1)).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("more than the {max} bytes read from such a file"),
        ));
    }
    Ok(bytes)
}

/// [`read_regular`] as UTF-8 text.
pub fn read_regular_text(path: &Path, max: u64) -> io::Result<String> {
    String::from_utf8(read_regular(path, max)?)
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidData, "not UTF-8 text"))
}

#[cfg(all(test, unix))]
mod tests {
    use super::*;

    #[test]
    fn only_regular_files_open() {
        let dir = crate::scratch::scratch("input");
        let file = dir.join("a.txt");
        std::fs::write(&file, "text").unwrap();
        assert_eq!(read_regular_text(&file, 10).unwrap(), "text");
        let e = read_regular(&file, 3).unwrap_err().to_string();
        assert!(e.contains("4 bytes, more than the 3"), "{e}");
        let fifo = dir.join("pipe");
        let status = std::process::Command::new("mkfifo").arg(&fifo).status();
        if status.is_ok_and(|s| s.success()) {
            let e = open_regular(&fifo).unwrap_err();
            assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
            assert!(e.to_string().contains("named pipe"), "{e}");
        }
        let e = open_regular(Path::new("/dev/zero"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("character device"), "{e}");
        let e = open_regular(&dir).unwrap_err().to_string();
        assert!(e.contains("a folder"), "{e}");
    }
}
