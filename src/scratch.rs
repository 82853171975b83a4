//! Scratch folders for the library's unit tests.

use std::ops::Deref;
use std::path::Path;

/// An empty folder in the system's temporary folder, its name starting `splatscene-TAG-`,
/// removed with what the test wrote in it when dropped: at the end of the test, and when it
/// fails too (a panic unwinds through it). Each is new, so that parallel tests and earlier
/// runs never collide.
#[derive(Debug)]
pub(crate) struct Scratch(tempfile::TempDir);

impl Deref for Scratch {
    type Target = Path;

    fn deref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        self
    }
}

/// A new [`Scratch`] folder.
pub(crate) fn scratch(tag: &str) -> Scratch {
    Scratch(
        tempfile::Builder::new()
            .prefix(&format!("splatscene-{tag}-"))
            .tempdir()
            .expect("create a scratch folder"),
    )
}
