//! Nothing of a plan is lost: quitting with unsaved edits asks first (S saves and quits, D
//! discards and quits, Escape goes back), and the plan is autosaved beside where it would be
//! saved (`NAME-autosave.toml`, a few seconds after each edit) until it is saved or discarded.
//! A session that ends without either (a crash, a kill) leaves the autosave, which the next
//! start on the same scene offers to restore (R restores it, D deletes it, Escape keeps it and
//! autosaves to another name).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use winit::event_loop::ActiveEventLoop;
use winit::keyboard::{Key, NamedKey};

use super::App;
use super::plan::History;
use crate::scene::file::SceneFile;

/// How long after an edit the plan is autosaved (edits in a burst are written once).
pub(super) const AUTOSAVE_AFTER: Duration = Duration::from_secs(2);

/// A question the window waits on: its keys answer it before anything else.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Prompt {
    /// Quitting with unsaved edits.
    Quit,
    /// An autosave an earlier session left.
    Restore(PathBuf),
}

impl Prompt {
    /// The question as the window shows it.
    pub(super) fn text(&self) -> String {
        match self {
            Self::Quit => {
                "UNSAVED EDITS: S saves the plan and quits, D discards them and quits, Escape goes back"
                    .into()
            }
            Self::Restore(path) => format!(
                "AN AUTOSAVED PLAN WAS LEFT ({}): R restores it, D deletes it, Escape keeps it for later",
                path.display()
            ),
        }
    }
}

/// Where the plan autosaves, and what it wrote last.
#[derive(Debug, Clone)]
pub(super) struct Autosave {
    /// The file.
    pub path: PathBuf,
    /// The scene's generation last written; `None` before the first write.
    pub written: Option<u64>,
    /// When the next write may happen (a little after the last edit).
    pub due: Option<Instant>,
}

impl App {
    /// The folder and the name stem plans are saved with: `--plans`, else beside the scene
    /// file, else the screenshot folder; the scene file's stem (`NAME-plan.toml`), else the
    /// input's name, else `splatscene`.
    pub(super) fn plan_place(&self) -> (PathBuf, String) {
        let scene = self.options.scene_path.as_ref();
        let dir = self
            .options
            .plan_dir
            .clone()
            .or_else(|| scene.map(|p| p.parent().unwrap_or(Path::new(".")).to_path_buf()))
            .unwrap_or_else(|| self.options.screenshot_dir.clone());
        let stem = scene
            .and_then(|p| p.file_stem())
            .map(|s| plan_stem(&s.to_string_lossy()).to_owned())
            .or_else(|| self.options.plan_name.clone())
            .unwrap_or_else(|| "splatscene".into());
        (dir, stem)
    }

    /// The folder and name stem of this scene's autosaves: the scene file's own stem (a plan
    /// opened again autosaves apart from the scene it came from).
    fn autosave_place(&self) -> (PathBuf, String) {
        let (dir, plan) = self.plan_place();
        let stem = self
            .options
            .scene_path
            .as_ref()
            .and_then(|p| p.file_stem())
            .map_or(plan, |s| s.to_string_lossy().into_owned());
        (dir, stem)
    }

    /// The first free other autosave name (`NAME-autosave-2.toml`...).
    fn free_autosave(&self) -> Option<PathBuf> {
        let (dir, stem) = self.autosave_place();
        (2..10_000)
            .map(|n| dir.join(format!("{stem}-autosave-{n}.toml")))
            .find(|p| std::fs::symlink_metadata(p).is_err())
    }

    /// At the start: an autosave left by an earlier session is offered; this session
    /// autosaves to that name, or to the first free other one while the old one is kept.
    pub(super) fn start_autosave(&mut self) {
        let (dir, stem) = self.autosave_place();
        let path = dir.join(format!("{stem}-autosave.toml"));
        if std::fs::symlink_metadata(&path).is_ok() {
            println!("autosave found {}", path.display());
            self.prompt = Some(Prompt::Restore(path.clone()));
        }
        self.autosave = Some(Autosave {
            path,
            written: None,
            due: None,
        });
    }

    /// Writes the plan to its autosave when it has unsaved edits not yet written and the
    /// last edit is a moment old; removes the autosave when nothing is unsaved any more.
    pub(super) fn autosave_now(&mut self) {
        let Some(auto) = &self.autosave else {
            return;
        };
        if matches!(self.prompt, Some(Prompt::Restore(_))) {
            // The file may be the earlier session's, still to be answered for.
            return;
        }
        let generation = self.edit.scene.generation();
        if !self.edit.history.unsaved() {
            if auto.written.is_some() {
                let path = auto.path.clone();
                remove_autosave(&path);
                if let Some(a) = &mut self.autosave {
                    a.written = None;
                    a.due = None;
                }
            }
            return;
        }
        if auto.written == Some(generation) {
            return;
        }
        let now = Instant::now();
        match auto.due {
            None => {
                if let Some(a) = &mut self.autosave {
                    a.due = Some(now + AUTOSAVE_AFTER);
                }
                return;
            }
            Some(due) if now < due => return,
            Some(_) => {}
        }
        let mut path = auto.path.clone();
        if auto.written.is_none() && std::fs::symlink_metadata(&path).is_ok() {
            // A file this session did not write (another window on the same scene): never
            // replaced, the first free other name taken.
            match self.free_autosave() {
                Some(free) => path = free,
                None => return,
            }
            if let Some(a) = &mut self.autosave {
                a.path = path.clone();
            }
        }
        let size = self
            .gpu
            .as_ref()
            .map_or(self.options.size, |g| g.target.size);
        let written = self
            .plan_file(size, path.parent().unwrap_or(Path::new(".")))
            .map_err(std::io::Error::other)
            .and_then(|text| crate::output::write_atomic(&path, text.as_bytes()).map(|_| ()));
        match written {
            Ok(()) => {
                println!("autosaved {}", path.display());
                if let Some(a) = &mut self.autosave {
                    a.written = Some(generation);
                    a.due = None;
                }
            }
            Err(e) => {
                // Said once; the edits stay here, to be saved with Ctrl+S.
                self.say(format!("autosave failed: {}: {e}", path.display()));
                self.autosave = None;
            }
        }
    }

    /// When the autosave wants waking.
    pub(super) fn autosave_due(&self) -> Option<Instant> {
        let auto = self.autosave.as_ref()?;
        if self.edit.history.unsaved() && auto.written != Some(self.edit.scene.generation()) {
            Some(auto.due.unwrap_or_else(Instant::now))
        } else {
            None
        }
    }

    /// Q, Escape with nothing to cancel, or the window closed: quits, asking first where
    /// there are unsaved edits.
    pub(super) fn quit(&mut self, event_loop: &ActiveEventLoop) {
        if self.edit.history.unsaved() {
            self.prompt = Some(Prompt::Quit);
            println!("unsaved: {}", Prompt::Quit.text());
        } else {
            self.exit_clean(event_loop);
        }
    }

    /// Quits, the autosave removed (the plan is saved, or its edits were discarded).
    fn exit_clean(&mut self, event_loop: &ActiveEventLoop) {
        if let Some(auto) = &self.autosave
            && auto.written.is_some()
        {
            remove_autosave(&auto.path);
        }
        event_loop.exit();
    }

    /// A key while a prompt waits: its answer (other keys do nothing). Returns whether a prompt
    /// took the key.
    pub(super) fn answer(&mut self, event_loop: &ActiveEventLoop, key: &Key) -> bool {
        let Some(prompt) = self.prompt.clone() else {
            return false;
        };
        let letter = match key {
            Key::Character(c) => c.to_lowercase(),
            Key::Named(NamedKey::Escape) => "escape".into(),
            _ => return true,
        };
        match (&prompt, letter.as_str()) {
            (Prompt::Quit, "s") => {
                self.prompt = None;
                self.save_plan();
                if self.edit.history.unsaved() {
                    // Not saved (the message says why): stay.
                    return true;
                }
                self.exit_clean(event_loop);
            }
            (Prompt::Quit, "d") => {
                println!("discarded the unsaved edits");
                if let Some(auto) = &self.autosave
                    && auto.written.is_some()
                {
                    remove_autosave(&auto.path);
                }
                event_loop.exit();
            }
            (Prompt::Quit, "escape" | "c") => {
                self.prompt = None;
                println!("quit cancelled");
                self.say("quit cancelled: the edits are still here".into());
            }
            (Prompt::Restore(path), "r") => {
                self.prompt = None;
                self.restore(path);
            }
            (Prompt::Restore(path), "d") => {
                self.prompt = None;
                remove_autosave(path);
                println!("deleted {}", path.display());
                self.say(format!("deleted {}", path.display()));
            }
            (Prompt::Restore(path), "escape") => {
                self.prompt = None;
                // Kept: this session autosaves beside it, to the first free name.
                self.autosave = self.free_autosave().map(|path| Autosave {
                    path,
                    written: None,
                    due: None,
                });
                println!("kept {}", path.display());
                self.say(format!("kept {} for later", path.display()));
            }
            _ => {}
        }
        true
    }

    /// Puts the autosaved plan at `path` in place of the scene: the edits it holds are
    /// unsaved until Ctrl+S (the autosave stays until then).
    fn restore(&mut self, path: &Path) {
        let loaded = SceneFile::read(path).and_then(|file| {
            let base = path.parent().unwrap_or(Path::new("."));
            file.load(path, base)
        });
        match loaded {
            Ok(loaded) => {
                self.adopt(loaded.scene, History::restored());
                if let Some(auto) = &mut self.autosave {
                    // The restored plan is this session's to autosave, over the file it came
                    // from.
                    auto.written = Some(self.edit.scene.generation());
                }
                println!("restored {}", path.display());
                self.say(format!(
                    "restored {}: Ctrl+S saves it as a plan",
                    path.display()
                ));
            }
            Err(e) => {
                self.say(format!("not restored: {e} (the file is kept)"));
                eprintln!("not restored: {e}");
            }
        }
    }
}

/// The name a plan takes from its scene file's stem: a plan opened again saves as the next of
/// its series (`shoulder-plan` and `shoulder-plan-3` give `shoulder`, so the next save is
/// `shoulder-plan-N.toml`, not `shoulder-plan-plan.toml`), as does a restored autosave.
pub(super) fn plan_stem(stem: &str) -> &str {
    for suffix in ["-plan", "-autosave"] {
        if let Some(at) = stem.rfind(suffix) {
            let rest = &stem[at + suffix.len()..];
            let numbered = rest
                .strip_prefix('-')
                .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
            if (rest.is_empty() || numbered) && at > 0 {
                return &stem[..at];
            }
        }
    }
    stem
}

/// Removes an autosave, saying so where it cannot.
fn remove_autosave(path: &Path) {
    if let Err(e) = std::fs::remove_file(path)
        && e.kind() != std::io::ErrorKind::NotFound
    {
        eprintln!("autosave {} not removed: {e}", path.display());
    }
}

#[cfg(test)]
mod tests {
    use super::plan_stem;

    #[test]
    fn plans_opened_again_save_in_their_series() {
        assert_eq!(plan_stem("shoulder"), "shoulder");
        assert_eq!(plan_stem("shoulder-plan"), "shoulder");
        assert_eq!(plan_stem("shoulder-plan-12"), "shoulder");
        assert_eq!(plan_stem("shoulder-autosave-2"), "shoulder");
        assert_eq!(plan_stem("shoulder-planning"), "shoulder-planning");
        assert_eq!(plan_stem("-plan"), "-plan");
    }
}
