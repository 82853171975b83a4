//! A frame's cancel flag as the parallel stages of making a frame read it.
//!
//! A viewer raises the flag when a drag wants the cores that a frame still holds, and lowers
//! it for the next frame. A stage split into parts (slices, pages, units of bricks) asks before
//! each part; the parts it leaves out make its result partial, and a partial result must not be
//! kept even when the flag is lowered again before the stage ends. [`Parts`] holds both: the
//! flag, and whether a part was left out.

use std::sync::atomic::{AtomicBool, Ordering};

/// The cancel flag (none: never raised) of a stage made of parts on several cores, and whether
/// any part was left out for it.
///
/// ```
/// use std::sync::atomic::AtomicBool;
/// use splatscene::cancel::Parts;
///
/// let flag = AtomicBool::new(true);
/// let parts = Parts::new(Some(&flag));
/// let made: Vec<u32> = (0..4).filter(|_| !parts.skip()).collect();
/// flag.store(false, std::sync::atomic::Ordering::Relaxed);
/// // Lowered again, but every part was left out: the stage's result is not kept.
/// assert_eq!(parts.whole(made), None);
/// ```
#[derive(Debug)]
pub struct Parts<'a> {
    flag: Option<&'a AtomicBool>,
    skipped: AtomicBool,
}

impl<'a> Parts<'a> {
    /// A stage read under `flag`, no part left out yet.
    pub fn new(flag: Option<&'a AtomicBool>) -> Self {
        Self {
            flag,
            skipped: AtomicBool::new(false),
        }
    }

    /// Whether to leave the next part out: the flag is raised now. A part left out is
    /// remembered.
    pub fn skip(&self) -> bool {
        let raised = self.flag.is_some_and(|f| f.load(Ordering::Relaxed));
        if raised {
            self.skipped.store(true, Ordering::Relaxed);
        }
        raised
    }

    /// Whether a part was left out so far.
    pub fn skipped(&self) -> bool {
        self.skipped.load(Ordering::Relaxed)
    }

    /// `made`, unless a part of it was left out.
    pub fn whole<T>(self, made: T) -> Option<T> {
        (!self.skipped.into_inner()).then_some(made)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_part_left_out_is_remembered_after_the_flag_is_lowered() {
        let flag = AtomicBool::new(false);
        let parts = Parts::new(Some(&flag));
        assert!(!parts.skip());
        flag.store(true, Ordering::Relaxed);
        assert!(parts.skip());
        flag.store(false, Ordering::Relaxed);
        assert!(!parts.skip());
        assert!(parts.skipped());
        assert_eq!(parts.whole(1), None);
    }

    #[test]
    fn no_flag_or_a_lowered_one_keeps_what_was_made() {
        assert_eq!(Parts::new(None).whole(2), Some(2));
        let lowered = AtomicBool::new(false);
        let parts = Parts::new(Some(&lowered));
        assert!(!parts.skip() && !parts.skipped());
        assert_eq!(parts.whole(3), Some(3));
    }
}
